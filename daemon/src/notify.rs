//! systemd's notify protocol for herbd (`Type=notify`, `WatchdogSec=`): `READY=1` once the
//! models are loaded and the ports are open, `WATCHDOG=1` while the loop's cycle counter
//! advances, `STOPPING=1` as soon as a stop is asked (SIGTERM, SIGINT, `--run-for`).
//!
//! Without `NOTIFY_SOCKET` (herbd started by hand) nothing is sent and nothing fails. A
//! notification that fails (the socket gone, a full queue) is logged once per kind, never
//! dropped in silence; later failures of that kind are counted and the count is logged at the
//! end. Called from the main and the reporter threads, never from the loop.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// The notifications herbd sends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Notice {
    /// `READY=1`.
    Ready,
    /// `WATCHDOG=1`.
    Watchdog,
    /// `STOPPING=1`.
    Stopping,
}

impl Notice {
    const ALL: [Notice; 3] = [Notice::Ready, Notice::Watchdog, Notice::Stopping];

    fn state(self) -> sd_notify::NotifyState<'static> {
        match self {
            Notice::Ready => sd_notify::NotifyState::Ready,
            Notice::Watchdog => sd_notify::NotifyState::Watchdog,
            Notice::Stopping => sd_notify::NotifyState::Stopping,
        }
    }

    /// The protocol's text, as sent.
    pub fn text(self) -> &'static str {
        match self {
            Notice::Ready => "READY=1",
            Notice::Watchdog => "WATCHDOG=1",
            Notice::Stopping => "STOPPING=1",
        }
    }
}

/// Sends the notices and remembers their failures (module docs).
#[derive(Debug, Default)]
pub struct Notifier {
    failed: [AtomicU64; 3],
    stopping_sent: AtomicBool,
}

impl Notifier {
    /// A notifier that has sent nothing yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Sends `notice`; the first failure of each kind is logged to stderr with its error.
    pub fn send(&self, notice: Notice) {
        if notice == Notice::Stopping && self.stopping_sent.swap(true, Ordering::Relaxed) {
            return;
        }
        if let Err(e) = sd_notify::notify(false, &[notice.state()]) {
            self.failed(notice, &e);
        }
    }

    fn failed(&self, notice: Notice, e: &std::io::Error) {
        let n = self.failed[notice as usize].fetch_add(1, Ordering::Relaxed);
        if n == 0 {
            crate::logfmt::log(
                "notify_failed",
                &[
                    ("notice", &notice.text()),
                    (
                        "socket",
                        &std::env::var_os("NOTIFY_SOCKET")
                            .unwrap_or_default()
                            .to_string_lossy(),
                    ),
                    ("error", &e),
                    ("further", &"counted, not logged"),
                ],
            );
        }
    }

    /// How many notices of each kind failed, for the final report: `(text, count)` for the
    /// kinds that failed at least once.
    pub fn failures(&self) -> Vec<(&'static str, u64)> {
        Notice::ALL
            .iter()
            .map(|&k| (k.text(), self.failed[k as usize].load(Ordering::Relaxed)))
            .filter(|&(_, n)| n > 0)
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failure_is_counted_per_kind_and_stopping_is_sent_once() {
        let n = Notifier::new();
        let e = std::io::Error::other("fixture error");
        n.failed(Notice::Watchdog, &e);
        n.failed(Notice::Watchdog, &e);
        n.failed(Notice::Ready, &e);
        assert_eq!(n.failures(), vec![("READY=1", 1), ("WATCHDOG=1", 2)]);
        // STOPPING is sent once however often a stop is seen (the test runs without
        // NOTIFY_SOCKET, where sending is a no-op).
        n.send(Notice::Stopping);
        assert!(n.stopping_sent.load(Ordering::Relaxed));
        n.send(Notice::Stopping);
        assert_eq!(n.failures().len(), 2);
    }
}
