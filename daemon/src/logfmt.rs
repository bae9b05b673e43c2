//! herbd's log lines, one stable form for people and for `journalctl` filters:
//!
//! ```text
//! herbd: event=<name> <key>=<value> ...
//! ```
//!
//! `event` always comes first; keys are lowercase `snake_case`; a value with a space, a quote
//! or an `=` is written in double quotes with `\"` and `\\` escaped. The events and their keys
//! are listed in the README ("herbd's log"). Lines are formatted off the loop (reporter,
//! journal writer, start and end), never in a cycle.

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

/// Writes [`line`] to stderr (journald, under systemd).
pub fn log(event: &str, fields: &[(&str, &dyn Display)]) {
    eprintln!("{}", line(event, fields));
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
