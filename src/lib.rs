//! jointd: a gateway daemon for RS-485 servo joint modules.
//!
//! # Layout
//! Rooms from the bottom up; each imports only from rooms above it in this
//! list (no import circles, between rooms or between the files of one).
//! - [`protocol`]: the wire protocol as pure functions of bytes: frames, CRC,
//!   typed commands/replies, units, the parameter table (`protocol::params`,
//!   one row per config/INFO index; everything else derives from it), the
//!   state and fault names, frames ↔ JSON. No I/O, no runtime.
//! - `logcap`: collapsing repeated log lines (one per key per window, with a count), for
//!   failures a client can repeat at will.
//! - [`mem`]: giving freed heap memory back to the system (glibc `malloc_trim`).
//! - [`histogram`]: a latency histogram in Prometheus' shape, cheap enough for the bus
//!   owner's hot path (no allocation, no lock).
//! - [`rosmsg`]: ROS 2 messages in CDR, encoded and decoded (recordings and the bridge). Pure.
//! - [`motion`]: moves generated in the daemon: synchronised multi-joint paths
//!   (linear, minimum-jerk, trapezoid; waypoints; limits) and a move's status. Pure.
//! - [`hands`]: named hands (`[[hand]]`), their poses and the joints' calibrations, kept in
//!   the state file (`state_dir`), written atomically.
//! - [`rt`]: real-time thread helpers (timer slack, FIFO class; `rt::wake`: how late a thread
//!   wakes) for the bus owner and the simulator.
//! - [`transport`]: the byte lines a bus runs over (tty/pty with RS-485 setup, in-memory pipe).
//! - [`sim`]: the wire-accurate simulated bus of joint modules (pty or in-memory), behaviour from the SPEC.
//! - [`bus`]: one owner thread per bus: the pure scheduler decides, the owner does the I/O;
//!   the [`bus::BusHandle`] is what the control core acts through.
//! - [`doctor`]: `jointd doctor PATH`: a real bus checked against what jointd assumes (the
//!   port, the adapter's timer, output count and echo, the line, the baud, each device, ids on
//!   two devices) and the bus config it proposes, with its rates; it sends only reads, on
//!   a port it opens or one a running bus lends it ([`bus::loan`]).
//! - [`record`]: MCAP recordings of the buses (joint states in CDR, frames, events,
//!   setpoints) and the `jointd record` client.
//! - [`control`]: the control core, the one way in: REST, WebSocket and ROS 2 only
//!   translate; every operation (enable, targets, moves, homing, grasps, configuration
//!   writes, the teleop step, e-stop) is a call on it, and a front-end reads a bus
//!   through a read-only [`control::bus_reader::BusReader`]; its own error
//!   ([`control::ControlError`]), which each front-end maps once.
//! - [`http`]: one axum application: state, auth, errors (the one place that picks HTTP
//!   statuses), and below it the REST areas, the WebSocket and the dashboard, which never
//!   import each other.
//! - [`ros2`]: the ROS 2 bridge over Zenoh, as `rmw_zenoh` names and encodes it
//!   (`joint_states`, `joint_commands`, `/diagnostics`); the bridge itself is compiled in
//!   with the feature `ros2`.
//! - [`foxglove`](crate::foxglove): the live view in Foxglove (`--foxglove`): Foxglove's SDK
//!   serves its WebSocket protocol with the recordings' channels, fed by the recorder's encoder
//!   of the buses' taps; read only, loopback by default.
//! - [`cli`]: the `jointd frame …` tools for reading a serial capture by hand.
//! - `config_locate`: the line and key of a config value refused after parsing.
//! - [`daemon`]: `jointd [run]`: config file and flags, buses, the HTTP server, graceful shutdown.
//! - `bench` (feature `bench`): `jointd bench`: the bus engine against the simulator, measured.
//! - `params_reach` (test builds only): a fictitious parameter row reaches every user of the
//!   table (REST schema, bus verification, simulator).
//!
//! # Where a behaviour lives
//! | behaviour | room |
//! |---|---|
//! | a frame's bytes, CRC, resync in a byte stream | `protocol::frame`, `protocol::checksum`, `protocol::stream` |
//! | a config/INFO index: name, raw type, scale, range, flash, how a write is confirmed | `protocol::params` (the table) |
//! | when a lost confirmation is retried, when a write is unverified | `bus::verify`, `bus::owner` (its `write`) |
//! | raw ↔ physical units | `protocol::units` |
//! | what goes on the wire next (e-stop, request, setpoints, polls, reopen) | `bus::scheduler` |
//! | when a frame leaves, when a reply is due or late | `bus::wire` |
//! | setpoints → broadcast/control frames | `bus::coalesce` |
//! | online/offline, per-device state and rates | `bus::registry` |
//! | a device reset (announcement, state drop), a joint found enabled at start | `bus::registry` (detection); `bus::owner` (`start`: `on_start`) |
//! | enable, verified writes, id/baud change, scan, e-stop on the wire | `bus::owner` (its `jobs`, `write`, `baud`, `scan`, `estop`) |
//! | what a bus error is; which HTTP status it gets | `bus::error`; `http::error` |
//! | who may call at all: token, Host (DNS rebinding), browser origin, body size | `http::auth`, `http::guard` (checks), `http::policy` (the decisions, pure) |
//! | a REST route | `http::api` (one file per area), its OpenAPI in the same handler; what it does, a call on `control` |
//! | enable, disable, mode, jog, re-zero, targets, e-stop; scan, baud, parameter writes, id | `control::actions`; `control::bus_ops` |
//! | a WebSocket message | `http::ws::messages`, applied in `http::ws::session` |
//! | soft limits, target checks, admission under the motion authority | `control::limits`, `control::targets`, `control::batch` |
//! | whether a frame may still go out (motion epoch per joint) | `bus::authority`, checked in `bus::scheduler` (control) and `bus::motion` |
//! | the dashboard | `web/` (files), served by `http::web` |
//! | moves generated in the daemon; named hands, poses, calibration, homing | `motion`, `bus::motion`, `control::moves`; `hands`; `control::calibration`, `control::homing` |
//! | the teleop watchdog and streams (WebSocket, ROS 2), the one teleop step | `control::watchdog`, `control::streams` (`Streams::apply`) |
//! | a ROS 2 message's CDR | `rosmsg` |
//! | MCAP recordings (what `jointd record` and `POST /api/v1/recordings` write) | `record`, `control::recordings`, `http::api::recordings` |
//! | the live view in Foxglove: its channels, what goes on them, a slow client's queue | `record::channels`, `record::tap`; `foxglove` |
//! | what a simulated device does with a frame | `sim::device`, `sim::physics`, `sim::faults` |
//! | collisions and timing on the simulated wire | `sim::wire`, `sim::engine` |
//! | opening a serial port (exclusive: a `flock` a second daemon or the doctor finds), RS-485 mode, FTDI latency | `transport::tty`, `transport::rs485` |
//! | what a bus on real hardware is, checked before the daemon runs on it | `doctor` |
//! | config file keys, command-line flags | `daemon`, `main.rs`; a refused value's line: `config_locate` |
//! | which log lines a failing request writes (5xx: WARN, collapsed) | `http` (`log_failures`), `logcap` |

// Visibility says who may use an item: `pub` only where it is reachable from
// outside the crate, `pub(crate)` for the rest; every public type prints in
// a log or a test failure.
#![warn(unreachable_pub, missing_debug_implementations)]

#[cfg(feature = "bench")]
pub mod bench;
pub mod bus;
pub mod cli;
mod config_locate;
pub mod control;
pub mod daemon;
pub mod doctor;
pub mod foxglove;
pub mod hands;
pub mod histogram;
pub mod http;
mod logcap;
pub mod mem;
pub mod motion;
pub mod protocol;
pub mod record;
pub mod ros2;
pub mod rosmsg;
pub mod rt;
pub mod sim;
pub mod transport;

#[cfg(test)]
mod params_reach;
#[cfg(test)]
mod test_dir;
