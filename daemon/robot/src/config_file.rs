//! Configuration files of the robot-side processes (herbd, the adapters): TOML, every value
//! checked before anything acts on it, errors naming the file and the bad value.

use std::path::Path;

/// `Ok` when `v` is finite and within `lo..=hi`; else an error naming `name`.
pub fn in_range(name: &str, v: f64, lo: f64, hi: f64) -> Result<(), String> {
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(())
    } else {
        Err(format!("{name} = {v} is outside {lo}..={hi}"))
    }
}

/// A configuration read from a TOML file and validated as a whole.
pub trait ConfigFile: serde::de::DeserializeOwned {
    /// Checks every value; the error names the first bad one.
    fn validate(&self) -> Result<(), String>;

    /// Parses TOML text (`origin` names it in errors) and validates it.
    fn from_toml(text: &str, origin: &str) -> Result<Self, String> {
        let c: Self = toml::from_str(text).map_err(|e| format!("{origin}: {e}"))?;
        c.validate().map_err(|e| format!("{origin}: {e}"))?;
        Ok(c)
    }

    /// Reads and validates the file at `path`, or takes the defaults (validated too) without
    /// one.
    fn load_or_default(path: Option<&Path>) -> Result<Self, String>
    where
        Self: Default,
    {
        let c = match path {
            Some(p) => Self::load(p)?,
            None => Self::default(),
        };
        c.validate()?;
        Ok(c)
    }

    /// Reads and validates a TOML file.
    fn load(path: &Path) -> Result<Self, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("cannot read config {}: {e}", path.display()))?;
        Self::from_toml(&text, &path.display().to_string())
    }
}
