//! Configuration files of HERB's processes (herbd, the adapters): TOML, every value
//! checked before anything acts on it, errors naming the file and the bad value.

use std::path::{Path, PathBuf};

/// A configuration value that is not allowed: the error names it and says why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Invalid {
    /// A number outside its range, or not finite ([`in_range`]).
    #[error("{name} = {value} is outside {lo}..={hi}")]
    OutOfRange {
        /// The value's name (its key in the file).
        name: String,
        /// The value.
        value: f64,
        /// Lowest allowed.
        lo: f64,
        /// Highest allowed.
        hi: f64,
    },
    /// Any other value a configuration checks, in words that name it.
    #[error("{0}")]
    Other(String),
}

impl From<String> for Invalid {
    fn from(what: String) -> Self {
        Self::Other(what)
    }
}

impl From<&str> for Invalid {
    fn from(what: &str) -> Self {
        Self::Other(what.into())
    }
}

/// A configuration that cannot be used: the file cannot be read, is not TOML of the expected
/// shape, or holds a value that is not allowed.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file cannot be read.
    #[error("cannot read config {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// Not TOML, or not of the expected shape (an unknown key, a wrong type).
    #[error("{origin}: {source}")]
    Parse {
        /// Where the text came from (the file).
        origin: String,
        /// The parser's error.
        source: toml::de::Error,
    },
    /// A value that is not allowed, in the text from `origin`.
    #[error("{origin}: {source}")]
    InvalidIn {
        /// Where the text came from (the file).
        origin: String,
        /// The value.
        source: Invalid,
    },
    /// A value that is not allowed (the defaults').
    #[error(transparent)]
    Invalid(#[from] Invalid),
}

/// `Ok` when `v` is finite and within `lo..=hi`; else an error naming `name`.
pub fn in_range(name: &str, v: f64, lo: f64, hi: f64) -> Result<(), Invalid> {
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(())
    } else {
        Err(Invalid::OutOfRange {
            name: name.into(),
            value: v,
            lo,
            hi,
        })
    }
}

/// A configuration read from a TOML file and validated as a whole.
pub trait ConfigFile: serde::de::DeserializeOwned {
    /// Checks every value; the error names the first bad one.
    fn validate(&self) -> Result<(), Invalid>;

    /// Parses TOML text (`origin` names it in errors) and validates it.
    fn from_toml(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let c: Self = toml::from_str(text).map_err(|source| ConfigError::Parse {
            origin: origin.into(),
            source,
        })?;
        c.validate().map_err(|source| ConfigError::InvalidIn {
            origin: origin.into(),
            source,
        })?;
        Ok(c)
    }

    /// Reads and validates the file at `path`, or takes the defaults (validated too) without
    /// one.
    fn load_or_default(path: Option<&Path>) -> Result<Self, ConfigError>
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
    fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.into(),
            source,
        })?;
        Self::from_toml(&text, &path.display().to_string())
    }
}
