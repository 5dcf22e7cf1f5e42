//! The live view's feed: a thread that drains every bus's taps every few
//! milliseconds with the recorder's own [`BusTap`] and logs each message
//! on its channel, with the log time a recording gives it.
//!
//! A thread, as the recorder's: decoding frames into joint states and
//! encoding JSON is CPU work that must not hold an async worker (and the
//! requests queued behind it), and it runs at a lower priority, so a busy
//! host slows the live view, never the buses or the API. Nothing here
//! waits on anyone: the taps are read with `try_recv` (the bus owner never
//! waits for the feed; a feed too far behind loses the oldest, counted),
//! and logging hands a message to each subscribed client's bounded queue
//! without waiting (see `server`'s backlog). A message of a channel no
//! client subscribes to is not encoded at all.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use ::foxglove::PartialMetadata;

use super::server::BusChannels;
use crate::control::foxglove_stats::FoxgloveStats;
use crate::record::channels::Topic;
use crate::record::tap::BusTap;

/// How often the taps are drained (well under a poll round).
const DRAIN_EVERY: Duration = Duration::from_millis(5);
/// The feed's nice value: as a recording's, below the API's and the buses'.
const FEED_NICE: libc::c_int = 10;

/// The running feed; dropping it stops the thread.
pub(super) struct Feed {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Feed {
    /// Starts draining `buses` (each bus's taps and its live channels).
    pub(super) fn spawn(
        buses: Vec<(BusTap, BusChannels)>,
        stats: Arc<FoxgloveStats>,
    ) -> std::io::Result<Self> {
        let stop = Arc::new(AtomicBool::new(false));
        let thread_stop = stop.clone();
        let thread = std::thread::Builder::new()
            .name("foxglove".into())
            .spawn(move || {
                crate::rt::lower_priority(FEED_NICE);
                run(buses, &stats, &thread_stop);
            })?;
        Ok(Self {
            stop,
            thread: Some(thread),
        })
    }

    /// Stops the thread and waits for it (at most one drain).
    pub(super) fn stop(mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

impl Drop for Feed {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
    }
}

fn run(mut buses: Vec<(BusTap, BusChannels)>, stats: &FoxgloveStats, stop: &AtomicBool) {
    while !stop.load(Ordering::Acquire) {
        std::thread::sleep(DRAIN_EVERY);
        for (tap, channels) in buses.iter_mut() {
            drain(tap, channels, stats);
        }
        let lost: u64 = buses.iter().map(|(tap, _)| tap.lost()).sum();
        stats.lost.store(lost, Ordering::Relaxed);
    }
}

/// Everything one bus's taps hold now, logged on the channels a client
/// subscribes to.
fn drain(tap: &mut BusTap, channels: &BusChannels, stats: &FoxgloveStats) {
    let wanted = |topic: Topic| channels.get(topic).is_some_and(|c| c.has_sinks());
    let logged = tap.drain(wanted, |topic, log_ns, data| {
        if let Some(channel) = channels.get(topic) {
            channel.log_with_meta(data, PartialMetadata::with_log_time(log_ns));
            stats.messages.fetch_add(1, Ordering::Relaxed);
        }
        Ok::<(), std::convert::Infallible>(())
    });
    // Logging cannot fail (the SDK keeps a client's errors to itself).
    let _ = logged;
}
