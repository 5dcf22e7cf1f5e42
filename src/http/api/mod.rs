//! The REST areas, one router each, composed into the OpenAPI document.

pub mod buses;
pub mod config;
pub mod config_params;
pub mod control;
pub mod devices;
pub mod estop;
pub mod health;
pub mod openapi;
