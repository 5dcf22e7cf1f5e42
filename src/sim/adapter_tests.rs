use super::*;
use crate::sim::line::MemoryLine;
use crate::transport::Transport;

#[test]
fn the_hosts_count_falls_at_the_frame_however_late_the_model_reads() {
    let (mut host, dev) = crate::transport::memory::pair(500_000);
    let mut line = AdapterLine::new(
        Box::new(MemoryLine::new(dev)),
        AdapterModel::Ch340,
        Instant::now(),
        7,
        WriteDelayCell::default(),
    );
    let before = Instant::now();
    host.write_all(&[1, 2, 3]).unwrap();
    // The model's thread does not read the line (held off its CPU):
    // a driver's count falls when the adapter takes the transfer all
    // the same.
    let deadline = before + Duration::from_secs(2);
    let fell = loop {
        if host.unsent() == Some(0) {
            break Instant::now();
        }
        assert!(
            Instant::now() < deadline,
            "the count stayed up while the model did not read"
        );
        std::thread::sleep(Duration::from_micros(100));
    };
    // Read late, the bytes reach the wire at the frame the count named.
    let mut buf = [0u8; 8];
    assert_eq!(line.read_timeout(&mut buf, Duration::ZERO).unwrap(), 3);
    let on_wire = line.take_read_at().expect("dated on the wire");
    assert!(on_wire > before && on_wire <= fell, "{on_wire:?} {fell:?}");
    assert_eq!(host.unsent(), Some(0));
}

fn ms(n: u64) -> Duration {
    Duration::from_millis(n)
}

#[test]
fn frame_boundaries_follow_the_period_and_phase() {
    let t0 = Instant::now();
    let c = UsbClock::new(t0, ms(1), Duration::from_micros(300));
    assert_eq!(c.next_after(t0), t0 + Duration::from_micros(300));
    assert_eq!(
        c.next_after(t0 + Duration::from_micros(300)),
        t0 + Duration::from_micros(1300)
    );
    assert_eq!(
        c.next_after(t0 + Duration::from_micros(1299)),
        t0 + Duration::from_micros(1300)
    );
    let hs = UsbClock::new(t0, Duration::from_micros(125), Duration::ZERO);
    assert_eq!(
        hs.next_after(t0 + Duration::from_micros(130)),
        t0 + Duration::from_micros(250)
    );
}

#[test]
fn ftdi_holds_a_short_reply_for_its_timer_and_a_full_packet_not() {
    let t0 = Instant::now();
    let c = UsbClock::new(t0, ms(1), Duration::ZERO);
    let ftdi = RxRule::of(AdapterModel::Ftdi { latency_ms: 16 });
    let got = t0 + Duration::from_micros(2500);
    let held = |n: usize| vec![got; n];
    assert_eq!(ftdi.release(&c, &[]), None);
    // A 20-byte reply: first byte + 16 ms, then the next frame.
    assert_eq!(ftdi.release(&c, &held(20)), Some(t0 + ms(19)));
    // 62 bytes: the next frame after the 62nd, whatever came after it.
    assert_eq!(ftdi.release(&c, &held(62)), Some(t0 + ms(3)));
    let mut times = held(61);
    times.push(t0 + Duration::from_micros(3100));
    times.push(t0 + Duration::from_micros(4100));
    assert_eq!(ftdi.release(&c, &times), Some(t0 + ms(4)));
    assert_eq!(ftdi.packet(80), 62);
    let ftdi1 = RxRule::of(AdapterModel::Ftdi { latency_ms: 1 });
    assert_eq!(ftdi1.release(&c, &held(20)), Some(t0 + ms(4)));
    // No timer: the next frame after the last byte, all of them.
    let ch340 = RxRule::of(AdapterModel::Ch340);
    assert_eq!(ch340.release(&c, &held(20)), Some(t0 + ms(3)));
    assert_eq!(ch340.packet(80), 80);
    let hs = UsbClock::new(t0, Duration::from_micros(125), Duration::ZERO);
    let ft232h = RxRule::of(AdapterModel::Ft232h { latency_ms: 1 });
    assert_eq!(
        ft232h.release(&hs, &held(20)),
        Some(t0 + Duration::from_micros(3625))
    );
}
