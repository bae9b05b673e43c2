//! ROS time (wall clock, in message headers) to HERB's clock (CLOCK_MONOTONIC).

use roslibrust::codegen::integral_types::Time;
use std::time::{SystemTime, UNIX_EPOCH};

/// A stamp more than this far in the future is refused (clock skew between machines).
pub const MAX_FUTURE_NS: i128 = 50_000_000;

/// Why a header stamp was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum StampError {
    /// The stamp is zero.
    #[error("no stamp")]
    Missing,
    /// The stamp is more than [`MAX_FUTURE_NS`] ahead of the wall clock.
    #[error("stamp {:.3} s in the future", *.ahead_ns as f64 * 1e-9)]
    Future {
        /// How far ahead (ns).
        ahead_ns: i128,
    },
    /// The stamp is older than allowed.
    #[error("stamp {:.3} s old", *.age_ns as f64 * 1e-9)]
    Old {
        /// Its age on the wall clock (ns).
        age_ns: i128,
    },
}

/// The monotonic time of a header stamp: `now_mono_ns` less the stamp's age on the wall clock
/// (`now_wall`). Refused: a zero stamp, a stamp more than [`MAX_FUTURE_NS`] in the future or
/// older than `max_age_ns`.
pub fn to_monotonic(
    stamp: &Time,
    now_mono_ns: u64,
    now_wall: SystemTime,
    max_age_ns: u64,
) -> Result<u64, StampError> {
    if stamp.secs == 0 && stamp.nsecs == 0 {
        return Err(StampError::Missing);
    }
    let stamp_ns = stamp.secs as i128 * 1_000_000_000 + stamp.nsecs as i128;
    let wall_ns = now_wall
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as i128);
    let age = wall_ns - stamp_ns;
    if age < -MAX_FUTURE_NS {
        return Err(StampError::Future { ahead_ns: -age });
    }
    if age > max_age_ns as i128 {
        return Err(StampError::Old { age_ns: age });
    }
    Ok((now_mono_ns as i128 - age.max(0)).max(1) as u64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn stamps_map_to_the_monotonic_clock_and_bad_ones_are_refused() {
        let wall = UNIX_EPOCH + Duration::from_secs(1_700_000_000);
        let at = |secs: i32, nsecs: i32| Time { secs, nsecs };
        let ok = to_monotonic(
            &at(1_699_999_999, 900_000_000),
            5_000_000_000,
            wall,
            500_000_000,
        );
        assert_eq!(ok, Ok(4_900_000_000));
        let e = to_monotonic(&at(0, 0), 5, wall, 1).unwrap_err().to_string();
        assert!(e.contains("no stamp"), "{e}");
        let e = to_monotonic(&at(1_699_999_998, 0), 5_000_000_000, wall, 500_000_000)
            .unwrap_err()
            .to_string();
        assert!(e.contains("2.000 s old"), "{e}");
        let e = to_monotonic(&at(1_700_000_001, 0), 5_000_000_000, wall, 500_000_000)
            .unwrap_err()
            .to_string();
        assert!(e.contains("future"), "{e}");
        assert_eq!(e, "stamp 1.000 s in the future");
        // A little ahead (skew within the tolerance): now.
        assert_eq!(
            to_monotonic(&at(1_700_000_000, 10_000_000), 7, wall, 1),
            Ok(7)
        );
    }
}
