//! Configuration files of the robot-side processes (herbd, the adapters): TOML, every value
//! checked before anything acts on it, errors naming the file and the bad value.

use std::path::Path;

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

    /// Reads and validates a TOML file.
    fn load(path: &Path) -> Result<Self, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("cannot read config {}: {e}", path.display()))?;
        Self::from_toml(&text, &path.display().to_string())
    }
}
