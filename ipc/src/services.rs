//! Service names under a prefix.

/// Service names under a configurable prefix (default [`Services::DEFAULT_PREFIX`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Services {
    prefix: String,
}

/// A prefix that cannot name services.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "IPC prefix {0:?}: use 1-100 characters of [A-Za-z0-9_-/.], not starting or ending with '/'"
)]
pub struct BadPrefix(pub String);

impl Services {
    /// The default prefix.
    pub const DEFAULT_PREFIX: &'static str = "herb";

    /// Names under `prefix`.
    pub fn new(prefix: &str) -> Result<Self, BadPrefix> {
        let ok = (1..=100).contains(&prefix.len())
            && !prefix.starts_with('/')
            && !prefix.ends_with('/')
            && prefix
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || "_-/.".contains(c));
        if ok {
            Ok(Self {
                prefix: prefix.to_owned(),
            })
        } else {
            Err(BadPrefix(prefix.to_owned()))
        }
    }

    /// The prefix.
    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    fn name(&self, leaf: &str) -> String {
        format!("{}/{leaf}", self.prefix)
    }

    /// pub-sub [`HeightmapFrame`], camera adapter -> herbd, clients.
    pub fn heightmap(&self) -> String {
        self.name("heightmap")
    }
    /// pub-sub [`JointState`], adapter -> herbd.
    pub fn joint_state(&self) -> String {
        self.name("joint_state")
    }
    /// pub-sub [`ArmStatus`], arm adapter -> herbd, clients.
    pub fn arm_status(&self) -> String {
        self.name("arm_status")
    }
    /// pub-sub [`JointCommand`], herbd -> adapter.
    pub fn joint_command(&self) -> String {
        self.name("joint_command")
    }
    /// pub-sub [`GripperCommand`], herbd -> adapter.
    pub fn gripper_command(&self) -> String {
        self.name("gripper_command")
    }
    /// pub-sub [`GripperState`], adapter -> herbd.
    pub fn gripper_state(&self) -> String {
        self.name("gripper_state")
    }
    /// pub-sub [`Status`], herbd -> clients.
    pub fn status(&self) -> String {
        self.name("status")
    }
    /// request-response [`PackJobRequest`] / [`PackJobReply`], clients -> herbd.
    pub fn pack_job(&self) -> String {
        self.name("pack_job")
    }
    /// request-response [`CancelJobRequest`] / [`CancelJobReply`], clients -> herbd.
    pub fn cancel_job(&self) -> String {
        self.name("cancel_job")
    }
    /// request-response [`ConfirmPickRequest`] / [`ConfirmPickReply`], clients -> herbd.
    pub fn confirm_pick(&self) -> String {
        self.name("confirm_pick")
    }
    /// pub-sub [`SimOutcome`], loopback -> tests (sim only).
    pub fn sim_outcome(&self) -> String {
        self.name("sim/outcome")
    }
    /// pub-sub [`DecisionReport`], herbd's decision thread -> clients (viewers).
    pub fn decision(&self) -> String {
        self.name("decision")
    }
    /// pub-sub [`SimReset`], clients -> loopback (sim only).
    pub fn sim_reset(&self) -> String {
        self.name("sim/reset")
    }
}

impl Default for Services {
    fn default() -> Self {
        Self {
            prefix: Self::DEFAULT_PREFIX.to_owned(),
        }
    }
}
