//! A latent (USB) adapter: control frames ride in front of a poll in one
//! write; reply deadlines cover the adapter's hold; a native line never
//! batches.

use super::*;
use crate::transport::adapter::AdapterModel;

fn batches(slots: &[Slot]) -> Vec<(usize, u8)> {
    slots
        .iter()
        .filter_map(|s| match s {
            Slot::Batch {
                control, dev_id, ..
            } => Some((control.len(), *dev_id)),
            _ => None,
        })
        .collect()
}

fn streaming(adapter: Option<AdapterModel>) -> Vec<Slot> {
    let ids: Vec<u8> = (1..=16).collect();
    let mut b = Bus::new(&ids, &ids);
    if let Some(a) = adapter {
        b.s.set_adapter(a);
    }
    let mut slots = Vec::new();
    for k in 0..40 {
        // A new target for all 16 joints before every step: two broadcasts' worth.
        b.set(1..=16, 100 + k);
        slots.push(b.step(&[]));
    }
    slots
}

#[test]
fn on_a_usb_adapter_broadcasts_and_a_poll_share_one_write() {
    let slots = streaming(Some(AdapterModel::Ftdi { latency_ms: 1 }));
    let b = batches(&slots);
    assert!(!b.is_empty(), "{slots:?}");
    // Both broadcasts of 16 joints ride in front of the poll.
    assert!(b.iter().any(|(n, _)| *n == 2), "{b:?}");
    assert!(
        b.iter().all(|(n, _)| (1..=MAX_BATCHED).contains(n)),
        "{b:?}"
    );
}

#[test]
fn a_native_line_never_batches() {
    let slots = streaming(None);
    assert!(batches(&slots).is_empty());
    assert!(!polls(&slots).is_empty() && !controls(&slots).is_empty());
}

#[test]
fn reply_deadlines_cover_the_adapter_hold() {
    let mut b = Bus::new(&[1], &[1]);
    let native = b.s.reply_window(b.now);
    b.s.set_adapter(AdapterModel::Ftdi { latency_ms: 16 });
    let ftdi = b.s.reply_window(b.now);
    // The reply is expected after the 16 ms timer and a USB frame, and the
    // deadline covers the write's own wait for a frame as well.
    assert_eq!(ftdi.due - native.due, Duration::from_millis(17));
    assert_eq!(ftdi.deadline - native.deadline, Duration::from_millis(18));
}
