//! What a bus tells its subscribers as it happens: devices coming and
//! going, state changes, faults, resets, configuration written, the USB
//! pipeline's mode (the WebSocket `events` stream and recordings carry them).

use serde::Serialize;

use super::state::ResetSignal;

/// Something subscribers should hear about as it happens.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum BusEvent {
    DeviceOnline {
        bus: String,
        #[serde(rename = "id")]
        dev_id: u8,
    },
    DeviceOffline {
        bus: String,
        #[serde(rename = "id")]
        dev_id: u8,
    },
    Fault {
        bus: String,
        #[serde(rename = "id")]
        dev_id: u8,
        err_code: u8,
        name: &'static str,
    },
    BusUp {
        bus: String,
    },
    BusDown {
        bus: String,
        reason: String,
    },
    IdChanged {
        bus: String,
        old: u8,
        new: u8,
    },
    BaudChanged {
        bus: String,
        baud: u32,
    },
    Estop {
        bus: String,
    },
    /// A device found enabled at start (its first INFO_01 shows align or
    /// run): what `on_start` does with it.
    FoundEnabled {
        bus: String,
        #[serde(rename = "id")]
        dev_id: u8,
        state: &'static str,
        /// `keep` (left enabled, target unknown) or `disable`.
        on_start: &'static str,
    },
    /// A move ([`crate::motion`]) with joints on this bus started.
    MoveStarted {
        bus: String,
        move_id: u64,
        /// Its joints on this bus.
        ids: Vec<u8>,
        duration_ms: f64,
    },
    /// How far a running move is (share of its time), every 100 ms.
    MoveProgress {
        bus: String,
        move_id: u64,
        progress: f64,
    },
    /// Every joint of the move reached the end of its path (or was taken
    /// over by a newer move or setpoint).
    MoveDone {
        bus: String,
        move_id: u64,
    },
    /// Stopped by its caller: its joints hold where they are.
    MoveStopped {
        bus: String,
        move_id: u64,
    },
    /// A move was cut short: an e-stop, the bus lost, a joint went offline
    /// or faulted. Its joints stop where they are.
    MoveAborted {
        bus: String,
        move_id: u64,
        reason: String,
    },
    /// A parameter written to a device and confirmed (a RES reply or the
    /// INFO block read back): RAM writes, flash writes, mode switches.
    ConfigWritten {
        bus: String,
        #[serde(rename = "id")]
        dev_id: u8,
        index: u8,
        /// The vendor's name (`MAX_CUR`, `CTRL_MODE_SW`, ...).
        name: &'static str,
        /// The raw value written.
        value: u16,
        /// `res` or `read_back`.
        verified_by: &'static str,
    },
    /// Behind a USB adapter: the pipeline changed mode (backed off after
    /// a collision's aftermath, or stepped back after a clean while).
    UsbPipeline {
        bus: String,
        /// `pipelined`, `guarded` or `lockstep`.
        mode: &'static str,
        previous: &'static str,
        /// How late a write may reach the adapter now, µs.
        guard_us: u64,
        reason: String,
    },
    /// A finger of a grasp touched something: it holds it from now on.
    GraspContact {
        bus: String,
        grasp_id: u64,
        /// The joint.
        id: u8,
        /// Where contact began, in the joint's calibrated frame.
        contact_deg: f64,
    },
    /// A finger holding an object felt its current fall: the object is
    /// gone (pulled away, slipped, broke). The finger stays where it was.
    GraspLost {
        bus: String,
        grasp_id: u64,
        id: u8,
        /// The q current when it was seen, A.
        q_current_a: f64,
    },
    /// A device reset (power cut, reboot): it is disabled, forgot its mode
    /// and target; the daemon forgot its targets too.
    DeviceReset {
        bus: String,
        #[serde(rename = "id")]
        dev_id: u8,
        /// `announcement` or `state_dropped`.
        seen: ResetSignal,
        /// State name before (`run`, ...; `unknown` if never read) and now.
        state_before: &'static str,
        state: &'static str,
    },
    /// A motion or configuration command a front-end passed on, with who
    /// sent it (its token's name, never the token): what a recording
    /// keeps of who moved what. A command repeated fast is told once per
    /// second, with how many more came in that second.
    Command {
        bus: String,
        /// The token's name (`open` without tokens).
        by: String,
        /// What, as the front-end names it: `PUT /api/v1/buses/sim0/devices/1/target`,
        /// `websocket setpoints`, ...
        command: String,
        /// How it ended: the HTTP status, or `accepted` / the WebSocket error code.
        outcome: String,
        /// More like it (same who and what) in the second before.
        repeats: u64,
    },
}
