//! herbd's log lines, one stable form for people and for `journalctl` filters:
//!
//! ```text
//! herbd: event=<name> <key>=<value> ...
//! ```
//!
//! `event` always comes first; keys are lowercase `snake_case`; a value with a space, a quote
//! or an `=` is written in double quotes with `\"` and `\\` escaped. The events and their keys
//! are listed in `docs/hardening.md` ("herbd's log"). Lines are formatted off the loop (reporter,
//! journal writer, start and end), never in a cycle. Under journald (which stamps each line
//! itself: `$JOURNAL_STREAM` is set) a line is written as is; otherwise it starts with the UTC
//! time, e.g. `2026-11-26T05:40:00.123Z herbd: event=...`.

use std::fmt::{Display, Write};

/// One log line: `herbd: event=<event>` then each `key=value` in order.
pub fn line(event: &str, fields: &[(&str, &dyn Display)]) -> String {
    let mut s = format!("herbd: event={event}");
    for (k, v) in fields {
        let v = v.to_string();
        let _ = write!(s, " {k}={}", quote(&v));
    }
    s
}

/// Writes [`line`] to stderr (journald, under systemd), see [`emit`].
pub fn log(event: &str, fields: &[(&str, &dyn Display)]) {
    emit(&line(event, fields));
}

/// Writes a formatted line to stderr: as is under journald, else after the UTC time. A write
/// that fails (stderr closed) is counted ([`failed_writes`]), never a panic.
pub fn emit(line: &str) {
    use std::io::Write;
    let mut err = std::io::stderr().lock();
    let r = if std::env::var_os("JOURNAL_STREAM").is_some() {
        writeln!(err, "{line}")
    } else {
        writeln!(
            err,
            "{} {line}",
            humantime::format_rfc3339_millis(std::time::SystemTime::now())
        )
    };
    if r.is_err() {
        FAILED.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    }
}

static FAILED: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// Lines [`emit`] could not write (stderr closed or failing).
pub fn failed_writes() -> u64 {
    FAILED.load(std::sync::atomic::Ordering::Relaxed)
}

/// `v` as a value: bare when it has no space, quote or `=`, else quoted and escaped.
pub fn quote(v: &str) -> String {
    if !v.is_empty() && !v.contains(|c: char| c.is_whitespace() || c == '"' || c == '=') {
        return v.to_string();
    }
    let mut q = String::with_capacity(v.len() + 2);
    q.push('"');
    for c in v.chars() {
        match c {
            '"' => q.push_str("\\\""),
            '\\' => q.push_str("\\\\"),
            '\n' => q.push_str("\\n"),
            c => q.push(c),
        }
    }
    q.push('"');
    q
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_are_bare_or_quoted_and_escaped() {
        let l = line(
            "job_failed",
            &[
                ("job", &42u64),
                ("fault", &"NoFeasiblePlacement"),
                ("detail", &"a \"b\" = c\\d"),
                ("empty", &""),
            ],
        );
        assert_eq!(
            l,
            r#"herbd: event=job_failed job=42 fault=NoFeasiblePlacement detail="a \"b\" = c\\d" empty="""#
        );
    }
}
