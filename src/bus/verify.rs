//! How a config write is confirmed (SPEC §4.3), read from the parameter
//! table: a RES reply for the rows that answer, a read-back of the row's
//! INFO field for the settings that do not, and an honest "unverifiable"
//! for the rest. Rows the table guards are refused with the row's reason.
//!
//! # When a lost confirmation is retried
//! Noise on the line can eat the write, the read-back request or its
//! reply, or the RES: a lost confirmation says nothing about the write.
//! A read-back is read again first (reading is always harmless). Only a
//! write that is idempotent is then sent again: a RAM setting the table
//! does not guard (storage `ram` or `volatile`, guard `none`): setting the
//! same value twice is the same as once. A flash write (WRITE_FLASH, an
//! action with storage `none`), an id change (storage `flash`, routed) or
//! anything the table does not know goes out once: flash has a bounded
//! number of erase cycles and an id change re-sent to the old id would go
//! to a device that may no longer have it. What stays unconfirmed is
//! reported unverified, never "not written".

use crate::protocol::params::{self, Access, Field, Guard, ReplyKind, Storage};
use crate::protocol::{ConfigParam, InfoBlock};

/// The way a write of one parameter is confirmed.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Confirm {
    /// The device answers RES (1 success, 0 failure).
    Res,
    /// Read `block` back and compare `field` with the value written.
    ReadBack { block: InfoBlock, field: Field },
    /// No reply and no INFO field shows it.
    Unverifiable,
}

/// How `param` is confirmed, or why `write_config` refuses it.
pub(crate) fn confirmation(param: &ConfigParam) -> Result<Confirm, &'static str> {
    let (index, _) = param.index_value();
    let Some(row) = params::by_index(index) else {
        return Ok(Confirm::Unverifiable); // an index the table does not know
    };
    if row.access == Access::Read {
        return Err("a read is not a write: use read_info");
    }
    match row.guard {
        Guard::Routed(why) | Guard::Dangerous(why) => return Err(why),
        Guard::None => {}
    }
    Ok(match (row.reply, row.read_back) {
        (ReplyKind::Res, _) => Confirm::Res,
        (_, Some(field)) => Confirm::ReadBack {
            block: field.block,
            field,
        },
        _ => Confirm::Unverifiable,
    })
}

/// How often a write whose confirmation is lost is tried again.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct RetryPlan {
    /// Times the write may go out (1: never re-sent).
    pub(crate) sends: u32,
    /// Read-backs after each send (a RES is waited for once per send: it
    /// cannot be asked for again without sending the write again).
    pub(crate) reads_per_send: u32,
}

/// The plan for `param` with the bus's `retries` (extra attempts after a timeout).
pub(crate) fn retry_plan(param: &ConfigParam, retries: u32) -> RetryPlan {
    let again = 1 + retries;
    RetryPlan {
        sends: if resend_safe(param) { again } else { 1 },
        reads_per_send: again,
    }
}

/// A write that may be re-sent: an unguarded RAM setting (idempotent).
pub(crate) fn resend_safe(param: &ConfigParam) -> bool {
    let (index, _) = param.index_value();
    params::by_index(index).is_some_and(|row| {
        row.access == Access::Write
            && row.guard == Guard::None
            && matches!(row.storage, Storage::Ram | Storage::Volatile)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::{Gains, Info05, Reply, ReplyBody};

    #[test]
    fn ram_parameters_read_back_the_field_they_wrote() {
        let info05 = Info05 {
            protect_cur_lv1: 2912,
            protect_delay_lv1_ms: 600,
            recv_cur: 582,
            recover_delay_ms: 400,
        };
        let reply = Reply::new(1, ReplyBody::Info05(info05));
        let Ok(Confirm::ReadBack { block, field }) = confirmation(&ConfigParam::CurLv1DelayMs(600))
        else {
            panic!("expected a read-back");
        };
        assert_eq!(block, InfoBlock::Info05);
        assert_eq!(field.read(&reply.data), 600);
    }

    #[test]
    fn every_read_back_names_a_block_whose_field_round_trips() {
        let gains = Gains {
            pos_kp: 1,
            pos_kd: 2,
            spd_kp: 3,
            spd_ki: 4,
        };
        let d = Reply::new(1, ReplyBody::Info03(gains)).data;
        for (param, want) in [
            (ConfigParam::PosKp(1), 1),
            (ConfigParam::PosKd(2), 2),
            (ConfigParam::SpdKp(3), 3),
            (ConfigParam::SpdKi(4), 4),
        ] {
            let Ok(Confirm::ReadBack { field, .. }) = confirmation(&param) else {
                panic!("{param:?}")
            };
            assert_eq!(field.read(&d), want, "{param:?}");
        }
    }

    #[test]
    fn dangerous_and_routed_writes_are_refused() {
        assert!(confirmation(&ConfigParam::CommSilent(1)).is_err());
        assert!(confirmation(&ConfigParam::UpdateEncZero).is_err());
        assert!(confirmation(&ConfigParam::SetId { new_id: 3 }).is_err());
        assert!(confirmation(&ConfigParam::BaudRate(crate::protocol::BaudLevel::B500000)).is_err());
        assert!(confirmation(&ConfigParam::ReadInfo(InfoBlock::Info01)).is_err());
        assert!(matches!(
            confirmation(&ConfigParam::WriteFlash { key: 0xA5 }),
            Ok(Confirm::Res)
        ));
    }

    #[test]
    fn only_unguarded_ram_writes_are_sent_again() {
        use crate::protocol::BaudLevel;
        let plan = |p| retry_plan(&p, 2);
        let twice = RetryPlan {
            sends: 3,
            reads_per_send: 3,
        };
        assert_eq!(plan(ConfigParam::MaxCur(100)), twice);
        assert_eq!(plan(ConfigParam::PosKp(100)), twice);
        for once in [
            ConfigParam::WriteFlash { key: 0xA5 },
            ConfigParam::SetId { new_id: 3 },
            ConfigParam::BaudRate(BaudLevel::B500000),
            ConfigParam::Other { index: 0, value: 1 },
            ConfigParam::Other {
                index: 29,
                value: 1,
            },
        ] {
            assert_eq!(plan(once).sends, 1, "{once:?}");
        }
    }

    #[test]
    fn writes_without_reply_or_field_are_unverifiable() {
        for p in [
            ConfigParam::CtrlMode(crate::protocol::CtrlMode::Speed),
            ConfigParam::UpdateFinZero,
            ConfigParam::DrvOtC(80),
            ConfigParam::SpdLimit(100),
            ConfigParam::Other {
                index: 29,
                value: 1,
            },
        ] {
            assert!(
                matches!(confirmation(&p), Ok(Confirm::Unverifiable)),
                "{p:?}"
            );
        }
    }
}
