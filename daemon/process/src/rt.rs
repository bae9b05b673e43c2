//! Real-time timing for fixed-rate loops (herbd's control loop, an adapter's publishing loop):
//! the process setup (memory locking, SCHED_FIFO, CPU pinning) and an absolute-deadline sleep on
//! CLOCK_MONOTONIC, the clock every stamp on the wire uses (`herb_ipc::monotonic_ns`).

use herb_ipc::monotonic_ns;
use serde::{Deserialize, Serialize};

/// Optional real-time setup; each step that is not permitted degrades to a warning.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RtConfig {
    /// Lock all memory (mlockall).
    pub mlockall: bool,
    /// SCHED_FIFO priority of the loop thread (1-99); 0 keeps the default scheduler.
    pub fifo_priority: i32,
    /// CPU to pin the loop thread to; none when absent.
    pub cpu: Option<usize>,
}

/// Applies `rt` to the calling thread (and, for memory locking, the process). Returns one
/// message per step that was not permitted; the caller reports them and runs on without.
pub fn apply(rt: &RtConfig) -> Vec<String> {
    let mut warnings = Vec::new();
    if rt.mlockall {
        // SAFETY: plain syscall.
        if unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } != 0 {
            warnings.push(format!(
                "mlockall failed ({}); memory may page",
                std::io::Error::last_os_error()
            ));
        }
    }
    if rt.fifo_priority > 0 {
        let p = libc::sched_param {
            sched_priority: rt.fifo_priority,
        };
        // SAFETY: plain syscall on the calling thread.
        if unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &p) } != 0 {
            warnings.push(format!(
                "SCHED_FIFO {} not permitted ({}); running with the default scheduler",
                rt.fifo_priority,
                std::io::Error::last_os_error()
            ));
        }
    }
    if let Some(cpu) = rt.cpu {
        // SAFETY: a zeroed cpu_set_t is valid; CPU_SET indexes within it.
        unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            libc::CPU_SET(cpu, &mut set);
            if libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) != 0 {
                warnings.push(format!(
                    "pinning to CPU {cpu} failed ({})",
                    std::io::Error::last_os_error()
                ));
            }
        }
    }
    warnings
}

/// Sets the calling thread's timer slack to 1 ns (Linux's default 50 us delays every
/// wake-up from `clock_nanosleep` by up to that much).
pub fn set_timer_slack() {
    // SAFETY: plain prctl on the calling thread.
    unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong) };
}

/// Sleeps until `deadline` (CLOCK_MONOTONIC ns), busy-waiting the last `spin_ns`.
pub fn sleep_until(deadline: u64, spin_ns: u64) {
    let wake = deadline.saturating_sub(spin_ns);
    let ts = libc::timespec {
        tv_sec: (wake / 1_000_000_000) as libc::time_t,
        tv_nsec: (wake % 1_000_000_000) as libc::c_long,
    };
    // SAFETY: clock_nanosleep with an absolute time reads one timespec; EINTR just retries.
    while unsafe {
        libc::clock_nanosleep(
            libc::CLOCK_MONOTONIC,
            libc::TIMER_ABSTIME,
            &ts,
            std::ptr::null_mut(),
        )
    } == libc::EINTR
    {}
    while spin_ns > 0 && monotonic_ns() < deadline {
        std::hint::spin_loop();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sleep_until_does_not_wake_before_its_deadline() {
        for spin in [0, 50_000] {
            let deadline = monotonic_ns() + 2_000_000;
            sleep_until(deadline, spin);
            assert!(monotonic_ns() >= deadline, "woke early with spin {spin} ns");
        }
    }

    #[test]
    fn an_empty_setup_changes_nothing_and_warns_of_nothing() {
        assert!(apply(&RtConfig::default()).is_empty());
    }
}
