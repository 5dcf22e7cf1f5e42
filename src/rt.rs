//! Real-time helpers for the threads that pace a wire (the bus owner, the
//! simulator, the bench's clients): precise timers and the FIFO class. One
//! copy, so the daemon and the simulator it is measured against ask the
//! kernel for the same thing.
//!
//! Also the other way: [`lower_priority`] for the threads that must give
//! way to the wire and the API (recordings, the live Foxglove view).
//!
//! - [`wake`]: how late a thread wakes from a timed sleep, learnt from its
//!   own sleeps (how early to stop sleeping and spin).
//! - [`skewed`]: the estimate both learn with, faster one way than the other.

pub(crate) mod skewed;
pub(crate) mod wake;

/// Makes this thread's timed waits precise: Linux otherwise lets a timer fire
/// up to 50 µs late (timer slack), an eighth of a frame at 500000 baud.
pub fn precise_timers() {
    /// The smallest slack the kernel accepts (0 would mean "reset to default").
    const SLACK_NS: libc::c_ulong = 1;
    // SAFETY: PR_SET_TIMERSLACK takes one integer argument and touches no memory.
    let rc = unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, SLACK_NS, 0, 0, 0) };
    if rc != 0 {
        tracing::debug!(
            "PR_SET_TIMERSLACK failed: {}",
            std::io::Error::last_os_error()
        );
    }
}

/// Puts thread `tid` (0: the calling thread) in the real-time FIFO class at
/// `priority` (1..=99), so other work on the machine cannot hold it back for
/// milliseconds while the wire waits. Needs CAP_SYS_NICE or an RTPRIO limit.
pub fn set_fifo(tid: libc::pid_t, priority: u8) -> std::io::Result<()> {
    let param = libc::sched_param {
        sched_priority: libc::c_int::from(priority),
    };
    // SAFETY: a valid sched_param; on Linux the pid argument names a thread.
    if unsafe { libc::sched_setscheduler(tid, libc::SCHED_FIFO, &param) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

/// Lowers the calling thread's priority to `nice` (Linux: nice applies per
/// thread), for work that a busy host should slow before the buses and the
/// API; a refusal is only logged.
pub fn lower_priority(nice: libc::c_int) {
    // SAFETY: gettid and setpriority take integers and touch no memory; a
    // tid names the calling thread for PRIO_PROCESS on Linux.
    let rc = unsafe {
        let tid = libc::gettid();
        libc::setpriority(libc::PRIO_PROCESS, tid as libc::id_t, nice)
    };
    if rc != 0 {
        tracing::debug!(
            "setpriority({nice}) of this thread failed: {}",
            std::io::Error::last_os_error()
        );
    }
}
