//! `--keep-cpus-awake`: one idle-class busy thread per CPU while the bench
//! runs, so no CPU halts.
//!
//! On a virtual machine a halted vCPU takes tens of µs to wake (the
//! hypervisor has to schedule it again), and every frame crosses the pty to
//! a thread that was asleep: the referee then timestamps a host frame when
//! its vCPU woke, not when the daemon wrote it, and the gap after each reply
//! grows by that much. `SCHED_IDLE` threads give way to every other thread
//! at once, so they change nothing but the halting. The daemon's CPU
//! figures do not include them (they are counted by thread name).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;

/// Thread name of the busy threads (not a prefix the CPU report charges).
const THREAD: &str = "bench-awake";

/// The running busy threads; dropping it stops them.
pub struct KeepAwake {
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
}

impl KeepAwake {
    /// Starts one busy thread per CPU this process may run on.
    pub fn start() -> std::io::Result<Self> {
        let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
        // Built up in place: on an error, dropping it stops what started.
        let mut awake = Self {
            stop: Arc::new(AtomicBool::new(false)),
            threads: Vec::with_capacity(cpus),
        };
        for _ in 0..cpus {
            let stop = awake.stop.clone();
            let thread = std::thread::Builder::new()
                .name(THREAD.into())
                .spawn(move || spin(&stop))?;
            awake.threads.push(thread);
        }
        Ok(awake)
    }
}

fn spin(stop: &AtomicBool) {
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: pid 0 is this thread; `param` is a valid sched_param.
    if unsafe { libc::sched_setscheduler(0, libc::SCHED_IDLE, &param) } != 0 {
        // At normal priority a busy thread would compete with the bench: leave.
        tracing::warn!(
            "--keep-cpus-awake: SCHED_IDLE refused: {}",
            std::io::Error::last_os_error()
        );
        return;
    }
    while !stop.load(Ordering::Relaxed) {
        std::hint::spin_loop();
    }
}

impl Drop for KeepAwake {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use std::time::{Duration, Instant};

    /// Busy threads that named themselves and are in the idle class.
    fn idle_class_spinners() -> usize {
        super::super::cpu::tids(THREAD)
            .into_iter()
            // SAFETY: a plain query by thread id.
            .filter(|tid| unsafe { libc::sched_getscheduler(*tid) } == libc::SCHED_IDLE)
            .count()
    }

    #[test]
    fn one_idle_class_thread_per_cpu_and_they_stop() {
        let awake = KeepAwake::start().expect("spawn");
        let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
        assert_eq!(awake.threads.len(), cpus);
        // Each thread names itself and switches class when it starts.
        let deadline = Instant::now() + Duration::from_secs(5);
        while idle_class_spinners() < cpus && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(5));
        }
        assert_eq!(idle_class_spinners(), cpus);
        drop(awake);
        assert!(super::super::cpu::tids(THREAD).is_empty(), "joined on drop");
    }
}
