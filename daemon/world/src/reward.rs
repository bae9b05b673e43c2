//! The rewards, exactly as the HERB paper (section "Reward"):
//! - `Simple`: +1 if inside, else -1;
//! - `C`: C if inside, else -1;
//! - `CS(alpha)`: `alpha * C + (1 - alpha) * S` if inside, else -1.

use crate::PlacementOutcome;
use herb_core::error::{Result, SimError};

/// The reward function.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RewardMode {
    /// +1 inside, -1 otherwise.
    Simple,
    /// C inside, -1 otherwise.
    Compactness,
    /// `alpha * C + (1 - alpha) * S` inside, -1 otherwise; `0 <= alpha <= 1`.
    CompactnessStability {
        /// Weight of compactness.
        alpha: f32,
    },
}

impl RewardMode {
    /// `CS(alpha)`, checking `0 <= alpha <= 1`.
    pub fn cs(alpha: f32) -> Result<Self> {
        if (0.0..=1.0).contains(&alpha) {
            Ok(Self::CompactnessStability { alpha })
        } else {
            Err(SimError::Config(format!(
                "reward alpha {alpha} outside [0, 1]"
            )))
        }
    }

    /// Parses `simple`, `c`, or `cs<alpha>` (e.g. `cs0.6`).
    pub fn parse(s: &str) -> Result<Self> {
        match s.to_ascii_lowercase().as_str() {
            "simple" => Ok(Self::Simple),
            "c" => Ok(Self::Compactness),
            other => match other.strip_prefix("cs").map(str::parse::<f32>) {
                Some(Ok(a)) => Self::cs(a),
                _ => Err(SimError::Config(format!(
                    "unknown reward mode {s:?} (expected simple, c, or cs<alpha>)"
                ))),
            },
        }
    }

    /// The reward of one placement.
    pub fn reward(&self, o: &PlacementOutcome) -> f32 {
        if !o.inside {
            return -1.0;
        }
        let s = if o.stable { 1.0 } else { 0.0 };
        match *self {
            Self::Simple => 1.0,
            Self::Compactness => o.compactness,
            Self::CompactnessStability { alpha } => alpha * o.compactness + (1.0 - alpha) * s,
        }
    }
}
