//! `herbctl calibrate-cell`: the box and pick-station poses of herbd's `[cell]` table, measured
//! by touching them with the gripper.
//!
//! The operator moves the arm by hand (Baxter's cuff puts it in zero-g) until the gripper's tip
//! touches each inner floor corner of the box, in the order [`herb_robot::calibrate`] names, then
//! the centre of the pick station's surface, and presses Enter at each; the arm adapter's joint
//! states (the `joint_state` service, so the adapter must run; herbd need not) give the tip's
//! position by forward kinematics. The fitted `[cell]` lines are printed to paste into
//! `/etc/herb/herbd.toml`.

use herb_ipc::bus::Bus;
use herb_ipc::{JointState, Services, monotonic_ns};
use herb_robot::calibrate::{box_from_corners, cell_toml, tip_in_base};
use herb_robot::kinematics::Arm;
use herb_sim::frames::{BOX_HALF_X, BOX_HALF_Y};
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
) -> Result<String, String> {
    if !(3..=4).contains(&corners) {
        return Err(format!("--corners {corners}: 3 or 4"));
    }
    if !(tip_offset_m.is_finite() && (-0.2..=0.2).contains(&tip_offset_m)) {
        return Err(format!("--tip-offset {tip_offset_m} outside -0.2..=0.2 m"));
    }
    let services = Services::new(prefix).map_err(|e| e.to_string())?;
    let bus = Bus::open("herbctl-calibrate", &services).map_err(|e| e.to_string())?;
    let states = bus
        .subscriber::<JointState>(&services.joint_state())
        .map_err(|e| e.to_string())?;
    let arm = Arm::baxter_left();
    let mut latest: Option<JointState> = None;
    let say = |out: &mut dyn Write, text: &str| -> Result<(), String> {
        writeln!(out, "{text}")
            .and_then(|()| out.flush())
            .map_err(|e| format!("output: {e}"))
    };
    let mut touch = |what: &str, out: &mut dyn Write| -> Result<Option<[f64; 3]>, String> {
        say(
            out,
            &format!("Touch {what} with the gripper's tip, then press Enter (or type skip):"),
        )?;
        let mut line = String::new();
        let n = input
            .read_line(&mut line)
            .map_err(|e| format!("input: {e}"))?;
        if n == 0 {
            return Err("input ended before the procedure did".into());
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
                return Err(format!(
                    "no joint state from the arm adapter under prefix {prefix:?} (is herb-baxter running?)"
                ));
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    };
    let mut points = Vec::with_capacity(corners);
    for what in &CORNERS[..corners] {
        let p = touch(&format!("the box's inner floor at {what}"), out)?
            .ok_or_else(|| format!("{what} is needed"))?;
        points.push(p);
    }
    let fit = box_from_corners(
        &points,
        2.0 * f64::from(BOX_HALF_X),
        2.0 * f64::from(BOX_HALF_Y),
    )
    .map_err(|e| e.to_string())?;
    let pick = touch("the centre of the pick station's surface", out)?;
    Ok(cell_toml(&fit, pick))
}
