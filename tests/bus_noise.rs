//! Nothing reported wrongly under line noise: with bytes garbled on the
//! line, every config write's reported outcome agrees with what the
//! simulated device holds afterwards.
//!
//! - written (confirmed) ⇒ the device has the value;
//! - not written (read back with another value) ⇒ it does not;
//! - unverified (sent, confirmation lost) ⇒ either.
//!
//! Each write carries a value no earlier write used, so "the device has
//! this write's value" can only be this write's doing.

mod support;

use jointd::bus::BusError;
use jointd::protocol::params::index;
use jointd::protocol::ConfigParam;
use jointd::sim::Fault;
use support::bus::*;

const WRITES: u16 = 200;
/// 2.5 % of the bytes on the line (each direction) garbled: about 40 % of
/// the 20-byte frames, so most writes lose a frame somewhere.
const CORRUPT_RATE: f64 = 0.025;
/// A reply given up on after this (not the rig's 500 ms): lost replies are
/// the point here, and each costs one wait.
const REPLY_MARGIN_US: u64 = 15_000;

/// The `n`th write: RAM settings in four INFO blocks in turn, each value
/// unique to its write.
fn nth_write(n: u16) -> (ConfigParam, u8) {
    let v = n / 4;
    match n % 4 {
        0 => (ConfigParam::MaxCur(1000 + v), index::MAX_CUR),
        1 => (ConfigParam::CurLv1DelayMs(2000 + v), index::CUR_LV1_DELAY),
        2 => (ConfigParam::PosKp(3000 + v), index::SET_POS_KP),
        _ => (ConfigParam::ColdTime(100 + v as u8), index::COLD_TIME),
    }
}

#[derive(Debug, Default)]
struct Tally {
    written: u32,
    unverified: u32,
    not_written: u32,
    /// Of `not_written`: failures other than a read-back showing another
    /// value (a timeout). A write that went out is never one.
    other_errors: u32,
    contradictions: Vec<String>,
}

#[tokio::test]
async fn no_write_outcome_contradicts_the_device_under_corruption() {
    let rig = rig_with(sim_config(&[1], BAUD), |c| {
        c.timing.reply_margin_us = REPLY_MARGIN_US
    });
    rig.online(1).await;
    rig.sim.inject(Fault::CorruptRate(CORRUPT_RATE));
    let started = std::time::Instant::now();
    let mut t = Tally::default();
    for n in 0..WRITES {
        let (param, idx) = nth_write(n);
        let value = param.index_value().1;
        let result = rig.bus.write_config(1, param).await;
        let has = rig.sim.device(1).expect("device 1").params.raw(idx) == value;
        let contradiction = match &result {
            Ok(_) => {
                t.written += 1;
                !has
            }
            Err(BusError::Unverified { .. }) => {
                t.unverified += 1;
                false
            }
            Err(BusError::VerifyMismatch { .. }) => {
                t.not_written += 1;
                has
            }
            // Any other failure (a timeout) says "not written" too.
            Err(_) => {
                t.not_written += 1;
                t.other_errors += 1;
                has
            }
        };
        if contradiction {
            t.contradictions.push(format!(
                "write {n} ({param:?}): {result:?}, device has it: {has}"
            ));
        }
    }
    rig.sim.inject(Fault::ClearAll);
    let stats = rig.sim.stats();
    println!(
        "{WRITES} writes at {CORRUPT_RATE} corruption in {:.1} s: written {}, unverified {}, \
         not_written {} (of which not a read-back mismatch: {}), contradictions {} \
         (simulator: {} replies corrupted)",
        started.elapsed().as_secs_f64(),
        t.written,
        t.unverified,
        t.not_written,
        t.other_errors,
        t.contradictions.len(),
        stats.corrupted_replies,
    );
    assert!(t.contradictions.is_empty(), "{:#?}", t.contradictions);
    assert_eq!(
        t.other_errors, 0,
        "a write that went out failed otherwise: {t:?}"
    );
    assert_eq!(t.written + t.unverified + t.not_written, u32::from(WRITES));
    assert!(t.written > 0, "the noise left nothing confirmed: {t:?}");
    assert!(stats.corrupted_replies > 0, "the noise never hit a reply");

    // The bus counts what it did about the noise.
    let unverified = u64::from(t.unverified);
    let snap = rig
        .until("counters published", |s| {
            s.counters.writes_unverified == unverified && s.counters.verify_retries > 0
        })
        .await;
    println!(
        "counters: verify_retries {}, writes_unverified {}",
        snap.counters.verify_retries, snap.counters.writes_unverified
    );
}
