//! The adapters' log lines on stderr, stamped the way herbd stamps its own
//! (`daemon/src/logfmt.rs`): under journald (which stamps each line itself; systemd sets
//! `$JOURNAL_STREAM` for a unit whose stderr goes to the journal) a line is written as is;
//! otherwise, run by hand, it starts with the UTC wall-clock time in ISO 8601 with
//! milliseconds:
//!
//! ```text
//! 2026-11-27T09:12:03.123Z herb-camera: first heightmap published
//! ```
//!
//! Write lines with [`log!`](crate::log!) (`eprintln!`'s arguments). A line is written in one
//! piece; a write that fails (stderr closed) is dropped, never a panic. An adapter's JSON
//! summary is not a log line: it goes to stdout as is ([`crate::finish`]).

use std::fmt::Arguments;
use std::time::{SystemTime, UNIX_EPOCH};

/// Writes one log line to stderr: `eprintln!`'s arguments, stamped unless stderr is journald
/// ([`emit`]).
///
/// ```
/// herb_adapter::log!("herb-camera: {} x {} cells", 224, 224);
/// ```
#[macro_export]
macro_rules! log {
    ($($arg:tt)*) => {
        $crate::log::emit(::std::format_args!($($arg)*))
    };
}

/// Writes `args` as one line to stderr: as is when `$JOURNAL_STREAM` is set (journald stamps
/// it), else after [`stamp`] of now and a space. Never panics.
pub fn emit(args: Arguments<'_>) {
    use std::io::Write;
    let journald = std::env::var_os("JOURNAL_STREAM").is_some();
    let text = line(journald, SystemTime::now(), args);
    let _ = std::io::stderr().lock().write_all(text.as_bytes());
}

/// The line [`emit`] writes, newline included.
fn line(journald: bool, now: SystemTime, args: Arguments<'_>) -> String {
    if journald {
        format!("{args}\n")
    } else {
        format!("{} {args}\n", stamp(now))
    }
}

/// `t` in UTC, ISO 8601 with milliseconds, e.g. `2026-11-27T09:12:03.123Z` (the form herbd's
/// log and `humantime::format_rfc3339_millis` write). Times before 1970 are written as 1970.
pub fn stamp(t: SystemTime) -> String {
    let since = t.duration_since(UNIX_EPOCH).unwrap_or_default();
    let secs = since.as_secs();
    let (days, s) = (secs / 86_400, secs % 86_400);
    let (y, m, d) = civil_from_days(days);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}.{:03}Z",
        s / 3600,
        s / 60 % 60,
        s % 60,
        since.subsec_millis()
    )
}

/// The proleptic Gregorian date (year, month 1-12, day 1-31) `days` after 1970-01-01 (Howard
/// Hinnant's `civil_from_days`, for days on or after the epoch).
fn civil_from_days(days: u64) -> (u64, u64, u64) {
    // Days from 0000-03-01, so that each 400-year era starts with March (leap day last).
    let z = days + 719_468;
    let era = z / 146_097;
    let doe = z % 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + u64::from(m <= 2);
    (y, m, d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn stamps_are_utc_iso_8601_with_milliseconds() {
        // Seconds since the epoch from `date -u -d ... +%s`.
        for (secs, ms, want) in [
            (0, 0, "1970-01-01T00:00:00.000Z"),
            (1_795_770_723, 123, "2026-11-27T09:12:03.123Z"),
            (1_709_251_199, 999, "2024-02-29T23:59:59.999Z"),
            (951_868_800, 7, "2000-03-01T00:00:00.007Z"),
            (4_133_937_600, 50, "2100-12-31T12:00:00.050Z"),
        ] {
            let t = UNIX_EPOCH + Duration::from_secs(secs) + Duration::from_millis(ms);
            assert_eq!(stamp(t), want);
        }
        let t = UNIX_EPOCH + Duration::from_millis(1_795_770_723_123);
        assert_eq!(
            line(false, t, format_args!("herb-camera: {} cells", 224)),
            "2026-11-27T09:12:03.123Z herb-camera: 224 cells\n"
        );
        // Under journald: as is.
        assert_eq!(
            line(true, t, format_args!("herb-camera: {} cells", 224)),
            "herb-camera: 224 cells\n"
        );
    }
}
