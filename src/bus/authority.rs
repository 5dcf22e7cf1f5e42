//! Who may move a joint, decided where frames are made: a motion epoch per
//! joint, with whether the daemon enabled it and the mode it runs in.
//!
//! Every setpoint in the store carries the epoch it was admitted under (a
//! move, a homing job or a teleop stream keeps the one it started with).
//! An e-stop, every disable, a reset, a fault, a mode change and an enable
//! advance the joint's epoch; the bus owner drops a setpoint whose epoch is
//! not the joint's current one, or whose joint the daemon has not enabled
//! since (counted as stale). So a command admitted before any of these can
//! never reach the joint after it, whoever holds it and however late.
//!
//! One atomic word per joint id: reading it costs the owner one load per
//! pending setpoint, and the e-stop's fan-out (run by the caller, before the
//! owner even sees the press) takes no lock.

use std::sync::atomic::{AtomicU64, AtomicU8, Ordering};

use serde::Serialize;

use crate::protocol::CtrlMode;

/// The motion epoch a command was admitted under.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
pub struct Epoch(pub u64);

impl Epoch {
    /// The epoch after a mode change made under this one and nothing else:
    /// [`MotionAuthority::mode_changing`] and [`MotionAuthority::mode_set`]
    /// advance it once each (a job that changes the mode itself, like
    /// homing, goes on under this epoch).
    pub fn after_own_mode_change(self) -> Epoch {
        Epoch(self.0 + 2)
    }
}

/// Why a joint's epoch advanced: what ends a move, a homing job or a
/// teleop stream of that joint.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Revoked {
    Estopped,
    Disabled,
    Reset,
    ModeChanged,
    Fault,
    /// Enabled again: it holds where it stands, and nothing earlier applies.
    Reenabled,
    /// Its zero moved (re-zero, jog): earlier angles mean something else.
    ZeroMoved,
}

impl Revoked {
    /// The name in JSON, events and logs.
    pub fn name(self) -> &'static str {
        match self {
            Self::Estopped => "estopped",
            Self::Disabled => "disabled",
            Self::Reset => "reset",
            Self::ModeChanged => "mode_changed",
            Self::Fault => "fault",
            Self::Reenabled => "reenabled",
            Self::ZeroMoved => "zero_moved",
        }
    }

    fn code(self) -> u8 {
        self as u8 + 1
    }

    fn from_code(code: u8) -> Option<Self> {
        [
            Self::Estopped,
            Self::Disabled,
            Self::Reset,
            Self::ModeChanged,
            Self::Fault,
            Self::Reenabled,
            Self::ZeroMoved,
        ]
        .into_iter()
        .find(|r| r.code() == code)
    }
}

/// A joint's standing as the owner last set it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Grant {
    pub epoch: Epoch,
    /// The daemon enabled the joint and nothing has revoked it since.
    pub enabled: bool,
    /// The mode the daemon knows; `None`: never set (position, the
    /// power-up default) — or being changed right now ([`Self::mode_settled`] false).
    pub mode: Option<CtrlMode>,
    mode_settled: bool,
}

impl Grant {
    /// True when position targets and move samples may drive the joint.
    pub fn takes_positions(&self) -> bool {
        self.enabled && self.mode_settled && matches!(self.mode, None | Some(CtrlMode::Position))
    }

    /// True when a speed reference may drive the joint.
    pub fn takes_speeds(&self) -> bool {
        self.enabled && self.mode_settled && self.mode == Some(CtrlMode::Speed)
    }

    /// False while a mode change is on its way to the device.
    pub fn mode_settled(&self) -> bool {
        self.mode_settled
    }
}

// Word layout: bit 0 enabled, bits 1..4 the mode (0 never set, 1 + raw
// mode, 7 changing), bits 8.. the epoch.
const ENABLED: u64 = 1;
const MODE_SHIFT: u32 = 1;
const MODE_MASK: u64 = 0b111 << MODE_SHIFT;
const MODE_CHANGING: u64 = 7;
const EPOCH_SHIFT: u32 = 8;

fn mode_bits(mode: Option<CtrlMode>) -> u64 {
    mode.map_or(0, |m| 1 + m as u64) << MODE_SHIFT
}

fn decode(word: u64) -> Grant {
    let mode_code = (word & MODE_MASK) >> MODE_SHIFT;
    Grant {
        epoch: Epoch(word >> EPOCH_SHIFT),
        enabled: word & ENABLED != 0,
        mode: match mode_code {
            0 | MODE_CHANGING => None,
            c => CtrlMode::from_raw((c - 1) as u8),
        },
        mode_settled: mode_code != MODE_CHANGING,
    }
}

/// The motion authority of one bus: a word per joint id.
pub struct MotionAuthority {
    words: Box<[AtomicU64]>,
    reasons: Box<[AtomicU8]>,
    /// Setpoints the owner dropped as stale.
    stale: AtomicU64,
}

impl Default for MotionAuthority {
    fn default() -> Self {
        Self {
            words: (0..256).map(|_| AtomicU64::new(0)).collect(),
            reasons: (0..256).map(|_| AtomicU8::new(0)).collect(),
            stale: AtomicU64::new(0),
        }
    }
}

impl std::fmt::Debug for MotionAuthority {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MotionAuthority")
            .field("stale", &self.stale_dropped())
            .finish_non_exhaustive()
    }
}

impl MotionAuthority {
    fn word(&self, id: u8) -> &AtomicU64 {
        &self.words[usize::from(id)]
    }

    /// The joint's standing now.
    pub fn grant(&self, id: u8) -> Grant {
        decode(self.word(id).load(Ordering::Acquire))
    }

    /// Why the joint's epoch last advanced, if it ever did.
    pub fn last_revoked(&self, id: u8) -> Option<Revoked> {
        Revoked::from_code(self.reasons[usize::from(id)].load(Ordering::Acquire))
    }

    /// True when a setpoint admitted under `epoch` may still reach joint `id`.
    pub fn admits(&self, id: u8, epoch: Epoch) -> bool {
        let g = self.grant(id);
        g.enabled && g.epoch == epoch
    }

    /// Advances the joint's epoch and takes its enable away; returns the new epoch.
    pub fn revoke(&self, id: u8, why: Revoked) -> Epoch {
        self.reasons[usize::from(id)].store(why.code(), Ordering::Release);
        let old = self.update(id, |w| (w & !ENABLED) + (1 << EPOCH_SHIFT));
        Epoch((old >> EPOCH_SHIFT) + 1)
    }

    /// Advances the joint's epoch and keeps its enable (its zero moved:
    /// angles admitted before mean something else now).
    pub fn advance(&self, id: u8, why: Revoked) -> Epoch {
        self.reasons[usize::from(id)].store(why.code(), Ordering::Release);
        let old = self.update(id, |w| w + (1 << EPOCH_SHIFT));
        Epoch((old >> EPOCH_SHIFT) + 1)
    }

    /// [`Self::revoke`] for every joint id (an e-stop, a bus lost, shutdown).
    pub fn revoke_all(&self, why: Revoked) {
        for id in 0..=u8::MAX {
            self.revoke(id, why);
        }
    }

    /// The joint is enabled, unless something revoked it after `since`
    /// (the epoch its enable started at): then it stays disabled.
    pub fn arm(&self, id: u8, since: Epoch) -> bool {
        let word = self.word(id);
        let mut current = word.load(Ordering::Acquire);
        loop {
            if decode(current).epoch != since {
                return false;
            }
            match word.compare_exchange_weak(
                current,
                current | ENABLED,
                Ordering::AcqRel,
                Ordering::Acquire,
            ) {
                Ok(_) => return true,
                Err(seen) => current = seen,
            }
        }
    }

    /// A mode change is on its way: nothing admitted before applies, and
    /// nothing is admitted until [`Self::mode_set`] says which mode it is.
    pub fn mode_changing(&self, id: u8) {
        self.reasons[usize::from(id)].store(Revoked::ModeChanged.code(), Ordering::Release);
        self.update(id, |w| {
            ((w & !MODE_MASK) | (MODE_CHANGING << MODE_SHIFT)) + (1 << EPOCH_SHIFT)
        });
    }

    /// The device runs `mode` now (a write done, a reset's power-up
    /// default); a change advances the epoch, the enable is kept.
    pub fn mode_set(&self, id: u8, mode: Option<CtrlMode>) {
        let bits = mode_bits(mode);
        let old = self.word(id).load(Ordering::Acquire);
        if old & MODE_MASK == bits {
            return;
        }
        self.reasons[usize::from(id)].store(Revoked::ModeChanged.code(), Ordering::Release);
        self.update(id, |w| ((w & !MODE_MASK) | bits) + (1 << EPOCH_SHIFT));
    }

    /// Counts setpoints the owner dropped as stale.
    pub(crate) fn count_stale(&self, n: u64) {
        if n > 0 {
            self.stale.fetch_add(n, Ordering::Relaxed);
        }
    }

    /// Setpoints dropped as stale since the bus started.
    pub fn stale_dropped(&self) -> u64 {
        self.stale.load(Ordering::Relaxed)
    }

    fn update(&self, id: u8, f: impl Fn(u64) -> u64) -> u64 {
        match self
            .word(id)
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |w| Some(f(w)))
        {
            Ok(old) | Err(old) => old,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_revoke_makes_every_earlier_epoch_stale_and_disarms() {
        let a = MotionAuthority::default();
        let e = a.revoke(3, Revoked::Reenabled);
        assert!(a.arm(3, e));
        assert!(a.admits(3, e));
        a.revoke(3, Revoked::Estopped);
        assert!(!a.admits(3, e));
        assert!(!a.grant(3).enabled);
        assert_eq!(a.last_revoked(3), Some(Revoked::Estopped));
    }

    #[test]
    fn an_enable_overtaken_by_a_revoke_does_not_arm() {
        let a = MotionAuthority::default();
        let e = a.revoke(1, Revoked::Reenabled);
        a.revoke(1, Revoked::Estopped);
        assert!(!a.arm(1, e));
        assert!(!a.grant(1).enabled);
    }

    #[test]
    fn a_mode_change_advances_the_epoch_and_keeps_the_enable() {
        let a = MotionAuthority::default();
        let e = a.revoke(2, Revoked::Reenabled);
        a.arm(2, e);
        assert!(a.grant(2).takes_positions());
        a.mode_changing(2);
        let g = a.grant(2);
        assert!(g.enabled && !g.takes_positions() && !g.takes_speeds());
        assert!(!a.admits(2, e));
        a.mode_set(2, Some(CtrlMode::Speed));
        let g = a.grant(2);
        assert!(g.takes_speeds() && !g.takes_positions());
        assert_ne!(g.epoch, e);
        // Setting the same mode again changes nothing.
        a.mode_set(2, Some(CtrlMode::Speed));
        assert_eq!(a.grant(2).epoch, g.epoch);
    }

    #[test]
    fn a_job_knows_the_epoch_its_own_mode_change_leads_to() {
        let a = MotionAuthority::default();
        let e = a.revoke(4, Revoked::Reenabled);
        a.arm(4, e);
        a.mode_changing(4);
        a.mode_set(4, Some(CtrlMode::Speed));
        assert!(a.admits(4, e.after_own_mode_change()));
        let z = a.advance(4, Revoked::ZeroMoved);
        assert!(a.grant(4).enabled && a.admits(4, z));
        assert_eq!(a.last_revoked(4), Some(Revoked::ZeroMoved));
    }

    #[test]
    fn joints_are_independent() {
        let a = MotionAuthority::default();
        let e1 = a.revoke(1, Revoked::Reenabled);
        a.arm(1, e1);
        a.revoke(2, Revoked::Disabled);
        assert!(a.admits(1, e1));
    }
}
