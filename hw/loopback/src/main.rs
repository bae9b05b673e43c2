//! `herb-loopback`: a stand-in for the Baxter arm, its gripper and the depth camera, so the
//! whole controller runs on any machine.
//!
//! - **Arm**: follows `JointCommand`s (ideal tracking, or a first-order lag with `--lag-s`),
//!   never faster than the configured joint speed limits, and publishes `JointState` every cycle. Commands are validated against the configured
//!   joint limits (the same configuration file as `herbd`): an invalid one is counted and not
//!   followed; the largest excess seen is reported.
//! - **Gripper**: closing within 2 cm of the pick station's grasp point takes the object the
//!   daemon expects there (`GripperCommand::object_type`; a real pick station is fed in the
//!   planned order); opening releases the held object at the gripper pose given by forward
//!   kinematics, in a `herb-sim` packing world that then settles. Publishes `GripperState`
//!   every cycle.
//! - **Camera**: publishes the world's heightmap after every settle (stamped when the settle
//!   ended), and re-captures it every 200 ms (stamped then) while no release is settling:
//!   a frame is never stamped later than a release whose settle it does not show.
//! - **Sim-only**: publishes a `SimOutcome` after every release (inside, tilt, compactness,
//!   command counts, the releasing job) for tests, and empties the box on a `SimReset`
//!   (`herbctl reset`) while nothing is settling, taking a held object out of the gripper too.
//! - **Robot state**, as a real arm's adapter reports it: publishes an `ArmStatus` every
//!   100 ms and on each change. SIGUSR1 toggles a disable and SIGUSR2 an e-stop (released
//!   enabled): while either holds, joint states are withheld, commands are not followed and
//!   the arm sags (`--sag` rad/s on s1, half on e1), as a real arm does without power; once it
//!   can move again it holds where it is until a new command comes. Every command passes the
//!   adapter's jump guard (`herb_adapter::guard`) first; the summary lists each first
//!   command's distance from the arm after it could move again (`first_command_offsets_rad`).
//! - **Missed grasps**: with `--miss-grasps N` the first N grasps close on nothing; SIGRTMIN
//!   makes the next one close on nothing (a fault injected while it runs: `herb-chaos`).
//! - **Camera dropouts**: SIGRTMIN+1 publishes no heightmap for `--dropout-s` seconds.
//! - **Start pose**: `--start Q` (7 angles) starts the arm there, e.g. past herbd's limits.
//!
//! SIGINT/SIGTERM: prints a JSON summary on stdout and exits 0.

use clap::Parser;
use herb_adapter::guard::{GuardSettings, JumpGuard, REFUSAL_HOLD_NS, Refusal};
use herb_adapter::{ArmPorts, CameraPort, Heightmap};
use herb_core::{Catalog, TypeIdx, paths};
use herb_ipc::bus::Bus;
use herb_ipc::{
    ArmBlocker, CommandChecks, GripperAction, GripperCommand, GripperState, Header, JointCommand,
    JointState, MAX_JOB_OBJECTS, NO_OBJECT, SIM_BOUNDS, Services, SimObject, SimOutcome, SimReset,
    monotonic_ns,
};
use herb_loopback::config::{ConfigFile, LoopbackConfig};
use herb_process::rt::{set_timer_slack, sleep_until};
use herb_robot::cell::CellConfig;
use herb_robot::kinematics::{Arm, DOF, LEFT_TOP_DOWN_NOMINAL};
use herb_world::{PackingWorld, WorldConfig};
use nalgebra::Isometry3;
use rapier3d::math::{Pose, Rotation, Vector};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::mpsc;
use std::time::Duration;

/// A simulated Baxter left arm, gripper and box camera over iceoryx2.
#[derive(Debug, Parser)]
#[command(name = "herb-loopback", version)]
struct Cli {
    /// The herbd configuration file (prefix, cell geometry, joint limits).
    #[arg(long)]
    config: Option<PathBuf>,
    /// IPC service-name prefix (overrides the file).
    #[arg(long)]
    prefix: Option<String>,
    /// BoxED folder (object meshes; primitives without it).
    #[arg(long)]
    boxed: Option<PathBuf>,
    /// Publishing rate (Hz).
    #[arg(long, default_value_t = 1000.0)]
    rate_hz: f64,
    /// First-order tracking lag (s); 0 tracks ideally.
    #[arg(long, default_value_t = 0.0)]
    lag_s: f64,
    /// Also write the final summary (JSON) here.
    #[arg(long)]
    report: Option<PathBuf>,
    /// How fast the arm sags while disabled or e-stopped (rad/s on s1, half on e1).
    #[arg(long, default_value_t = 0.05)]
    sag: f64,
    /// Where the arm stands at start: 7 comma-separated angles (rad), s0 .. w2, inside the
    /// arm's own limits (e.g. past herbd's, as an arm that sagged while the cell was off).
    /// Default: the top-down nominal configuration.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    start: Vec<f64>,
    /// The first N grasps close on nothing (a missed grasp). While it runs, SIGRTMIN makes
    /// the next grasp close on nothing.
    #[arg(long, default_value_t = 0)]
    miss_grasps: u32,
    /// How long the camera drops out on SIGRTMIN+1 (s): no heightmap is published meanwhile.
    #[arg(long, default_value_t = 3.0)]
    dropout_s: f64,
    /// Jump guard: command periods of travel at the speed limit allowed past the arm.
    #[arg(long, default_value_t = 3.0)]
    guard_periods: f64,
    /// Jump guard: how long the arm may trail its command (s), on top of `--lag-s`.
    #[arg(long, default_value_t = 0.02)]
    tracking_lag_s: f64,
}

/// SIGUSR1 (disable) and SIGUSR2 (e-stop) toggles, counted by the handler.
static TOGGLES: [AtomicU32; 2] = [AtomicU32::new(0), AtomicU32::new(0)];

extern "C" fn on_toggle(sig: libc::c_int) {
    let k = usize::from(sig != libc::SIGUSR1);
    TOGGLES[k].fetch_add(1, Ordering::Relaxed);
}

/// Faults injected while it runs, counted by the handler: SIGRTMIN (the next grasp misses),
/// SIGRTMIN+1 (the camera drops out for `--dropout-s`).
static INJECTED: [AtomicU32; 2] = [AtomicU32::new(0), AtomicU32::new(0)];

extern "C" fn on_inject(sig: libc::c_int) {
    let k = usize::from(sig != libc::SIGRTMIN());
    INJECTED[k].fetch_add(1, Ordering::Relaxed);
}

struct Released {
    stamp_ns: u64,
    heightmap: Vec<f32>,
    nx: u32,
    ny: u32,
    cell_m: f32,
    objects: u32,
    /// Every object in the box: where it is, whether inside.
    placed: [SimObject; MAX_JOB_OBJECTS],
    /// The outcome, the released type, the release pose and the releasing job.
    outcome: Option<(herb_world::PlacementOutcome, u32, [f32; 4], u64)>,
}

/// What the publishing loop asks of the world thread.
enum ToWorld {
    /// Release an object (type, pose in B, the releasing job) and settle.
    Release(TypeIdx, Pose, u64),
    /// Empty the box.
    Reset,
}

/// The world thread: releases objects and settles, off the publishing loop.
fn world_thread(
    catalog: Arc<Catalog>,
    rx: mpsc::Receiver<ToWorld>,
    tx: mpsc::Sender<Result<Released, String>>,
) {
    let mut world = match PackingWorld::new(catalog, WorldConfig::default()) {
        Ok(w) => w,
        Err(e) => {
            let _ = tx.send(Err(format!("world: {e}")));
            return;
        }
    };
    let snapshot = |w: &mut PackingWorld, outcome| {
        let mut placed = [SimObject::default(); MAX_JOB_OBJECTS];
        for (slot, r) in placed.iter_mut().zip(w.report()) {
            let bound = r.violation.map_or(0, |(name, _)| {
                SIM_BOUNDS.iter().position(|b| *b == name).unwrap_or(0) as u32
            });
            *slot = SimObject {
                object_type: r.ty.0 as u32,
                bound,
                over_m: r.violation.map_or(0.0, |v| v.1),
                yaw_rad: r.yaw,
                lo: r.lo,
                hi: r.hi,
                origin: r.origin,
                rotation: r.rotation,
            };
        }
        let hm = w.heightmap();
        Released {
            placed,
            stamp_ns: monotonic_ns(),
            heightmap: hm.data().to_vec(),
            nx: hm.spec().nx as u32,
            ny: hm.spec().ny as u32,
            cell_m: hm.spec().cell,
            objects: w.placed().len() as u32,
            outcome,
        }
    };
    let _ = tx.send(Ok(snapshot(&mut world, None)));
    for msg in rx {
        let (ty, pose, job_id) = match msg {
            ToWorld::Release(ty, pose, job_id) => (ty, pose, job_id),
            ToWorld::Reset => {
                world.reset();
                let _ = tx.send(Ok(snapshot(&mut world, None)));
                continue;
            }
        };
        let yaw = {
            let x = pose.rotation * Vector::X;
            x.y.atan2(x.x)
        };
        let release = [
            pose.translation.x,
            pose.translation.y,
            pose.translation.z,
            yaw,
        ];
        match world.place_pose(ty, pose) {
            Ok(o) => {
                let _ = tx.send(Ok(snapshot(
                    &mut world,
                    Some((o, ty.0 as u32, release, job_id)),
                )));
            }
            Err(e) => {
                let _ = tx.send(Err(format!("release of type {}: {e}", ty.0)));
            }
        }
    }
}

fn to_pose(iso: &Isometry3<f64>) -> Pose {
    let t = iso.translation.vector;
    let q = iso.rotation.quaternion();
    Pose::from_parts(
        Vector::new(t.x as f32, t.y as f32, t.z as f32),
        Rotation::from_xyzw(q.i as f32, q.j as f32, q.k as f32, q.w as f32).normalize(),
    )
}

struct Sim {
    cell: CellConfig,
    arm: Arm,
    catalog: Arc<Catalog>,
    lower: [f64; DOF],
    upper: [f64; DOF],
    /// The arm's own position limits (its URDF's, wider than herbd's): how far it sags.
    arm_range: ([f64; DOF], [f64; DOF]),
    /// Joint speed limits: the simulated arm never moves faster, whatever the commands did
    /// while this process was stalled or before it started.
    vmax: [f64; DOF],
    q: [f64; DOF],
    qd: [f64; DOF],
    target: [f64; DOF],
    closed: bool,
    held: Option<(TypeIdx, Isometry3<f64>)>,
    max_excess: f64,
    releases: u64,
    last_outcome: Option<SimOutcome>,
    settling: u64,
    /// Why the arm cannot move (disabled, e-stop), if it cannot.
    blocker: Option<ArmBlocker>,
    guard: JumpGuard,
    /// The last joint state's stamp (the guard compares commands with it).
    measured_at: u64,
    /// A command has been followed since the arm could move again.
    commanded_since_ready: bool,
    /// Each first command's distance from the arm after it could move again (rad).
    first_offsets: Vec<f64>,
    /// Joint state is withheld until then after a command refused for its distance.
    refused_until: u64,
    /// Grasps still to miss.
    miss_grasps: u32,
    missed: u32,
}

impl Sim {
    /// A joint command as received, with the adapter's verdict: the largest excess over the
    /// limits is recorded for every one, only valid ones are followed.
    fn command(&mut self, c: &JointCommand, valid: bool, now: u64) {
        for i in 0..DOF {
            let p = c.position[i];
            if p.is_finite() {
                let excess = (self.lower[i] - p).max(p - self.upper[i]).max(0.0);
                self.max_excess = self.max_excess.max(excess);
            }
        }
        if !valid {
            return;
        }
        let q = self.q;
        let verdict = self.guard.check(
            c.header.stamp_ns,
            &c.position,
            Some((self.measured_at, &q)),
            now,
        );
        if let Err(r) = verdict {
            if matches!(r, Refusal::TooFar { .. }) {
                // herbd and the arm disagree: halt herbd, which resumes from the arm.
                self.refused_until = now + REFUSAL_HOLD_NS;
                self.guard.set_ready(false, now);
            }
            return;
        }
        if !self.commanded_since_ready {
            self.commanded_since_ready = true;
            let offset = (0..DOF)
                .map(|i| (c.position[i] - q[i]).abs())
                .fold(0.0, f64::max);
            self.first_offsets.push(offset);
        }
        self.target = c.position;
    }

    /// Applies the faults injected by signal since `seen`: missed grasps to come, and a camera
    /// dropout until `camera_off_until` (`dropout_s` long).
    fn injected(
        &mut self,
        seen: &mut [u32; 2],
        camera_off_until: &mut u64,
        now: u64,
        dropout_s: f64,
    ) {
        let misses = INJECTED[0].load(Ordering::Relaxed);
        if misses != seen[0] {
            self.miss_grasps += misses.wrapping_sub(seen[0]);
            seen[0] = misses;
            eprintln!("herb-loopback: the next grasp misses (SIGRTMIN)");
        }
        let dropouts = INJECTED[1].load(Ordering::Relaxed);
        if dropouts != seen[1] {
            seen[1] = dropouts;
            *camera_off_until = now + (dropout_s * 1e9) as u64;
            eprintln!("herb-loopback: camera drops out for {dropout_s} s (SIGRTMIN+1)");
        }
    }

    /// Moves the arm over `dt` seconds: it sags (`sag` rad/s) while unpowered, else tracks its
    /// target (the fraction `a` of the way, within its speed limits).
    fn advance(&mut self, dt: f64, a: f64, sag: f64) {
        if self.blocker.is_some() {
            // Unpowered: the arm sags (s1 and e1 under gravity), within its own limits (past
            // herbd's, as a real Baxter's shoulder does).
            for (i, rate) in [(1, sag), (3, 0.5 * sag)] {
                let (lo, hi) = (self.arm_range.0[i], self.arm_range.1[i]);
                let nq = (self.q[i] + rate * dt).clamp(lo, hi);
                self.qd[i] = (nq - self.q[i]) / dt;
                self.q[i] = nq;
            }
        } else {
            for i in 0..DOF {
                // A stall between taking the commands and measuring the time leaves a whole
                // stall's worth of commanded motion to one short cycle: the arm's speed limit
                // bounds it.
                let reach = self.vmax[i] * dt;
                let nq = self.q[i] + (a * (self.target[i] - self.q[i])).clamp(-reach, reach);
                self.qd[i] = (nq - self.q[i]) / dt;
                self.q[i] = nq;
            }
        }
    }

    /// Applies the signal toggles counted so far.
    fn toggles(&mut self, seen: &mut [u32; 2], now: u64) {
        let mut changed = false;
        for (k, seen) in seen.iter_mut().enumerate() {
            let n = TOGGLES[k].load(Ordering::Relaxed);
            while *seen != n {
                *seen = seen.wrapping_add(1);
                let this = if k == 0 {
                    ArmBlocker::Disabled
                } else {
                    ArmBlocker::EStop
                };
                self.blocker = match self.blocker {
                    Some(b) if b == this => None,
                    // An e-stop outranks a disable; releasing it leaves the arm enabled.
                    _ => Some(this),
                };
                changed = true;
            }
        }
        if changed {
            let ready = self.blocker.is_none();
            self.guard.set_ready(ready, now);
            if ready {
                // Powered again: hold where the arm is until a new command comes.
                self.target = self.q;
                self.commanded_since_ready = false;
            }
            eprintln!(
                "herb-loopback: {}",
                self.blocker.map_or("robot ready", |b| b.fault().describe())
            );
        }
    }

    /// A valid gripper command.
    fn gripper(
        &mut self,
        c: &GripperCommand,
        action: GripperAction,
        release: &mpsc::Sender<ToWorld>,
    ) {
        match action {
            GripperAction::Close if !self.closed => {
                self.closed = true;
                if self.miss_grasps > 0 {
                    self.miss_grasps -= 1;
                    self.missed += 1;
                } else if c.object_type != NO_OBJECT {
                    let ty = TypeIdx(c.object_type as u16);
                    let h = self.catalog.shape(ty).extents().z as f64;
                    let object = self.cell.pick_object_pose(h);
                    let tool = self.arm.fk(&self.q);
                    if (tool.translation.vector - self.cell.grasp_point(h)).norm() < 0.02 {
                        self.held = Some((ty, tool.inverse() * object));
                    }
                }
            }
            GripperAction::Open if self.closed => {
                self.closed = false;
                if let Some((ty, in_tool)) = self.held.take() {
                    let object = self.arm.fk(&self.q) * in_tool;
                    let in_box = self.cell.box_pose().inverse() * object;
                    let _ = release.send(ToWorld::Release(ty, to_pose(&in_box), c.job_id));
                    self.releases += 1;
                    self.settling += 1;
                }
            }
            _ => {}
        }
    }
}

fn publish_frame(camera: &CameraPort, seq: u64, r: &Released) {
    let frame = Heightmap {
        stamp_ns: r.stamp_ns,
        nx: r.nx,
        ny: r.ny,
        cell_m: r.cell_m,
        objects: r.objects,
        cells: &r.heightmap,
    };
    if let Err(e) = camera.publish(seq, &frame) {
        eprintln!("herb-loopback: heightmap not published: {e}");
    }
}

/// The command line's values checked (each against its range); the arm's start pose.
fn checked_start(cli: &Cli) -> Result<[f64; DOF], String> {
    if !(cli.rate_hz.is_finite() && (10.0..=10_000.0).contains(&cli.rate_hz)) {
        return Err(format!("--rate-hz {} outside 10..=10000", cli.rate_hz));
    }
    if !(cli.lag_s.is_finite() && (0.0..=1.0).contains(&cli.lag_s)) {
        return Err(format!("--lag-s {} outside 0..=1", cli.lag_s));
    }
    if !(0.0..=600.0).contains(&cli.dropout_s) {
        return Err(format!("--dropout-s {} outside 0..=600", cli.dropout_s));
    }
    let start = match cli.start.len() {
        0 => LEFT_TOP_DOWN_NOMINAL,
        DOF => {
            let q: [f64; DOF] = std::array::from_fn(|i| cli.start[i]);
            let (lo, hi) = herb_robot::motion::baxter_left_arm_range();
            if let Some(e) = herb_robot::motion::excess_of(&q, &lo, &hi) {
                return Err(format!(
                    "--start: joint {} at {} rad is beyond the arm's own limit {} rad",
                    herb_ipc::JOINT_NAMES[e.joint],
                    e.position,
                    e.bound
                ));
            }
            q
        }
        n => return Err(format!("--start needs {DOF} angles (rad), got {n}")),
    };
    if !(cli.sag.is_finite() && (0.0..=1.0).contains(&cli.sag)) {
        return Err(format!("--sag {} outside 0..=1 rad/s", cli.sag));
    }
    if !(cli.guard_periods.is_finite() && (1.0..=100.0).contains(&cli.guard_periods)) {
        return Err(format!(
            "--guard-periods {} outside 1..=100",
            cli.guard_periods
        ));
    }
    if !(cli.tracking_lag_s.is_finite() && (0.0..=0.5).contains(&cli.tracking_lag_s)) {
        return Err(format!(
            "--tracking-lag-s {} outside 0..=0.5",
            cli.tracking_lag_s
        ));
    }
    Ok(start)
}

/// The fault toggles' and injections' signal handlers (SIGUSR1/2, SIGRTMIN, SIGRTMIN+1).
fn install_signal_handlers() -> Result<(), String> {
    for sig in [libc::SIGUSR1, libc::SIGUSR2] {
        // SAFETY: the handler only increments an atomic (async-signal-safe).
        let prev = unsafe { libc::signal(sig, on_toggle as *const () as libc::sighandler_t) };
        if prev == libc::SIG_ERR {
            return Err(format!("signal handler for {sig}"));
        }
    }
    for sig in [libc::SIGRTMIN(), libc::SIGRTMIN() + 1] {
        // SAFETY: the handler only increments an atomic (async-signal-safe).
        let prev = unsafe { libc::signal(sig, on_inject as *const () as libc::sighandler_t) };
        if prev == libc::SIG_ERR {
            return Err(format!("signal handler for {sig}"));
        }
    }
    Ok(())
}

fn run(cli: Cli) -> Result<serde_json::Value, String> {
    let mut cfg =
        LoopbackConfig::load_or_default(cli.config.as_deref()).map_err(|e| e.to_string())?;
    if let Some(p) = &cli.prefix {
        cfg.ipc_prefix = p.clone();
    }
    cfg.validate().map_err(|e| e.to_string())?;
    let start = checked_start(&cli)?;
    let services = Services::new(&cfg.ipc_prefix).map_err(|e| e.to_string())?;
    let root = paths::boxed_root(cli.boxed.as_deref().or(cfg.models.boxed.as_deref()));
    let catalog = Arc::new(
        Catalog::builtin(&paths::mesh_source(None, root.as_deref()))
            .map_err(|e| format!("catalog: {e}"))?,
    );
    let stop = Arc::new(AtomicBool::new(false));
    {
        let s = stop.clone();
        ctrlc::set_handler(move || s.store(true, Ordering::Relaxed)).map_err(|e| e.to_string())?;
    }
    let bus = Bus::open("herb-loopback", &services).map_err(|e| e.to_string())?;
    let mut arm = ArmPorts::open(&bus).map_err(|e| e.to_string())?;
    install_signal_handlers()?;
    let camera = CameraPort::open(&bus).map_err(|e| e.to_string())?;
    let out_pub = bus
        .publisher::<SimOutcome>(&services.sim_outcome())
        .map_err(|e| e.to_string())?;
    let reset_sub = bus
        .subscriber::<SimReset>(&services.sim_reset())
        .map_err(|e| e.to_string())?;
    let (mut resets, mut resets_refused) = (0u64, 0u64);

    let (rel_tx, rel_rx) = mpsc::channel();
    let (res_tx, res_rx) = mpsc::channel();
    {
        let c = catalog.clone();
        std::thread::Builder::new()
            .name("loopback-world".into())
            .spawn(move || world_thread(c, rel_rx, res_tx))
            .map_err(|e| e.to_string())?;
    }
    let mut sim = Sim {
        cell: cfg.cell,
        arm: Arm::baxter_left(),
        catalog: catalog.clone(),
        lower: cfg.limits.lower,
        upper: cfg.limits.upper,
        arm_range: herb_robot::motion::baxter_left_arm_range(),
        vmax: cfg.limits.velocity,
        q: start,
        qd: [0.0; DOF],
        target: start,
        closed: false,
        held: None,
        max_excess: 0.0,
        releases: 0,
        last_outcome: None,
        settling: 0,
        blocker: None,
        // A first-order lag (`--lag-s`) trails by about speed x lag: allowed on top.
        guard: JumpGuard::new(GuardSettings::from_limits(
            &cfg.limits.velocity,
            cli.rate_hz,
            cli.guard_periods,
            cli.tracking_lag_s + cli.lag_s,
        )),
        measured_at: 0,
        refused_until: 0,
        commanded_since_ready: false,
        first_offsets: Vec::with_capacity(64),
        miss_grasps: cli.miss_grasps,
        missed: 0,
    };
    sim.guard.set_ready(true, monotonic_ns());
    let mut toggles_seen = [0u32; 2];
    eprintln!(
        "herb-loopback: prefix {:?}, {} Hz, {} objects ({})",
        cfg.ipc_prefix,
        cli.rate_hz,
        catalog.len(),
        if root.is_some() {
            "meshes if present"
        } else {
            "primitives"
        }
    );
    let period = (1e9 / cli.rate_hz) as u64;
    set_timer_slack();
    let mut next = monotonic_ns() + period;
    let mut last_cycle = monotonic_ns();
    let mut seq = 0u64;
    let mut latest: Option<Released> = None;
    let mut last_frame = 0u64;
    let mut injected_seen = [0u32; 2];
    let mut camera_off_until = 0u64;
    let mut world_error = None;
    while !stop.load(Ordering::Relaxed) {
        sleep_until(next, 0);
        next += period;
        let now = monotonic_ns();
        if now > next {
            next = now + period;
        }
        let refusing = now < sim.refused_until;
        if !refusing && sim.refused_until != 0 && sim.blocker.is_none() {
            // The hold after a refusal is over: a new epoch (commands from before refused).
            sim.refused_until = 0;
            sim.guard.set_ready(true, now);
        }
        sim.toggles(&mut toggles_seen, now);
        sim.injected(
            &mut injected_seen,
            &mut camera_off_until,
            now,
            cli.dropout_s,
        );
        let camera_on = now >= camera_off_until;
        let said = match sim.blocker {
            Some(b) => b,
            None if refusing => ArmBlocker::CommandRefused,
            None => ArmBlocker::None,
        };
        arm.report_arm_status(said, sim.guard.refused, now);
        // herbd's limits, widened to an arm that sagged past them (herbd brings it back in).
        let (lower, upper) = herb_adapter::command_range(
            (&sim.lower, &sim.upper),
            Some(&sim.q),
            (&sim.arm_range.0, &sim.arm_range.1),
        );
        if sim.blocker.is_some() {
            // No power: nothing is followed (commands are still drained and counted).
            arm.drain_joint_commands(&lower, &upper, |_, _| {});
        } else {
            arm.drain_joint_commands(&lower, &upper, |c, valid| sim.command(c, valid, now));
        }
        let types = sim.catalog.len();
        arm.drain_gripper_commands(types, |c, a| sim.gripper(c, a, &rel_tx));
        // Empty the box (and the gripper) on request, only while nothing is settling; the heightmap of
        // the empty box that follows is the confirmation.
        while let Ok(Some(r)) = reset_sub.receive() {
            // A request handed over from history (sent before this loopback started) is old.
            let r = r.payload();
            if r.validate().is_err() || now.saturating_sub(r.header.stamp_ns) > 1_000_000_000 {
                continue;
            }
            if sim.settling == 0 && rel_tx.send(ToWorld::Reset).is_ok() {
                resets += 1;
                sim.last_outcome = None;
                // The gripper is emptied too (an operator takes the object out).
                if sim.held.take().is_some() {
                    sim.closed = false;
                    eprintln!("herb-loopback: the held object was taken out of the gripper");
                }
            } else {
                resets_refused += 1;
                eprintln!("herb-loopback: box reset refused: an object is settling");
            }
        }
        // The real time since the last measurement, read after the commands were taken (a
        // cycle preempted before or while draining them sees more motion and more time): a late
        // or stalled cycle reports the arm's speed, not the distance covered divided by the
        // nominal period. The joint state is stamped with this measurement time.
        let measured = monotonic_ns();
        let dt = (measured.saturating_sub(last_cycle) as f64 * 1e-9).max(1e-6);
        last_cycle = measured;
        // Track the target.
        let a = if cli.lag_s > 0.0 {
            (dt / cli.lag_s).min(1.0)
        } else {
            1.0
        };
        sim.advance(dt, a, cli.sag);
        seq += 1;
        sim.measured_at = measured;
        if sim.blocker.is_none() && !refusing {
            arm.publish_joint_state(JointState {
                header: Header {
                    stamp_ns: measured,
                    ..Header::now(seq)
                },
                position: sim.q,
                velocity: sim.qd,
            });
        }
        arm.publish_gripper_state(GripperState {
            header: Header::now(seq),
            closed: sim.closed as u32,
            holding: sim.held.is_some() as u32,
            object_type: sim.held.map_or(NO_OBJECT, |h| h.0.0 as u32),
            reserved: 0,
        });
        while let Ok(r) = res_rx.try_recv() {
            match r {
                Ok(r) => {
                    if let Some((o, ty, release, job_id)) = r.outcome {
                        sim.settling = sim.settling.saturating_sub(1);
                        let m = SimOutcome {
                            header: Header::now(seq),
                            job_id,
                            objects: r.objects,
                            object_type: ty,
                            all_inside: o.inside as u32,
                            stable: o.stable as u32,
                            tilt_rad: o.tilt_rad,
                            compactness: o.compactness,
                            release,
                            commands: CommandChecks {
                                max_limit_excess_rad: sim.max_excess,
                                received: arm.joint.received,
                                rejected: arm.joint.rejected,
                            },
                            placed: r.placed,
                        };
                        let _ = out_pub.send_copy(m);
                        sim.last_outcome = Some(m);
                    }
                    if camera_on {
                        publish_frame(&camera, seq, &r);
                        last_frame = now;
                    }
                    latest = Some(r);
                }
                Err(e) => {
                    sim.settling = sim.settling.saturating_sub(1);
                    eprintln!("herb-loopback: {e}");
                    world_error = Some(e);
                }
            }
        }
        if now.saturating_sub(last_frame) >= 200_000_000
            && camera_on
            && sim.settling == 0
            && let Some(r) = &mut latest
        {
            r.stamp_ns = now;
            publish_frame(&camera, seq, r);
            last_frame = now;
        }
    }
    std::thread::sleep(Duration::from_millis(1));
    let o = sim.last_outcome;
    Ok(serde_json::json!({ "loopback_final": {
        "commands": arm.joint.received,
        "commands_rejected": arm.joint.rejected,
        "gripper_commands_rejected": arm.gripper.rejected,
        "max_limit_excess_rad": sim.max_excess,
        "releases": sim.releases,
        "objects_in_box": o.map_or(0, |o| o.objects),
        "all_inside": o.is_some_and(|o| o.all_inside == 1),
        "compactness": o.map_or(0.0, |o| o.compactness),
        "world_error": world_error,
        "resets": resets,
        "resets_refused": resets_refused,
        "commands_refused": sim.guard.refused,
        "max_command_offset_rad": sim.guard.max_offset_rad,
        "first_command_offsets_rad": sim.first_offsets,
        "missed_grasps": sim.missed,
    }}))
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let report = cli.report.clone();
    herb_adapter::finish("herb-loopback", run(cli), report.as_deref())
}
