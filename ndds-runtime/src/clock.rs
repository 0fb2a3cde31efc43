//! The monotonic clock habitats schedule against, an absolute sleep on it, and the calls that
//! make a habitat's thread real-time (timer slack, `SCHED_FIFO`, CPU pinning).
//!
//! Sleeping until an absolute time (not for a duration) is what keeps a periodic task from
//! drifting: a late wake-up delays one sample, not every later one.
//!
//! Every call goes through `nix` except `sched_setscheduler`, which `nix` does not wrap (it has
//! no scheduling-policy call at all); that one stays a `libc` call.

use std::time::Duration;

use nix::errno::Errno;
use nix::sched::{CpuSet, sched_setaffinity};
use nix::sys::time::TimeSpec;
use nix::time::{ClockId, ClockNanosleepFlags, clock_gettime, clock_nanosleep};
use nix::unistd::Pid;

/// The calling thread, as the `sched_*` calls name it.
const THIS_THREAD: Pid = Pid::from_raw(0);

/// Nanoseconds on `CLOCK_MONOTONIC`.
pub(crate) fn now_ns() -> u64 {
    let now = clock_gettime(ClockId::CLOCK_MONOTONIC)
        .expect("CLOCK_MONOTONIC exists on every Linux kernel and cannot fail to read");
    ns(Duration::from(now))
}

/// Sleeps until `deadline_ns` on `CLOCK_MONOTONIC` (returns at once if it has passed).
pub(crate) fn sleep_until_ns(deadline_ns: u64) {
    let deadline = TimeSpec::from(Duration::from_nanos(deadline_ns));
    loop {
        let slept = clock_nanosleep(
            ClockId::CLOCK_MONOTONIC,
            ClockNanosleepFlags::TIMER_ABSTIME,
            &deadline,
        );
        if !matches!(slept, Err(Errno::EINTR)) {
            return;
        }
    }
}

/// Makes this thread's timer wake-ups precise (the default slack is 50 µs).
pub(crate) fn tighten_timer_slack() {
    // Best effort: a thread that keeps the default slack still runs, only less precisely.
    let _ = nix::sys::prctl::set_timerslack(1);
}

/// Asks for `SCHED_FIFO` at `priority` for this thread.
pub(crate) fn set_realtime(priority: i32) -> std::io::Result<()> {
    // `nix` has no `sched_setscheduler` (nor any call that sets a scheduling policy), so this
    // one call stays on `libc`.
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: `param` is a valid sched_param that outlives the call; pid 0 is this thread.
    let rc = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// Pins the calling thread to CPU `cpu` (an error if the system has no such CPU, or if `cpu`
/// is outside the kernel's CPU set).
pub fn pin_to_cpu(cpu: usize) -> std::io::Result<()> {
    let mut set = CpuSet::new();
    set.set(cpu)?;
    sched_setaffinity(THIS_THREAD, &set)?;
    Ok(())
}

/// `d` in nanoseconds, saturating.
pub(crate) fn ns(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}
