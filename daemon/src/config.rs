//! `herbd`'s configuration: a TOML file (every key optional, unknown keys rejected) with
//! command-line overrides applied by the binary. [`Config::validate`] checks every value and
//! names the bad one; nothing is acted on before it passes.

use herb_decide::PolicySpec;
pub use herb_process::config_file::{ConfigError, ConfigFile, Invalid};
pub use herb_process::rt::RtConfig;
use herb_robot::cell::CellConfig;
use herb_robot::motion::JointLimits;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// The control loop.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LoopConfig {
    /// Cycle rate (Hz).
    pub rate_hz: f64,
    /// Busy-wait this long before each deadline instead of sleeping (us); 0 sleeps the whole
    /// way. Trades a core for lower wake-up jitter.
    pub spin_us: u64,
    /// Seconds between statistics reports (printed off the loop).
    pub report_interval_s: f64,
    /// Longest trajectory the planner can hand the loop (s): sizes the preallocated buffers.
    pub max_trajectory_s: f64,
}

impl Default for LoopConfig {
    fn default() -> Self {
        Self {
            rate_hz: 1000.0,
            spin_us: 100,
            report_interval_s: 10.0,
            max_trajectory_s: 60.0,
        }
    }
}

/// Input timeouts (s).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Timeouts {
    /// Joint states older than this are a fault.
    pub joint_state_s: f64,
    /// Gripper states older than this are a fault.
    pub gripper_state_s: f64,
    /// Heightmaps older than this are a fault (while a job runs).
    pub heightmap_s: f64,
    /// The gripper must reach a commanded state within this.
    pub gripper_action_s: f64,
    /// Inputs must be healthy this long before a faulted job resumes.
    pub resume_after_s: f64,
    /// How long to wait for a heightmap newer than the last release.
    pub fresh_heightmap_s: f64,
}

impl Default for Timeouts {
    fn default() -> Self {
        Self {
            joint_state_s: 0.1,
            gripper_state_s: 0.2,
            heightmap_s: 2.0,
            gripper_action_s: 2.0,
            resume_after_s: 0.5,
            fresh_heightmap_s: 10.0,
        }
    }
}

/// Models and data.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ModelsConfig {
    /// `blbf` (the PackIt SO(2) baseline), a shipped policy (`cs06`, `cs09`: the file
    /// `policy-<name>.onnx` in the sequence model's folder) or the path of an ONNX policy.
    pub policy: PolicySpec,
    /// The sequence model (Beam-3 transition counts).
    pub sequence: PathBuf,
    /// BoxED folder for the object meshes; absent: `HERB_BOXED` or `../shared/boxed`,
    /// falling back to primitives.
    pub boxed: Option<PathBuf>,
    /// Gap above the estimated resting height at release (m).
    pub clearance_m: f64,
}

impl ModelsConfig {
    /// The policy with a shipped policy's name turned into its file, which sits beside the
    /// sequence model (the models folder).
    pub fn resolved_policy(&self) -> PolicySpec {
        let dir = self
            .sequence
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or(std::path::Path::new("."));
        self.policy.resolved(dir)
    }

    /// The policy's ONNX file (resolved as [`ModelsConfig::resolved_policy`]); `None` for BLBF.
    pub fn policy_file(&self) -> Option<PathBuf> {
        match self.resolved_policy() {
            PolicySpec::Onnx(p) => Some(p),
            _ => None,
        }
    }
}

impl Default for ModelsConfig {
    fn default() -> Self {
        Self {
            policy: PolicySpec::Blbf,
            sequence: PathBuf::from("models/sequence.json"),
            boxed: None,
            clearance_m: herb_core::frames::RELEASE_CLEARANCE_M as f64,
        }
    }
}

/// Everything `herbd` reads.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// Service-name prefix (`herb_ipc::Services`).
    pub ipc_prefix: String,
    /// The loop.
    #[serde(rename = "loop")]
    pub loop_: LoopConfig,
    /// Real-time setup.
    pub rt: RtConfig,
    /// Input timeouts.
    pub timeouts: Timeouts,
    /// Models and data.
    pub models: ModelsConfig,
    /// Box and pick-station poses, approach geometry.
    pub cell: CellConfig,
    /// Joint limits.
    pub limits: JointLimits,
    /// Run logs (`herbd replay`, `herbd explain`).
    pub record: RecordConfig,
    /// The job journal (a job survives a daemon crash).
    pub journal: JournalConfig,
    /// What the cell does after a fault it can recover from by itself.
    pub recovery: RecoveryConfig,
    /// How placements are decided.
    pub decision: DecisionConfig,
}

/// How each placement is decided ([`crate::decision`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DecisionMethod {
    /// The placement policy of `[models] policy` (BLBF or a learned policy): under a
    /// millisecond.
    Policy,
    /// The search (the default): the lattice's best `k` candidates each rolled out to the
    /// job's end (or `horizon` objects) in a physics twin, within `budget_s`.
    #[default]
    Search,
}

/// The world the search's rollouts run in ([`herb_search::TwinKind`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DecisionTwin {
    /// A twin built from the latest heightmap alone: the pile as static convex pieces.
    Heightmap,
    /// The job's own twin (the default): the objects herbd decided in the job replayed at
    /// their release poses, each fitted to the heightmap that followed it; the heightmap twin
    /// whenever it disagrees with the latest heightmap (a restart, a knocked object, a box
    /// filled by hand).
    #[default]
    Job,
}

/// The decision worker ([`crate::decision`]): it decides while the arm picks.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DecisionConfig {
    /// `policy` or `search`.
    pub method: DecisionMethod,
    /// The search's time per decision (s, 0 to 30): it returns the best candidate whose
    /// rollout finished by then (with 0, lattice BLBF's first, said so by `allowed` 0).
    pub budget_s: f64,
    /// Candidates the search rolls out at most (1 to 64), best first by lattice BLBF's order.
    pub k: usize,
    /// Objects per rollout, the candidate's included (0: to the job's end).
    pub horizon: usize,
    /// The world the search's rollouts run in.
    pub twin: DecisionTwin,
    /// Threads the search's rollouts run on (0 to 64; 0: the cores herbd's loop and planner
    /// leave, at least one, [`DecisionConfig::search_threads`]). A searched run replays bit
    /// for bit whatever the count.
    pub threads: usize,
    /// The robust search (0 to 64; 0: off): each candidate rolled out this many times, every
    /// object of each rollout released off its placement by the release error below (the same
    /// draws for every candidate), ranked by the mean return.
    pub samples: usize,
    /// The release error the robust search and the release check assume: standard deviation of
    /// x and of y (mm, 0 to 50). Measure your cell's: release an object at known poses and read
    /// where it lands.
    pub release_error_mm: f64,
    /// The release error the robust search and the release check assume: standard deviation
    /// of the yaw (degrees, 0 to 45).
    pub release_error_deg: f64,
    /// The release check (on by default): each of the search's best candidates is first
    /// released on the job twin's live pile off its placement by the four corners of
    /// `release_error_mm` and `release_error_deg`, and passed over when one of those releases
    /// leaves it outside the box ([`herb_search::SearchSettings::release_check`]).
    pub release_check: bool,
    /// The search's clearance for a gripper that does not release exactly (0 to 4 cells of
    /// 6.25 mm; 0: tight): each candidate pushed against a neighbour or a wall backs off by up
    /// to this many cells, as far as there is room ([`herb_search::SearchSettings::push_gap`]).
    pub gap: usize,
    /// The search's clearance from the walls for objects that stand above the box's rim, where
    /// a wall no longer holds one released off its placement (0 to 4 cells of 6.25 mm; 0:
    /// none): each candidate within this many cells of a wall moves away from it, as far as
    /// there is room ([`herb_search::SearchSettings::wall_gap`]).
    pub wall_gap: usize,
    /// The search's support rule (0 to 1; 0: off): a candidate that stands above the box's
    /// rim on less than this share of its footprint, which a release a few millimetres off
    /// can slide or tip off the pile, is ranked as a failed rollout is
    /// ([`herb_search::SearchSettings::min_support`]; measured at 0.3).
    pub min_support: f32,
    /// The search finds its candidates on the camera's heightmap filtered by a 3 x 3 median
    /// (off by default): the camera's per-cell depth noise then no longer decides between
    /// positions of the same top ([`herb_search::SearchSettings::median`]).
    pub median: bool,
    /// A decision not back this long after it was asked for (s) faults the job (`Decision`):
    /// a hung worker never holds the arm.
    pub timeout_s: f64,
}

impl Default for DecisionConfig {
    fn default() -> Self {
        Self {
            method: DecisionMethod::Search,
            budget_s: 1.0,
            k: herb_search::DEFAULT_K,
            horizon: 0,
            twin: DecisionTwin::Job,
            threads: 0,
            samples: 0,
            release_error_mm: herb_search::DEFAULT_RELEASE_ERROR_MM,
            release_error_deg: herb_search::DEFAULT_RELEASE_ERROR_DEG,
            release_check: herb_search::SearchSettings::default()
                .release_check
                .is_some(),
            gap: herb_search::DEFAULT_GAP,
            wall_gap: 0,
            min_support: herb_search::SearchSettings::default()
                .min_support
                .unwrap_or(0.0),
            median: herb_search::SearchSettings::default().median,
            timeout_s: 10.0,
        }
    }
}

impl DecisionConfig {
    /// The search's threads: `threads`, or with 0 the machine's cores less the two of herbd's
    /// loop and planner, at least one.
    pub fn search_threads(&self) -> usize {
        match self.threads {
            0 => std::thread::available_parallelism()
                .map_or(1, |n| n.get().saturating_sub(2))
                .max(1),
            n => n,
        }
    }
}

/// Recovery from faults the cell handles by itself.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RecoveryConfig {
    /// After a missed grasp (the gripper closed on nothing), the gripper opens and the pick is
    /// tried again with the same placement this many times (0 to 5); then the object is skipped
    /// (status `Skipped`, fault `MissedGrasp`) and the job goes on with the next one.
    pub grasp_retries: u32,
    /// What a measured joint outside `[limits]` (but inside the arm's own limits, e.g. an arm
    /// that sagged while disabled) means when a job starts or resumes.
    pub outside_limits: OutsideLimits,
    /// With `outside_limits = "recover"`: the fraction (0 < f <= 1) of `[limits]`' speed,
    /// acceleration and jerk at which the arm is brought back inside.
    pub recover_speed: f64,
    /// With `outside_limits = "recover"`: how far inside the limit a joint is brought (rad,
    /// 0 to 0.05).
    pub recover_margin_rad: f64,
}

impl Default for RecoveryConfig {
    fn default() -> Self {
        Self {
            grasp_retries: 1,
            outside_limits: OutsideLimits::Recover,
            recover_speed: 0.1,
            recover_margin_rad: 0.005,
        }
    }
}

/// What herbd does with an arm measured outside its configured joint limits (but inside the
/// arm's own) when a job starts or resumes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OutsideLimits {
    /// Report it (fault `OutsideLimits`, naming the joint) and bring the joints outside back in,
    /// slowly and toward the limit only, as the first motion; then the job goes on.
    #[default]
    Recover,
    /// Refuse jobs as "robot not ready" (`NotReady`, fault `OutsideLimits`) and hold a running
    /// job until the arm is moved inside by hand.
    Refuse,
}

/// What a restarted herbd does with an unfinished job found in its journal.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OnRestart {
    /// Take it up from the measured robot state.
    #[default]
    Resume,
    /// End it, failed with the fault `Restarted`, and start idle.
    Abandon,
}

/// The job journal ([`crate::journal`]).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct JournalConfig {
    /// Folder of the journal file; absent: `$STATE_DIRECTORY` (systemd's `StateDirectory=`),
    /// and no journal when that is not set either.
    pub dir: Option<PathBuf>,
    /// What to do with an unfinished job at start.
    pub on_restart: OnRestart,
}

impl JournalConfig {
    /// The journal's folder: `dir`, else the first folder of `state_directory` (the value of
    /// `$STATE_DIRECTORY`, a colon-separated list).
    pub fn folder(&self, state_directory: Option<&str>) -> Option<PathBuf> {
        self.dir.clone().or_else(|| {
            state_directory
                .and_then(|s| s.split(':').next())
                .filter(|s| !s.is_empty())
                .map(PathBuf::from)
        })
    }
}

/// Run logs: off unless `dir` is set (or `herbd --record DIR`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RecordConfig {
    /// Folder of the run log's segment files; absent: no run log.
    pub dir: Option<PathBuf>,
    /// A segment is closed, between jobs, once past this size (MB).
    pub segment_mb: u64,
    /// The oldest segments are deleted beyond this total (MB).
    pub keep_mb: u64,
}

impl Default for RecordConfig {
    fn default() -> Self {
        Self {
            dir: None,
            segment_mb: 64,
            keep_mb: 1024,
        }
    }
}

impl Default for Config {
    fn default() -> Self {
        Self {
            ipc_prefix: herb_ipc::Services::DEFAULT_PREFIX.into(),
            loop_: LoopConfig::default(),
            rt: RtConfig::default(),
            timeouts: Timeouts::default(),
            models: ModelsConfig::default(),
            cell: CellConfig::default(),
            limits: JointLimits::baxter_left(),
            record: RecordConfig::default(),
            journal: JournalConfig::default(),
            recovery: RecoveryConfig::default(),
            decision: DecisionConfig::default(),
        }
    }
}

impl Config {
    /// Loop period (s).
    pub fn period_s(&self) -> f64 {
        1.0 / self.loop_.rate_hz
    }

    /// Samples a trajectory buffer holds: `max_trajectory_s` at the loop rate.
    pub fn trajectory_samples(&self) -> usize {
        (self.loop_.max_trajectory_s * self.loop_.rate_hz).ceil() as usize
    }

    /// Loop period (ns).
    pub fn period_ns(&self) -> u64 {
        secs_to_ns(self.period_s())
    }
}

/// Seconds (from the configuration) to nanoseconds, truncated.
pub fn secs_to_ns(s: f64) -> u64 {
    (s * 1e9) as u64
}

impl ConfigFile for Config {
    fn validate(&self) -> Result<(), Invalid> {
        herb_ipc::Services::new(&self.ipc_prefix).map_err(|e| e.to_string())?;
        let l = &self.loop_;
        if !(l.rate_hz.is_finite() && (10.0..=10_000.0).contains(&l.rate_hz)) {
            return Err(format!("loop.rate_hz {} outside 10..=10000", l.rate_hz).into());
        }
        if l.spin_us as f64 * 1e-6 >= 1.0 / l.rate_hz {
            return Err(
                format!("loop.spin_us {} is not shorter than the period", l.spin_us).into(),
            );
        }
        if !(l.report_interval_s.is_finite() && l.report_interval_s >= 0.1) {
            return Err(format!("loop.report_interval_s {} below 0.1", l.report_interval_s).into());
        }
        if !(l.max_trajectory_s.is_finite() && (1.0..=600.0).contains(&l.max_trajectory_s)) {
            return Err(format!(
                "loop.max_trajectory_s {} outside 1..=600",
                l.max_trajectory_s
            )
            .into());
        }
        if !(0..=99).contains(&self.rt.fifo_priority) {
            return Err(
                format!("rt.fifo_priority {} outside 0..=99", self.rt.fifo_priority).into(),
            );
        }
        if self.recovery.grasp_retries > 5 {
            return Err(format!(
                "recovery.grasp_retries {} outside 0..=5",
                self.recovery.grasp_retries
            )
            .into());
        }
        let r = &self.recovery;
        if !(r.recover_speed.is_finite() && r.recover_speed > 0.0 && r.recover_speed <= 1.0) {
            return Err(format!(
                "recovery.recover_speed {} outside (0, 1] (a fraction of [limits])",
                r.recover_speed
            )
            .into());
        }
        if !(r.recover_margin_rad.is_finite() && (0.0..=0.05).contains(&r.recover_margin_rad)) {
            return Err(format!(
                "recovery.recover_margin_rad {} outside 0..=0.05 rad",
                r.recover_margin_rad
            )
            .into());
        }
        let t = &self.timeouts;
        for (name, v) in [
            ("joint_state_s", t.joint_state_s),
            ("gripper_state_s", t.gripper_state_s),
            ("heightmap_s", t.heightmap_s),
            ("gripper_action_s", t.gripper_action_s),
            ("resume_after_s", t.resume_after_s),
            ("fresh_heightmap_s", t.fresh_heightmap_s),
        ] {
            if !(v.is_finite() && (0.001..=600.0).contains(&v)) {
                return Err(format!("timeouts.{name} {v} outside 0.001..=600 s").into());
            }
        }
        if !(self.models.clearance_m.is_finite() && (0.0..=0.05).contains(&self.models.clearance_m))
        {
            return Err(format!(
                "models.clearance_m {} outside 0..=0.05",
                self.models.clearance_m
            )
            .into());
        }
        let d = &self.decision;
        if !(d.budget_s.is_finite() && (0.0..=30.0).contains(&d.budget_s)) {
            return Err(format!("decision.budget_s {} outside 0..=30", d.budget_s).into());
        }
        if !(1..=64).contains(&d.k) {
            return Err(format!("decision.k {} outside 1..=64", d.k).into());
        }
        if d.threads > 64 {
            return Err(format!("decision.threads {} outside 0..=64", d.threads).into());
        }
        use herb_search::RobustRollouts as R;
        if d.samples > R::MAX_SAMPLES {
            return Err(format!(
                "decision.samples {} outside 0..={}",
                d.samples,
                R::MAX_SAMPLES
            )
            .into());
        }
        for (name, v, max) in [
            ("release_error_mm", d.release_error_mm, R::MAX_ERROR_MM),
            ("release_error_deg", d.release_error_deg, R::MAX_ERROR_DEG),
        ] {
            if !(v.is_finite() && (0.0..=max).contains(&v)) {
                return Err(format!("decision.{name} {v} outside 0..={max}").into());
            }
        }
        let max_gap = herb_core::lattice::MAX_PUSH_GAP;
        if d.gap > max_gap {
            return Err(format!("decision.gap {} outside 0..={max_gap}", d.gap).into());
        }
        if d.wall_gap > max_gap {
            return Err(format!("decision.wall_gap {} outside 0..={max_gap}", d.wall_gap).into());
        }
        herb_search::support_rule(d.min_support)
            .map_err(|e| format!("decision.min_support {e}"))?;
        if d.horizon > herb_ipc::MAX_JOB_OBJECTS {
            return Err(format!(
                "decision.horizon {} above the {} objects of a job",
                d.horizon,
                herb_ipc::MAX_JOB_OBJECTS
            )
            .into());
        }
        if !(d.timeout_s.is_finite() && d.timeout_s > d.budget_s && d.timeout_s <= 600.0) {
            return Err(format!(
                "decision.timeout_s {} must exceed decision.budget_s {} (and be at most 600)",
                d.timeout_s, d.budget_s
            )
            .into());
        }
        let r = &self.record;
        if r.segment_mb == 0 || r.keep_mb < r.segment_mb {
            return Err(format!(
                "record.segment_mb {} must be at least 1 and at most record.keep_mb {}",
                r.segment_mb, r.keep_mb
            )
            .into());
        }
        self.cell.validate()?;
        self.limits.validate_baxter_left()?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    #[test]
    fn the_shipped_example_is_the_defaults() {
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../systemd/herbd.toml");
        let c = Config::load(&p).unwrap();
        let mut d = Config::default();
        // The file writes the derived numbers (URDF limits -+ 0.05 rad, 60 % speeds) rounded.
        let (a, b) = (c.limits, d.limits);
        for (x, y) in [
            (a.lower, b.lower),
            (a.upper, b.upper),
            (a.velocity, b.velocity),
            (a.acceleration, b.acceleration),
            (a.jerk, b.jerk),
        ] {
            assert!(
                x.iter().zip(&y).all(|(u, v)| (u - v).abs() < 1e-9),
                "{x:?} vs {y:?}"
            );
        }
        assert!((c.models.clearance_m - d.models.clearance_m).abs() < 1e-9);
        d.limits = c.limits;
        d.models.clearance_m = c.models.clearance_m;
        assert_eq!(c, d);
    }

    #[test]
    fn defaults_validate_and_bad_values_are_named() {
        Config::default().validate().unwrap();
        let c = Config::from_toml("ipc_prefix = \"t1\"\n[loop]\nrate_hz = 500.0\n", "x").unwrap();
        assert_eq!(c.loop_.rate_hz, 500.0);
        assert_eq!(c.ipc_prefix, "t1");
        let e = Config::from_toml("[loop]\nrate_hz = 0.0\n", "cfg.toml").unwrap_err();
        let e = e.to_string();
        assert!(e.contains("cfg.toml") && e.contains("rate_hz"), "{e}");
        let e = Config::from_toml("[loop]\nrate = 5\n", "x")
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown field"), "{e}");
        assert!(Config::from_toml("[limits]\nlower = [0.0]\n", "x").is_err());
        let mut c = Config::default();
        c.limits.upper[1] = 3.0;
        assert!(
            c.validate()
                .unwrap_err()
                .to_string()
                .contains("leaves the arm's limits")
        );
        c = Config::default();
        c.limits.jerk[4] = f64::NAN;
        assert!(c.validate().unwrap_err().to_string().contains("jerk"));
        c = Config::default();
        c.timeouts.joint_state_s = -1.0;
        assert!(
            c.validate()
                .unwrap_err()
                .to_string()
                .contains("joint_state_s")
        );
        c = Config::default();
        c.ipc_prefix = "/x".into();
        assert!(c.validate().is_err());
        // The decision: a method by name, and each bad number named.
        let c =
            Config::from_toml("[decision]\nmethod = \"search\"\nbudget_s = 0.0\n", "x").unwrap();
        assert_eq!(c.decision.method, DecisionMethod::Search);
        // The search's threads: the cores left by default (at least one), or as many as given.
        assert!(c.decision.threads == 0 && c.decision.search_threads() >= 1);
        let two = Config::from_toml("[decision]\nthreads = 2\n", "x").unwrap();
        assert_eq!(two.decision.search_threads(), 2);
        for (toml, name) in [
            ("[decision]\nmethod = \"rollout\"\n", "method"),
            ("[decision]\nbudget_s = -1.0\n", "decision.budget_s"),
            ("[decision]\nbudget_s = nan\n", "decision.budget_s"),
            ("[decision]\nk = 0\n", "decision.k"),
            ("[decision]\nk = 65\n", "decision.k"),
            ("[decision]\nthreads = 65\n", "decision.threads"),
            ("[decision]\nsamples = 65\n", "decision.samples"),
            ("[decision]\ngap = 5\n", "decision.gap"),
            ("[decision]\nwall_gap = 9\n", "decision.wall_gap"),
            ("[decision]\nmin_support = -0.1\n", "decision.min_support"),
            ("[decision]\nmin_support = 1.5\n", "decision.min_support"),
            (
                "[decision]\nrelease_error_mm = -1.0\n",
                "decision.release_error_mm",
            ),
            (
                "[decision]\nrelease_error_deg = nan\n",
                "decision.release_error_deg",
            ),
            ("[decision]\ntwin = \"exact\"\n", "twin"),
            (
                "[recovery]\noutside_limits = \"ignore\"\n",
                "outside_limits",
            ),
            (
                "[recovery]\nrecover_speed = 0.0\n",
                "recovery.recover_speed",
            ),
            (
                "[recovery]\nrecover_speed = 1.5\n",
                "recovery.recover_speed",
            ),
            (
                "[recovery]\nrecover_margin_rad = -0.1\n",
                "recovery.recover_margin_rad",
            ),
            ("[decision]\nhorizon = 65\n", "decision.horizon"),
            (
                "[decision]\nbudget_s = 5.0\ntimeout_s = 2.0\n",
                "decision.timeout_s",
            ),
        ] {
            let e = Config::from_toml(toml, "x").unwrap_err().to_string();
            assert!(e.contains(name), "{toml}: {e}");
        }
        let c = Config::from_toml("[journal]\non_restart = \"abandon\"\n", "x").unwrap();
        assert_eq!(c.journal.on_restart, OnRestart::Abandon);
        assert_eq!(
            c.journal.folder(Some("/var/lib/herb:/x")),
            Some("/var/lib/herb".into())
        );
        assert_eq!(c.journal.folder(None), None);
        let e = Config::from_toml("[journal]\non_restart = \"retry\"\n", "x")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("on_restart") || e.contains("unknown variant"),
            "{e}"
        );
        let e = Config::from_toml("[models]\npolicy = \"\"\n", "x")
            .unwrap_err()
            .to_string();
        assert!(e.contains("policy: empty"), "{e}");
        let c = Config::from_toml("[models]\npolicy = \"m/p.onnx\"\n", "x").unwrap();
        assert_eq!(c.models.policy, PolicySpec::Onnx("m/p.onnx".into()));
        assert_eq!(c.models.policy.to_string(), "m/p.onnx");
        let c = Config::from_toml(
            "[models]\npolicy = \"cs06\"\nsequence = \"/opt/herb/models/sequence.json\"\n",
            "x",
        )
        .unwrap();
        assert_eq!(
            c.models.policy_file(),
            Some("/opt/herb/models/policy-cs06.onnx".into())
        );
        assert_eq!(c.models.policy.to_string(), "cs06");
    }
}
