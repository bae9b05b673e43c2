//! What the loopback reads from herbd's configuration file: the IPC prefix, the BoxED folder,
//! the cell and the joint limits. The same file configures both processes, so the arm is
//! simulated where herbd believes it is and commands are checked against the limits herbd
//! plans with. The other tables are herbd's and are ignored here; within the tables read,
//! unknown keys are errors, as in herbd.

pub use herb_process::config_file::ConfigFile;
use herb_process::config_file::Invalid;
use herb_robot::cell::CellConfig;
use herb_robot::motion::JointLimits;
use serde::Deserialize;
use std::path::PathBuf;

/// The loopback's view of herbd's configuration.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default)]
pub struct LoopbackConfig {
    /// Service-name prefix (`herb_ipc::Services`).
    pub ipc_prefix: String,
    /// The `[models]` table (only `boxed` is read).
    pub models: Models,
    /// Box and pick-station poses.
    pub cell: CellConfig,
    /// Joint limits every command is checked against.
    pub limits: JointLimits,
}

/// The part of `[models]` the loopback reads.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(default)]
pub struct Models {
    /// BoxED folder for the object meshes (as herbd: absent means `HERB_BOXED` or
    /// `../shared/boxed`, falling back to primitives).
    pub boxed: Option<PathBuf>,
}

impl Default for LoopbackConfig {
    fn default() -> Self {
        Self {
            ipc_prefix: herb_ipc::Services::DEFAULT_PREFIX.into(),
            models: Models::default(),
            cell: CellConfig::default(),
            limits: JointLimits::baxter_left(),
        }
    }
}

/// Checks the prefix, the cell and the limits (herbd's checks of the same tables).
impl ConfigFile for LoopbackConfig {
    fn validate(&self) -> Result<(), Invalid> {
        herb_ipc::Services::new(&self.ipc_prefix).map_err(|e| e.to_string())?;
        self.cell.validate()?;
        Ok(self.limits.validate_baxter_left()?)
    }
}
