//! The names of a device's state (fsm) and fault codes (SPEC §5), defined
//! once: frame JSON, the REST views, WebSocket telemetry and the simulator
//! all print these.

use super::params::Revision;

/// fsm values of SPEC §5 this project relies on.
pub mod fsm {
    pub const READY: u8 = 0;
    /// Rev 2.0.8.
    pub const INIT: u8 = 1;
    /// Rev 2.0.8.
    pub const PRECHARGE: u8 = 2;
    pub const ALIGN: u8 = 5;
    /// Rev 2.0.8.
    pub const START: u8 = 6;
    pub const RUN: u8 = 7;
    /// Rev 2.0.8.
    pub const STOP: u8 = 8;
    pub const FAULT: u8 = 9;
    /// Rev 2.0.8.
    pub const BRAKE: u8 = 10;
}

/// err_code values of SPEC §5.
pub mod fault {
    pub const NONE: u8 = 0;
    pub const HW_OVER_CURRENT: u8 = 1;
    pub const SW_OVER_CURRENT: u8 = 2;
    pub const HW_UNDER_VOLTAGE: u8 = 5;
    pub const SW_UNDER_VOLTAGE: u8 = 6;
    pub const STALL: u8 = 8;
    pub const OVER_TEMPERATURE: u8 = 9;
}

/// Every named fsm state, with the revision that documents it.
pub const FSM_STATES: [(u8, &str, Revision); 9] = [
    (fsm::READY, "ready", Revision::V2_0_1),
    (fsm::INIT, "init", Revision::V2_0_8),
    (fsm::PRECHARGE, "precharge", Revision::V2_0_8),
    (fsm::ALIGN, "align", Revision::V2_0_1),
    (fsm::START, "start", Revision::V2_0_8),
    (fsm::RUN, "run", Revision::V2_0_1),
    (fsm::STOP, "stop", Revision::V2_0_8),
    (fsm::FAULT, "fault", Revision::V2_0_1),
    (fsm::BRAKE, "brake", Revision::V2_0_8),
];

/// Every fault code of SPEC §5 (9 is both hardware and software
/// over-temperature: errata 6).
pub const FAULTS: [(u8, &str); 12] = [
    (fault::NONE, "none"),
    (fault::HW_OVER_CURRENT, "hw_over_current"),
    (fault::SW_OVER_CURRENT, "sw_over_current"),
    (3, "hw_over_voltage"),
    (4, "sw_over_voltage"),
    (fault::HW_UNDER_VOLTAGE, "hw_under_voltage"),
    (fault::SW_UNDER_VOLTAGE, "sw_under_voltage"),
    (7, "phase_loss"),
    (fault::STALL, "stall"),
    (fault::OVER_TEMPERATURE, "over_temperature"),
    (10, "communication_lost"),
    (11, "self_test_failed"),
];

/// Low nibble of err_code: the active fault; high nibble: the latched
/// history (rev 2.0.8; correct for V2.0.1 codes too).
const ACTIVE_MASK: u8 = 0x0F;
const HISTORY_SHIFT: u8 = 4;

/// Name of an fsm state; `reserved` for a value SPEC does not name.
pub fn fsm_name(fsm: u8) -> &'static str {
    FSM_STATES
        .iter()
        .find(|(v, _, _)| *v == fsm)
        .map_or("reserved", |(_, n, _)| n)
}

/// Name of an fsm state as a device of `revision` means it: a code only
/// rev 2.0.8 names is `reserved` on V2.0.1 firmware. An unknown revision
/// gets every name (a name is more use than `reserved` while it is asked).
pub fn fsm_name_in(fsm: u8, revision: Option<Revision>) -> &'static str {
    match FSM_STATES.iter().find(|(v, _, _)| *v == fsm) {
        Some((_, _, since)) if revision.is_some_and(|r| r < *since) => "reserved",
        Some((_, name, _)) => name,
        None => "reserved",
    }
}

/// Name of a fault code; pass [`active_fault`] or [`fault_history`] of an err_code.
pub fn fault_name(code: u8) -> &'static str {
    FAULTS
        .iter()
        .find(|(v, _)| *v == code)
        .map_or("unknown", |(_, n)| n)
}

/// The active fault of an err_code.
pub fn active_fault(err_code: u8) -> u8 {
    err_code & ACTIVE_MASK
}

/// The latched fault history of an err_code.
pub fn fault_history(err_code: u8) -> u8 {
    err_code >> HISTORY_SHIFT
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_cover_spec_and_refuse_nothing() {
        assert_eq!(fsm_name(7), "run");
        assert_eq!(fsm_name(3), "reserved");
        assert_eq!(fault_name(active_fault(0x98)), "stall");
        assert_eq!(fault_name(fault_history(0x98)), "over_temperature");
        assert_eq!(fault_name(12), "unknown");
    }

    #[test]
    fn state_names_follow_the_revision() {
        assert_eq!(fsm_name_in(8, Some(Revision::V2_0_8)), "stop");
        assert_eq!(fsm_name_in(8, Some(Revision::V2_0_1)), "reserved");
        assert_eq!(fsm_name_in(8, None), "stop");
        assert_eq!(fsm_name_in(7, Some(Revision::V2_0_1)), "run");
        assert_eq!(fsm_name_in(3, Some(Revision::V2_0_8)), "reserved");
    }
}
