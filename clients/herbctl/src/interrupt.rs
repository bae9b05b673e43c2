//! Ctrl-C (SIGINT), SIGTERM and SIGHUP while `herbctl pack` runs: a handler counts them and
//! does nothing else; the pack loop reads the count, cancels its job on the first and exits
//! without waiting on the next.

use std::sync::atomic::{AtomicUsize, Ordering};

/// The signals received since [`catch`].
static SIGNALS: AtomicUsize = AtomicUsize::new(0);

/// The exit code after a signal: SIGINT's conventional 128 + 2 (the `ctrlc` crate does not
/// say which signal came, so SIGTERM and SIGHUP end with it too).
pub(crate) const EXIT_CODE: u8 = 130;

/// Counts SIGINT, SIGTERM and SIGHUP from now on instead of dying of them (once a process).
pub(crate) fn catch() -> Result<(), String> {
    ctrlc::set_handler(|| {
        SIGNALS.fetch_add(1, Ordering::SeqCst);
    })
    .map_err(|e| e.to_string())
}

/// How many signals came since [`catch`].
pub(crate) fn count() -> usize {
    SIGNALS.load(Ordering::SeqCst)
}
