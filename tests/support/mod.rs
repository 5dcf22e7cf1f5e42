//! The integration tests' shared helpers, in one place. Each test binary
//! declares `mod support;` and takes the room it needs.
//!
//! # Layout
//! - [`sim`]: a bare host on a simulator line (pty or memory): send frames, read replies.
//! - [`bus`]: a bus owner on a simulator's pty (`Rig`), waits on its snapshot, a target stream.
//! - [`http`]: the API served on `127.0.0.1:0` and a client that reads problems.
//! - [`sim_bus`]: the API in front of the real bus engine and the simulator, as `--sim` runs it.
//! - [`fake_bus`]: a scripted bus owner for exact control of what the bus answers.
//! - [`daemon`]: the `jointd` binary as a daemon: spawned, its address and log, killed on drop.
//! - [`tmp`]: a temp directory removed when the test drops it.
#![allow(dead_code)]

pub mod bus;
pub mod daemon;
pub mod fake_bus;
pub mod http;
pub mod sim;
pub mod sim_bus;
// The library's own test dir, one source for both kinds of test.
#[path = "../../src/test_dir.rs"]
pub mod tmp;
