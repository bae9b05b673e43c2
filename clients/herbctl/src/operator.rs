//! `herbctl pack --operator`: a person feeds the pick station. herbd asks for each try of each
//! pick (`AwaitingObject`) and holds the arm above the station until herbctl confirms, on the
//! operator's Enter or after `--operator-wait`.

use herb_ipc::Status;
use std::io::BufRead;
use std::sync::mpsc::{Receiver, channel};
use std::time::{Duration, Instant};

/// The operator's Enter presses, one message each, read on a thread of their own (a read of
/// the terminal blocks). The thread ends with the input (closed, or not a terminal that
/// answers): then nothing is ever confirmed by Enter.
pub(crate) fn enter_presses() -> Receiver<()> {
    let (tx, rx) = channel();
    let spawned = std::thread::Builder::new()
        .name("herbctl-enter".into())
        .spawn(move || {
            for line in std::io::stdin().lock().lines() {
                if line.is_err() || tx.send(()).is_err() {
                    break;
                }
            }
        });
    if let Err(e) = spawned {
        eprintln!("herbctl: warning: cannot read Enter presses ({e}): use --operator-wait");
    }
    rx
}

/// A pick herbd waits to have confirmed: which object and try, and when herbctl confirms by
/// itself (`--operator-wait`), if it does.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Awaiting {
    /// The object's index in the packing order.
    pub index: u32,
    /// The pick's try.
    pub attempt: u32,
    /// Confirmed by itself at this time (`None`: on Enter only).
    pub at: Option<Instant>,
}

impl Awaiting {
    /// What `s` (an `AwaitingObject` status) asks for, confirmed by itself after `wait`.
    pub fn new(s: &Status, wait: Option<Duration>) -> Self {
        Self {
            index: s.object_index,
            attempt: s.attempt,
            at: wait.map(|w| Instant::now() + w),
        }
    }

    /// Whether to confirm now: the wait ran out, or the operator pressed Enter (`enter`).
    pub fn due(&self, enter: Option<&Receiver<()>>) -> bool {
        self.at.is_some_and(|t| Instant::now() >= t)
            || enter.is_some_and(|rx| rx.try_recv().is_ok())
    }
}
