//! `herbd calibrate-cell`: the box and pick-station poses of herbd's `[cell]` table, measured
//! by touching them with the gripper.
//!
//! The operator moves the arm by hand (Baxter's cuff puts it in zero-g) until the gripper's tip
//! touches each inner floor corner of the box, in the order [`herb_robot::calibrate`] names, then
//! the centre of the pick station's surface, and presses Enter at each; the arm adapter's joint
//! states (the `joint_state` service, so the adapter must run; herbd need not) give the tip's
//! position by forward kinematics. The fitted `[cell]` lines are printed to paste into
//! `/etc/herb/herbd.toml`.

use herb_core::frames::{BOX_HALF_X, BOX_HALF_Y};
use herb_ipc::bus::Bus;
use herb_ipc::{JointState, Services, monotonic_ns};
use herb_robot::calibrate::{CalibrationError, box_from_corners, cell_toml, tip_in_base};
use herb_robot::kinematics::Arm;
use std::io::{BufRead, Write};
use std::time::{Duration, Instant};

/// Where each corner is, in the box frame B.
const CORNERS: [&str; 4] = [
    "corner 1 (-x, -y)",
    "corner 2 (+x, -y), along the long side from corner 1",
    "corner 3 (+x, +y)",
    "corner 4 (-x, +y)",
];

/// A joint state older than this when Enter is pressed is not used (s).
const MAX_AGE: Duration = Duration::from_millis(500);

/// Why the procedure stopped without a result.
#[derive(Debug, thiserror::Error)]
pub enum CellCalError {
    /// Neither 3 nor 4 corners asked for.
    #[error("--corners {0}: 3 or 4")]
    Corners(usize),
    /// A tip offset out of range.
    #[error("--tip-offset {0} outside -0.2..=0.2 m")]
    TipOffset(f64),
    /// The IPC prefix is not one.
    #[error(transparent)]
    Prefix(#[from] herb_ipc::BadPrefix),
    /// The joint states cannot be subscribed to.
    #[error(transparent)]
    Bus(#[from] herb_ipc::bus::BusError),
    /// The prompts cannot be written.
    #[error("output: {0}")]
    Output(std::io::Error),
    /// The answers cannot be read.
    #[error("input: {0}")]
    Input(std::io::Error),
    /// The answers ended first.
    #[error("input ended before the procedure did")]
    InputEnded,
    /// No fresh joint state within 2 s of an answer.
    #[error(
        "no joint state from the arm adapter under prefix {prefix:?} (is herb-baxter running?)"
    )]
    NoJointState {
        /// The prefix listened to.
        prefix: String,
    },
    /// A corner was skipped.
    #[error("{0} is needed")]
    Needed(&'static str),
    /// The corners give no box.
    #[error(transparent)]
    Fit(#[from] CalibrationError),
}

/// Runs the procedure under `prefix`: `corners` (3 or 4) corners, then the pick station unless
/// the operator types `skip`; `tip_offset_m` from the gripper's endpoint to the touching tip
/// along its approach axis. Prompts go to `out`, answers come from `input`. Returns the
/// `[cell]` lines.
pub fn run(
    prefix: &str,
    corners: usize,
    tip_offset_m: f64,
    input: &mut impl BufRead,
    out: &mut impl Write,
) -> Result<String, CellCalError> {
    if !(3..=4).contains(&corners) {
        return Err(CellCalError::Corners(corners));
    }
    if !(tip_offset_m.is_finite() && (-0.2..=0.2).contains(&tip_offset_m)) {
        return Err(CellCalError::TipOffset(tip_offset_m));
    }
    let services = Services::new(prefix)?;
    let bus = Bus::open("herbctl-calibrate", &services)?;
    let states = bus.subscriber::<JointState>(&services.joint_state())?;
    let arm = Arm::baxter_left();
    let mut latest: Option<JointState> = None;
    let say = |out: &mut dyn Write, text: &str| -> Result<(), CellCalError> {
        writeln!(out, "{text}")
            .and_then(|()| out.flush())
            .map_err(CellCalError::Output)
    };
    let mut touch = |what: &str, out: &mut dyn Write| -> Result<Option<[f64; 3]>, CellCalError> {
        say(
            out,
            &format!("Touch {what} with the gripper's tip, then press Enter (or type skip):"),
        )?;
        let mut line = String::new();
        let n = input.read_line(&mut line).map_err(CellCalError::Input)?;
        if n == 0 {
            return Err(CellCalError::InputEnded);
        }
        if line.trim() == "skip" {
            return Ok(None);
        }
        // The newest valid joint state, waiting up to 2 s for one.
        let t0 = Instant::now();
        loop {
            while let Ok(Some(s)) = states.receive() {
                if s.payload().validate().is_ok() {
                    latest = Some(*s.payload());
                }
            }
            let fresh = latest.filter(|s| {
                monotonic_ns().saturating_sub(s.header.stamp_ns) <= MAX_AGE.as_nanos() as u64
            });
            if let Some(s) = fresh {
                let p = tip_in_base(&arm, &s.position, tip_offset_m);
                say(
                    out,
                    &format!(
                        "  {what}: x {:+.4} y {:+.4} z {:+.4} m in base",
                        p[0], p[1], p[2]
                    ),
                )?;
                return Ok(Some(p));
            }
            if t0.elapsed() > Duration::from_secs(2) {
                return Err(CellCalError::NoJointState {
                    prefix: prefix.into(),
                });
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    };
    let mut points = Vec::with_capacity(corners);
    for what in &CORNERS[..corners] {
        let p = touch(&format!("the box's inner floor at {what}"), out)?
            .ok_or(CellCalError::Needed(what))?;
        points.push(p);
    }
    let fit = box_from_corners(
        &points,
        2.0 * f64::from(BOX_HALF_X),
        2.0 * f64::from(BOX_HALF_Y),
    )?;
    let pick = touch("the centre of the pick station's surface", out)?;
    Ok(cell_toml(&fit, pick))
}
