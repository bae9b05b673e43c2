//! The iceoryx2 side of a hardware-adapter process (the rapier loopback, the Baxter and the
//! depth-camera bridges): the ports an arm adapter and a camera adapter open, validation of
//! every command herbd sends before the hardware sees it (within the limits, widened only to an
//! arm that sagged past them: [`command_range`]), the jump guard, the counters an adapter
//! reports and its log lines. An adapter combines this crate with its hardware's own side (a
//! simulation, a ROS connection) and, where it needs the arm's model, `herb-robot`.

#![warn(missing_docs)]

use herb_ipc::bus::{Bus, BusError, Pub, Sub};
use herb_ipc::{
    ArmBlocker, ArmStatus, DOF, GripperAction, GripperCommand, GripperState, HEIGHTMAP_MAX_CELLS,
    Header, HeightmapFrame, JointCommand, JointState, Services, zeroed_in_place,
};

pub mod guard;
pub mod log;

/// How far past the measured position a command outside herbd's limits may lie (rad): the
/// measurement's noise between herbd's reading and the adapter's.
pub const MEASURED_SLACK_RAD: f64 = 0.002;

/// The position range an arm adapter accepts commands in: herbd's `limits` (lower, upper),
/// widened on each joint to where the arm is `measured` (plus [`MEASURED_SLACK_RAD`]) and never
/// past the arm's own limits `arm` (lower, upper). An arm that sagged past herbd's limit while
/// disabled is brought back by commands between where it is and the limit (herbd's way back
/// in); a command farther out than the arm is refused.
pub fn command_range(
    limits: (&[f64; DOF], &[f64; DOF]),
    measured: Option<&[f64; DOF]>,
    arm: (&[f64; DOF], &[f64; DOF]),
) -> ([f64; DOF], [f64; DOF]) {
    let (mut lo, mut hi) = (*limits.0, *limits.1);
    if let Some(q) = measured {
        for j in 0..DOF {
            if q[j].is_finite() {
                lo[j] = lo[j].min((q[j] - MEASURED_SLACK_RAD).max(arm.0[j]));
                hi[j] = hi[j].max((q[j] + MEASURED_SLACK_RAD).min(arm.1[j]));
            }
        }
    }
    (lo, hi)
}

/// The end of an adapter process: its final summary (JSON) on stdout and, if asked, in the
/// `report` file; or its error (any error the process ends with) on stderr, a
/// [`log!`](crate::log!) line. Exit code 0, or 2 on an error or an unwritable report.
pub fn finish<E: std::fmt::Display>(
    name: &str,
    result: Result<serde_json::Value, E>,
    report: Option<&std::path::Path>,
) -> std::process::ExitCode {
    use std::process::ExitCode;
    match result {
        Ok(v) => {
            println!("{v}");
            if let Some(p) = report
                && let Err(e) = std::fs::write(p, format!("{v}\n"))
            {
                crate::log!("{name}: cannot write {}: {e}", p.display());
                return ExitCode::from(2);
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            crate::log!("{name}: error: {e}");
            ExitCode::from(2)
        }
    }
}

/// The result of an adapter whose hardware side (a ROS thread, a world thread) ended with
/// `side`: the `summary`, or the side's error (whatever its type) with the summary printed
/// first (so the figures of a run that failed are not lost).
pub fn summary_or_error<E>(
    summary: serde_json::Value,
    side: Result<(), E>,
) -> Result<serde_json::Value, E> {
    match side {
        Ok(()) => Ok(summary),
        Err(e) => {
            println!("{summary}");
            Err(e)
        }
    }
}

/// A latency histogram (ns, 1 ns to 100 s, 3 significant digits).
pub type Latency = hdrhistogram::Histogram<u64>;

/// An empty [`Latency`].
pub fn latency() -> Latency {
    Latency::new_with_bounds(1, 100_000_000_000, 3).expect("valid bounds")
}

/// p50, p99 and max of `h` in milliseconds, with the count.
pub fn latency_json(h: &Latency) -> serde_json::Value {
    let ms = |ns: u64| ns as f64 * 1e-6;
    serde_json::json!({
        "n": h.len(),
        "p50": ms(h.value_at_quantile(0.5)),
        "p99": ms(h.value_at_quantile(0.99)),
        "max": ms(h.max()),
    })
}

/// What came in on one command service.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    /// Samples received.
    pub received: u64,
    /// Samples refused by validation (never acted on).
    pub rejected: u64,
    /// Header stamp of the newest valid sample (CLOCK_MONOTONIC ns); 0 before the first.
    pub last_valid_stamp_ns: u64,
}

impl Counters {
    fn count(&mut self, header: &Header, valid: bool) {
        self.received += 1;
        if valid {
            self.last_valid_stamp_ns = self.last_valid_stamp_ns.max(header.stamp_ns);
        } else {
            self.rejected += 1;
        }
    }

    /// True when a valid sample arrived within `max_age_ns` of `now_ns`.
    pub fn fresh(&self, now_ns: u64, max_age_ns: u64) -> bool {
        self.last_valid_stamp_ns != 0
            && now_ns.saturating_sub(self.last_valid_stamp_ns) <= max_age_ns
    }
}

/// The arm adapter's ports: joint and gripper commands in, joint and gripper states out.
pub struct ArmPorts {
    joint_commands: Sub<JointCommand>,
    gripper_commands: Sub<GripperCommand>,
    joint_state: Pub<JointState>,
    gripper_state: Pub<GripperState>,
    arm_status: Pub<ArmStatus>,
    arm_status_seq: u64,
    /// The blocker last published and when.
    arm_status_said: Option<(ArmBlocker, u64)>,
    /// Joint commands.
    pub joint: Counters,
    /// Gripper commands.
    pub gripper: Counters,
}

impl std::fmt::Debug for ArmPorts {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ArmPorts")
            .field("joint", &self.joint)
            .field("gripper", &self.gripper)
            .finish()
    }
}

impl ArmPorts {
    /// Opens the five services under `bus`'s prefix.
    pub fn open(bus: &Bus) -> Result<Self, BusError> {
        let s: &Services = bus.services();
        Ok(Self {
            joint_commands: bus.subscriber(&s.joint_command())?,
            gripper_commands: bus.subscriber(&s.gripper_command())?,
            joint_state: bus.publisher(&s.joint_state())?,
            gripper_state: bus.publisher(&s.gripper_state())?,
            arm_status: bus.publisher(&s.arm_status())?,
            arm_status_seq: 0,
            arm_status_said: None,
            joint: Counters::default(),
            gripper: Counters::default(),
        })
    }

    /// Receives every pending joint command. Each is checked against the position limits
    /// `lower`..`upper` (and its header) and handed to `f` with the verdict; the hardware must
    /// act only on valid ones. Returns how many arrived.
    pub fn drain_joint_commands(
        &mut self,
        lower: &[f64; DOF],
        upper: &[f64; DOF],
        mut f: impl FnMut(&JointCommand, bool),
    ) -> usize {
        let mut n = 0;
        while let Ok(Some(sample)) = self.joint_commands.receive() {
            let c = sample.payload();
            let valid = c.validate(lower, upper).is_ok();
            self.joint.count(&c.header, valid);
            f(c, valid);
            n += 1;
        }
        n
    }

    /// Receives every pending gripper command; valid ones (header, action, an object type
    /// below `catalog_len`) go to `f` with their action, invalid ones are only counted.
    /// Returns how many arrived.
    pub fn drain_gripper_commands(
        &mut self,
        catalog_len: usize,
        mut f: impl FnMut(&GripperCommand, GripperAction),
    ) -> usize {
        let mut n = 0;
        while let Ok(Some(sample)) = self.gripper_commands.receive() {
            let c = sample.payload();
            let action = c.validate(catalog_len);
            self.gripper.count(&c.header, action.is_ok());
            if let Ok(a) = action {
                f(c, a);
            }
            n += 1;
        }
        n
    }

    /// Publishes the measured joint state (best effort: a full queue drops it).
    pub fn publish_joint_state(&self, s: JointState) {
        let _ = self.joint_state.send_copy(s);
    }

    /// Publishes the gripper state (best effort).
    pub fn publish_gripper_state(&self, s: GripperState) {
        let _ = self.gripper_state.send_copy(s);
    }

    /// Reports the adapter's state at `now_ns`, called every cycle: published (best effort,
    /// stamped now) at once when `blocker` changed, else every
    /// [`herb_ipc::ARM_STATUS_PERIOD_NS`]: why it withholds joint state, if it does, and how
    /// many commands its guard refused.
    pub fn report_arm_status(&mut self, blocker: ArmBlocker, commands_refused: u64, now_ns: u64) {
        let due = self.arm_status_said.is_none_or(|(said, at)| {
            said != blocker || now_ns.saturating_sub(at) >= herb_ipc::ARM_STATUS_PERIOD_NS
        });
        if !due {
            return;
        }
        self.arm_status_said = Some((blocker, now_ns));
        self.arm_status_seq += 1;
        let _ = self.arm_status.send_copy(ArmStatus {
            header: Header::now(self.arm_status_seq),
            blocker: blocker as u32,
            reserved: 0,
            commands_refused,
        });
    }
}

/// One heightmap to publish: a row-major grid over the box interior.
#[derive(Debug, Clone, Copy)]
pub struct Heightmap<'a> {
    /// Capture time (CLOCK_MONOTONIC ns).
    pub stamp_ns: u64,
    /// Columns (along B x).
    pub nx: u32,
    /// Rows (along B y).
    pub ny: u32,
    /// Cell side (m).
    pub cell_m: f32,
    /// Objects in the box, if the source knows (else 0).
    pub objects: u32,
    /// `nx * ny` heights above the inner floor (m).
    pub cells: &'a [f32],
}

/// The camera adapter's port: heightmap frames out, written in place in shared memory.
pub struct CameraPort {
    heightmap: Pub<HeightmapFrame>,
}

impl std::fmt::Debug for CameraPort {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CameraPort").finish()
    }
}

/// Why a frame was not published.
#[derive(Debug, Clone, PartialEq)]
pub enum PublishError {
    /// The grid does not match its cells or does not fit a frame.
    BadGrid {
        /// Columns.
        nx: u32,
        /// Rows.
        ny: u32,
        /// Cells given.
        cells: usize,
    },
    /// No shared-memory sample could be loaned (subscribers hold them all).
    Loan(String),
    /// The transport refused the sample.
    Send(String),
}

impl std::fmt::Display for PublishError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::BadGrid { nx, ny, cells } => write!(
                f,
                "{cells} cells for a {nx} x {ny} grid (a frame holds at most {HEIGHTMAP_MAX_CELLS})"
            ),
            Self::Loan(e) => write!(f, "no sample to loan: {e}"),
            Self::Send(e) => write!(f, "send failed: {e}"),
        }
    }
}

impl std::error::Error for PublishError {}

impl CameraPort {
    /// Opens the heightmap service under `bus`'s prefix.
    pub fn open(bus: &Bus) -> Result<Self, BusError> {
        Ok(Self {
            heightmap: bus.publisher(&bus.services().heightmap())?,
        })
    }

    /// Publishes `hm` as frame `seq`, stamped with its capture time.
    pub fn publish(&self, seq: u64, hm: &Heightmap<'_>) -> Result<(), PublishError> {
        let n = hm.nx as usize * hm.ny as usize;
        if n == 0 || n != hm.cells.len() || n > HEIGHTMAP_MAX_CELLS {
            return Err(PublishError::BadGrid {
                nx: hm.nx,
                ny: hm.ny,
                cells: hm.cells.len(),
            });
        }
        let mut s = self
            .heightmap
            .loan_uninit()
            .map_err(|e| PublishError::Loan(format!("{e:?}")))?;
        let f = zeroed_in_place(s.payload_mut());
        f.header = Header {
            seq,
            stamp_ns: hm.stamp_ns,
            ..Header::now(seq)
        };
        f.nx = hm.nx;
        f.ny = hm.ny;
        f.cell_m = hm.cell_m;
        f.objects = hm.objects;
        f.data[..n].copy_from_slice(hm.cells);
        // SAFETY: zeroed_in_place initialised every byte.
        let s = unsafe { s.assume_init() };
        s.send()
            .map(|_| ())
            .map_err(|e| PublishError::Send(format!("{e:?}")))
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_command_range_widens_to_a_sagged_arm_only_and_never_past_the_arm() {
        let (lo, hi) = ([-1.0; super::DOF], [1.0; super::DOF]);
        let (alo, ahi) = ([-1.05; super::DOF], [1.05; super::DOF]);
        let mut q = [0.0; super::DOF];
        q[1] = 1.0034;
        q[3] = 1.06; // beyond the arm's own limit: capped there
        let (l, h) = super::command_range((&lo, &hi), Some(&q), (&alo, &ahi));
        assert_eq!(l, lo);
        assert!((h[1] - (1.0034 + super::MEASURED_SLACK_RAD)).abs() < 1e-12);
        assert_eq!(h[3], 1.05);
        assert_eq!(h[0], 1.0, "a joint inside keeps herbd's limit");
        assert_eq!(
            super::command_range((&lo, &hi), None, (&alo, &ahi)),
            (lo, hi)
        );
    }

    use super::*;

    #[test]
    fn counters_count_refusals_and_track_the_newest_valid_stamp() {
        let mut c = Counters::default();
        assert!(!c.fresh(1_000, u64::MAX), "nothing received is never fresh");
        let at = |stamp_ns| Header {
            stamp_ns,
            ..Header::now(1)
        };
        c.count(&at(500), true);
        c.count(&at(900), false);
        c.count(&at(400), true);
        assert_eq!((c.received, c.rejected, c.last_valid_stamp_ns), (3, 1, 500));
        assert!(c.fresh(600, 100));
        assert!(!c.fresh(601, 100));
    }
}
