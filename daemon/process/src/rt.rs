//! Real-time timing for fixed-rate loops (herbd's control loop, an adapter's publishing loop):
//! the process setup (memory locking, SCHED_FIFO, a held CPU latency request, CPU pinning) and
//! an absolute-deadline sleep on CLOCK_MONOTONIC, the clock every stamp on the wire uses
//! (`herb_ipc::monotonic_ns`).
//!
//! [`apply`] is called by the loop's own thread after every other thread of the process has
//! been started: SCHED_FIFO is a property of the calling thread (threads it starts later
//! inherit it), so the threads started before it (search, planner, recording, reporter) stay
//! at normal priority and the loop preempts them, never the other way round.

use herb_ipc::monotonic_ns;
use serde::{Deserialize, Serialize};
use std::io::Write;

/// The device through which a process asks the kernel to keep every CPU's wake-up latency at
/// most a given number of microseconds (PM QoS), for as long as it holds the file open.
pub const CPU_LATENCY_DEVICE: &str = "/dev/cpu_dma_latency";

/// The real-time setup of a loop thread; each step that is not permitted degrades to one
/// warning ([`RtSetup::warning`]) and the loop runs without it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RtConfig {
    /// Lock all memory (mlockall: what is mapped now, and what is mapped later as it is first
    /// touched), so that the loop never waits for a page to come back from disk.
    pub mlockall: bool,
    /// SCHED_FIFO priority of the loop thread (1-99); 0 keeps the default scheduler.
    pub fifo_priority: i32,
    /// Hold a CPU latency request of 0 us ([`CPU_LATENCY_DEVICE`]) while the loop runs, so an
    /// idle core is not put into a deep sleep state between cycles (its wake-up would make the
    /// loop late), as cyclictest does.
    pub cpu_latency: bool,
    /// CPU to pin the loop thread to; none when absent.
    pub cpu: Option<usize>,
}

impl Default for RtConfig {
    /// Real time: memory locked, SCHED_FIFO 80, the CPU latency request held, no pinning.
    fn default() -> Self {
        Self {
            mlockall: true,
            fifo_priority: 80,
            cpu_latency: true,
            cpu: None,
        }
    }
}

impl RtConfig {
    /// No real-time setup at all: the default scheduler, memory not locked, no request.
    pub const OFF: Self = Self {
        mlockall: false,
        fifo_priority: 0,
        cpu_latency: false,
        cpu: None,
    };
}

/// What [`apply`] set up. Holds the CPU latency request: dropping it releases the request.
#[derive(Debug, Default)]
pub struct RtSetup {
    /// The steps that took effect, in words (`mlockall`, `SCHED_FIFO 80`, ...).
    pub applied: Vec<String>,
    /// The steps that were refused, each with the system's reason.
    pub refused: Vec<String>,
    /// The open latency device: the request lasts while it is open.
    latency: Option<std::fs::File>,
}

impl RtSetup {
    /// One line for the operator when a step was refused (none when everything took effect):
    /// what was refused and why, and that the loop runs without it.
    pub fn warning(&self) -> Option<String> {
        (!self.refused.is_empty()).then(|| {
            format!(
                "real time refused: {}; the loop runs without it and may miss deadlines (the \
                 unit herbd.service grants all of it; in a shell run as root, or set [rt] in \
                 the configuration to ask for less)",
                self.refused.join("; ")
            )
        })
    }

    /// True while the CPU latency request is held.
    pub fn holds_cpu_latency(&self) -> bool {
        self.latency.is_some()
    }
}

fn last_error() -> std::io::Error {
    std::io::Error::last_os_error()
}

/// Applies `rt` to the calling thread (and, for memory locking and the latency request, the
/// process). Every step is tried; the ones not permitted are listed in [`RtSetup::refused`] and
/// the caller runs on without them. Keep the returned value alive as long as the loop runs.
pub fn apply(rt: &RtConfig) -> RtSetup {
    let mut s = RtSetup::default();
    if rt.mlockall {
        // What is mapped now is locked (and faulted in) at once; later mappings are locked as
        // their pages are first touched (MCL_ONFAULT), so that a peer's shared-memory segment
        // mapped by the loop thread when it connects is not faulted in whole inside a cycle.
        // SAFETY: plain syscalls.
        let now = unsafe { libc::mlockall(libc::MCL_CURRENT) };
        let later = if now == 0 {
            unsafe { libc::mlockall(libc::MCL_FUTURE | libc::MCL_ONFAULT) }
        } else {
            now
        };
        if later == 0 {
            s.applied.push("mlockall".into());
        } else {
            s.refused.push(format!("mlockall ({})", last_error()));
            // SAFETY: plain syscall; undoes a partial lock.
            unsafe { libc::munlockall() };
        }
    }
    if rt.fifo_priority > 0 {
        let p = libc::sched_param {
            sched_priority: rt.fifo_priority,
        };
        // SAFETY: plain syscall on the calling thread (pid 0: this thread only).
        if unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &p) } == 0 {
            s.applied.push(format!("SCHED_FIFO {}", rt.fifo_priority));
        } else {
            s.refused.push(format!(
                "SCHED_FIFO {} ({})",
                rt.fifo_priority,
                last_error()
            ));
        }
    }
    if rt.cpu_latency {
        let opened = std::fs::OpenOptions::new()
            .write(true)
            .open(CPU_LATENCY_DEVICE)
            .and_then(|mut f| f.write_all(&0i32.to_ne_bytes()).map(|_| f));
        match opened {
            Ok(f) => {
                s.latency = Some(f);
                s.applied.push(format!("{CPU_LATENCY_DEVICE} 0 us"));
            }
            Err(e) => s.refused.push(format!("{CPU_LATENCY_DEVICE} ({e})")),
        }
    }
    if let Some(cpu) = rt.cpu {
        // SAFETY: a zeroed cpu_set_t is valid; CPU_SET indexes within it.
        let pinned = unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            if cpu < libc::CPU_SETSIZE as usize {
                libc::CPU_SET(cpu, &mut set);
            }
            libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) == 0
        };
        if pinned {
            s.applied.push(format!("pinned to CPU {cpu}"));
        } else {
            s.refused
                .push(format!("pinning to CPU {cpu} ({})", last_error()));
        }
    }
    s
}

/// The calling thread's scheduling policy and priority (`SCHED_OTHER` is 0).
pub fn thread_policy() -> (i32, i32) {
    // SAFETY: plain syscalls on the calling thread; sched_param is plain data.
    unsafe {
        let policy = libc::sched_getscheduler(0);
        let mut p: libc::sched_param = std::mem::zeroed();
        libc::sched_getparam(0, &mut p);
        (policy, p.sched_priority)
    }
}

/// The calling thread's counters since it started: minor and major page faults, voluntary
/// context switches (it blocked: a lock, I/O, a sleep) and involuntary ones (it was preempted).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ThreadCounters {
    /// Minor page faults (a page mapped without I/O).
    pub minflt: u64,
    /// Major page faults (a page read from disk).
    pub majflt: u64,
    /// Voluntary context switches.
    pub nvcsw: u64,
    /// Involuntary context switches.
    pub nivcsw: u64,
}

impl ThreadCounters {
    /// The calling thread's counters now (one `getrusage`, no allocation).
    pub fn now() -> Self {
        // SAFETY: getrusage writes one rusage; a zeroed rusage is valid.
        let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
        unsafe { libc::getrusage(libc::RUSAGE_THREAD, &mut ru) };
        Self {
            minflt: ru.ru_minflt as u64,
            majflt: ru.ru_majflt as u64,
            nvcsw: ru.ru_nvcsw as u64,
            nivcsw: ru.ru_nivcsw as u64,
        }
    }

    /// What happened between `earlier` and `self`.
    pub fn since(self, earlier: Self) -> Self {
        Self {
            minflt: self.minflt.saturating_sub(earlier.minflt),
            majflt: self.majflt.saturating_sub(earlier.majflt),
            nvcsw: self.nvcsw.saturating_sub(earlier.nvcsw),
            nivcsw: self.nivcsw.saturating_sub(earlier.nivcsw),
        }
    }
}

/// Ends the process at once with `code`, running nothing on the way (no destructor, no
/// `atexit` handler, no flush of a possibly blocked stdout): for a shutdown's deadline.
pub fn exit_now(code: i32) -> ! {
    // SAFETY: _exit has no preconditions.
    unsafe { libc::_exit(code) }
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
        let s = apply(&RtConfig::OFF);
        assert!(s.applied.is_empty() && s.refused.is_empty());
        assert_eq!(s.warning(), None);
        assert!(!s.holds_cpu_latency());
    }

    #[test]
    fn the_default_is_real_time() {
        let d = RtConfig::default();
        assert!(d.mlockall && d.cpu_latency && d.fifo_priority == 80 && d.cpu.is_none());
    }

    #[test]
    fn each_step_either_takes_effect_or_is_named_in_one_warning() {
        // SCHED_FIFO on a thread of its own (the test runner's threads stay as they are).
        std::thread::spawn(|| {
            let rt = RtConfig {
                mlockall: false,
                ..RtConfig::default()
            };
            let s = apply(&rt);
            assert_eq!(s.applied.len() + s.refused.len(), 2, "{s:?}");
            let (policy, prio) = thread_policy();
            if s.applied.iter().any(|a| a == "SCHED_FIFO 80") {
                assert_eq!((policy, prio), (libc::SCHED_FIFO, 80));
            } else {
                assert_eq!(policy, libc::SCHED_OTHER);
                let w = s.warning().expect("a refused step warns");
                assert!(w.contains("SCHED_FIFO 80 ("), "{w}");
            }
            assert_eq!(
                s.holds_cpu_latency(),
                s.applied.iter().any(|a| a.contains(CPU_LATENCY_DEVICE))
            );
            // A thread started by a real-time thread inherits its policy; the loop therefore
            // applies real time after starting every other thread.
            let child = std::thread::spawn(thread_policy).join().unwrap();
            assert_eq!(child, (policy, prio));
        })
        .join()
        .unwrap();
    }
}
