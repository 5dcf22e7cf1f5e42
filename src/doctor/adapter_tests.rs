use super::*;
use crate::doctor::check::Verdict;

fn count(writes: u32) -> CountFacts {
    CountFacts {
        readable: true,
        writes,
        ..CountFacts::default()
    }
}

#[test]
fn a_count_that_never_falls_fails_with_usb_confirm_off() {
    let c = CountFacts {
        never_fell: 3,
        ..count(3)
    };
    let check = count_check(&c, true);
    assert_eq!(check.verdict, Verdict::Fail);
    assert!(check
        .fix
        .unwrap_or_default()
        .contains("usb_confirm = false"));
    let at_once = CountFacts {
        zero_at_once: 5,
        ..count(5)
    };
    assert_eq!(count_check(&at_once, true).verdict, Verdict::Warn);
    let fine = CountFacts {
        fell: 40,
        fall: Spread::of(&[Duration::from_micros(600)]),
        ..count(40)
    };
    assert_eq!(count_check(&fine, true).verdict, Verdict::Ok);
    assert_eq!(
        count_check(&CountFacts::default(), false).verdict,
        Verdict::Skipped
    );
}

#[test]
fn falls_on_one_phase_of_the_frame_are_on_its_boundary() {
    let t0 = Instant::now();
    let ms = Duration::from_millis(1);
    let on: Vec<Instant> = (1..=40u32)
        .map(|k| t0 + ms * k + Duration::from_micros(30))
        .collect();
    assert_eq!(on_frame_boundary(&on, ms), Some(true));
    let spread: Vec<Instant> = (1..=40u32)
        .map(|k| t0 + ms * k + Duration::from_micros(u64::from(k * 97 % 1000)))
        .collect();
    assert_eq!(on_frame_boundary(&spread, ms), Some(false));
    assert_eq!(on_frame_boundary(&on[..5], ms), None);
}

#[test]
fn an_echo_and_a_long_timer_are_warnings_with_their_fix() {
    let t = Tally {
        writes: 10,
        echoes: 10,
        ..Tally::default()
    };
    let e = echo_check(&t);
    assert_eq!(e.verdict, Verdict::Warn);
    assert!(e.found.contains("echoes"));
    assert_eq!(
        echo_check(&Tally {
            writes: 10,
            ..Tally::default()
        })
        .verdict,
        Verdict::Ok
    );
    let timer = latency_check(AdapterModel::Ftdi { latency_ms: 16 }, Some(16), None, false);
    assert_eq!(timer.verdict, Verdict::Warn);
    assert!(timer.fix.unwrap_or_default().contains("sudo tee"));
    let set = latency_check(AdapterModel::Ftdi { latency_ms: 1 }, Some(16), None, false);
    assert_eq!(set.verdict, Verdict::Ok);
    assert_eq!(
        latency_check(AdapterModel::Ch340, None, None, false).verdict,
        Verdict::Skipped
    );
}
