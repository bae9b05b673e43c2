//! `herbctl`: submit a pack job to `herbd`, follow it live, print per-object results and a
//! summary (Ctrl-C cancels the job); cancel a running job; empty the simulated box; print the
//! daemon's state.

mod interrupt;
mod operator;
mod pack;
mod words;

use clap::{Parser, Subcommand};
use herb_client::{Client, JobEvent, StatusError, WatchError};
use herb_daemon::record::Log;
use herb_daemon::replay::{Outcome, ReplayOptions, Replayed};
use herb_ipc::{
    Fault, Header, HeightmapFrame, JobState, Services, SimOutcome, SimReset, Status, StatusEvent,
    monotonic_ns,
};
use herb_sim::{Catalog, GridSpec, Heightmap, TypeIdx, paths};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// Client of the HERB packing controller.
#[derive(Debug, Parser)]
#[command(name = "herbctl", version)]
struct Cli {
    /// IPC service-name prefix.
    #[arg(long, default_value = Services::DEFAULT_PREFIX, global = true)]
    prefix: String,
    /// BoxED folder (sessions; object meshes are not needed here).
    #[arg(long, global = true)]
    boxed: Option<PathBuf>,
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Debug, Subcommand)]
enum Cmd {
    /// Submit a job and follow it to the end. Ctrl-C (or SIGTERM) cancels the job: the arm
    /// brakes and retreats, herbctl waits for herbd to confirm it and exits 130 (again: exits
    /// at once). Exit 0: done; 1: not done (failed, cancelled, timed out); 2: an error.
    Pack {
        /// A BoxED session whose objects to pack (e.g. p1_s1).
        #[arg(long, conflicts_with = "objects")]
        session: Option<String>,
        /// Catalog ids, comma-separated (e.g. 003,005,011).
        #[arg(long, value_delimiter = ',')]
        objects: Vec<String>,
        /// Write the final heightmap of the box here (PNG).
        #[arg(long)]
        picture: Option<PathBuf>,
        /// Give up after this many seconds, submitting included: a running job is cancelled
        /// (exit 1).
        #[arg(long, default_value_t = 900.0)]
        timeout: f64,
        /// Print the summary as one JSON line.
        #[arg(long)]
        json: bool,
        /// A real cell fed by hand: at each try of each pick, say which object to put at the
        /// pick station; the arm waits above the station until you press Enter (or
        /// `--operator-wait`), then descends and grasps.
        #[arg(long)]
        operator: bool,
        /// With `--operator`: confirm by itself this many seconds after asking, instead of
        /// waiting for Enter.
        #[arg(long, requires = "operator")]
        operator_wait: Option<f64>,
        /// When herbd goes silent, wait this long (s) for it to come back with the job (a
        /// restarted herbd takes an unfinished job up from its journal); 0 gives up at once.
        #[arg(long, default_value_t = 60.0)]
        reconnect: f64,
        /// Return once herbd accepted the job, leaving it running: print its id, how to follow
        /// it (`herbctl watch`) and how to cancel it (`herbctl cancel --job ID`).
        #[arg(long, conflicts_with_all = ["picture", "operator"])]
        detach: bool,
    },
    /// Empty the simulated box (the loopback; a real cell's box is emptied by hand). Refused
    /// while herbd runs a job.
    Reset {
        /// Give up after this many seconds.
        #[arg(long, default_value_t = 5.0)]
        timeout: f64,
    },
    /// Cancel the running job: the arm brakes, retreats straight up and the job ends
    /// `JobCancelled` (a job stopped on a fault ends where it stands). Waits for that end.
    Cancel {
        /// The job to cancel (default: the running one, from herbd's heartbeat).
        #[arg(long)]
        job: Option<u64>,
        /// Give up after this many seconds.
        #[arg(long, default_value_t = 30.0)]
        timeout: f64,
    },
    /// Re-run a run log (`herbd --record DIR`) offline: the job state machine on the recorded
    /// inputs, the decisions and motion plans on the recorded heightmaps; report the first
    /// divergence. Exit 0: reproduced bit for bit; 1: diverged; 3: the log is incomplete.
    Replay {
        /// A segment file (RUN-<start>-<n>.log).
        log: PathBuf,
        /// Replay even if the catalog or a model differs from the run's.
        #[arg(long)]
        force: bool,
        /// Also write what the replay saw as JSON lines for a recording
        /// (`python -m herb_client.view --events FILE --save job.rrd`): each status but the
        /// heartbeats, and each heightmap a decision was made on.
        #[arg(long)]
        events: Option<PathBuf>,
    },
    /// Why object N (1-based, as `herbctl pack` numbers them) went where it did: the
    /// heightmap it was decided on and the next one (PNGs), the policy's action, the z
    /// estimate, the placement, the outcome.
    Explain {
        /// A segment file.
        log: PathBuf,
        /// The object (1-based, in the packing order).
        #[arg(long)]
        object: u32,
        /// Where to write object-N-before.png and object-N-after.png.
        #[arg(long, default_value = ".")]
        out: PathBuf,
        /// Explain even if the catalog or a model differs from the run's.
        #[arg(long)]
        force: bool,
    },
    /// A live view of herbd: job progress, the last decision, loop statistics, faults, the
    /// simulated box, recent events. Ctrl-C quits.
    Watch {
        /// Seconds between redraws.
        #[arg(long, default_value_t = 0.25)]
        period: f64,
        /// Quit after this many seconds (default: run until Ctrl-C).
        #[arg(long)]
        duration: Option<f64>,
        /// Print each view below the previous one instead of redrawing the screen.
        #[arg(long)]
        plain: bool,
    },
    /// Measure the box and pick-station poses for herbd's `[cell]` table by touching them with
    /// the gripper (the arm moved by hand; the arm adapter must run): prints the lines to paste.
    CalibrateCell {
        /// Box corners to touch: 3 or 4.
        #[arg(long, default_value_t = 4)]
        corners: usize,
        /// From the gripper's endpoint to the touching tip, along its approach axis (m).
        #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
        tip_offset: f64,
    },
    /// Print the object catalog as JSON for viewers (`python -m herb_client.view`): the box
    /// (half lengths, height, wall thickness; m) and each object type's id, name and convex
    /// hull (vertices in its canonical frame, m, and outward triangles), from the BoxED meshes
    /// (`--boxed`) when present, else the primitives.
    Catalog,
    /// Print the daemon's next heartbeat.
    Status {
        /// Give up after this many seconds.
        #[arg(long, default_value_t = 5.0)]
        timeout: f64,
    },
}

fn name(catalog: &Catalog, t: u32) -> String {
    if (t as usize) < catalog.len() {
        let s = catalog.spec(TypeIdx(t as u16));
        format!("{} {}", s.id, s.name)
    } else {
        "-".into()
    }
}

/// The catalog id of type `t` (`-` if none).
fn id_of(catalog: &Catalog, t: u32) -> String {
    if (t as usize) < catalog.len() {
        catalog.spec(TypeIdx(t as u16)).id.clone()
    } else {
        "-".into()
    }
}

fn status(cli: &Cli, timeout: f64) -> Result<bool, String> {
    let client = connect(cli)?;
    let within = Duration::try_from_secs_f64(timeout).unwrap_or(Duration::ZERO);
    let s = client.status(within).map_err(|e| e.to_string())?;
    let state = JobState::from_code(s.state).unwrap_or(JobState::Idle);
    let fault = Fault::from_code(s.fault).unwrap_or(Fault::None);
    // Between jobs the fault is why a job would be refused now.
    let why = match (state, fault) {
        (_, Fault::None) => String::new(),
        (JobState::Idle, f) => format!(" (robot not ready: {})", f.describe()),
        (_, f) => format!(" ({})", f.describe()),
    };
    let why = match s.limit_words() {
        Some(w) => format!("{why}: {w}"),
        None => why,
    };
    println!(
        "herbd: {state:?}, job {}, {}/{} placed, {} cycles, {} deadline misses, fault {fault:?}{why}",
        s.job_id, s.objects_done, s.objects_total, s.cycles, s.deadline_misses,
    );
    Ok(true)
}

/// `herbctl watch`: redraws [`herb_daemon::watch::WatchView`] every `period` seconds.
fn watch(
    cli: &Cli,
    catalog: &Catalog,
    period: f64,
    duration: Option<f64>,
    plain: bool,
) -> Result<bool, String> {
    use herb_daemon::watch::{WatchView, wall_label};
    if !(period.is_finite() && (0.02..=60.0).contains(&period)) {
        return Err(format!("--period {period} outside 0.02..=60 s"));
    }
    let client = connect(cli)?;
    let outcomes = client
        .bus()
        .subscriber::<SimOutcome>(&client.services().sim_outcome())
        .map_err(|e| e.to_string())?;
    let t0 = Instant::now();
    let label = |t: u32| name(catalog, t);
    let mut view = WatchView::new(&cli.prefix);
    let mut next_draw = 0.0;
    loop {
        let t = t0.elapsed().as_secs_f64();
        for s in client.statuses() {
            view.status(&s, t, &wall_label(std::time::SystemTime::now()), &label);
        }
        while let Ok(Some(o)) = outcomes.receive() {
            view.outcome(o.payload());
        }
        let ending = duration.is_some_and(|d| t >= d);
        if t >= next_draw || ending {
            next_draw = t + period;
            let text = view.render(t, &label);
            if plain {
                println!(
                    "--- herbctl watch, {} UTC",
                    wall_label(std::time::SystemTime::now())
                );
                print!("{text}");
            } else {
                // Home, clear, draw.
                println!("\x1b[H\x1b[2J{text}(Ctrl-C quits)");
            }
            use std::io::Write;
            let _ = std::io::stdout().flush();
        }
        if ending {
            return Ok(true);
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// herbctl's client of the herbd under the prefix of `cli`.
fn connect(cli: &Cli) -> Result<Client, String> {
    Client::connect_as(&cli.prefix, "herbctl").map_err(|e| e.to_string())
}

/// `herbctl reset`: asks the loopback to empty its box, unless herbd reports a running job, and
/// waits for the heightmap of the empty box.
fn reset(cli: &Cli, timeout: f64) -> Result<bool, String> {
    let client = connect(cli)?;
    let frames = client
        .bus()
        .subscriber::<HeightmapFrame>(&client.services().heightmap())
        .map_err(|e| e.to_string())?;
    let request = client
        .bus()
        .publisher::<SimReset>(&client.services().sim_reset())
        .map_err(|e| e.to_string())?;
    // A heartbeat within two periods says whether a job runs (no herbd: nothing runs).
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_millis(250) {
        for s in client.statuses() {
            if s.event == StatusEvent::Heartbeat as u32 && s.job_id != 0 {
                return Err(format!("job {} is running: the box is not reset", s.job_id));
            }
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let asked = monotonic_ns();
    request
        .send_copy(SimReset {
            header: Header::now(1),
        })
        .map_err(|e| format!("cannot send the reset: {e:?}"))?;
    let deadline = Instant::now() + Duration::from_secs_f64(timeout);
    while Instant::now() < deadline {
        while let Ok(Some(f)) = frames.receive() {
            let f = f.payload();
            if f.validate_meta().is_ok() && f.header.stamp_ns >= asked && f.objects == 0 {
                println!("box emptied");
                return Ok(true);
            }
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    Err(format!(
        "no heightmap of an empty box within {timeout} s: is the loopback running, holding nothing?"
    ))
}

/// `herbctl cancel`: cancels job `job` (or the running one) and follows it to its end.
fn cancel(cli: &Cli, job: Option<u64>, timeout: f64) -> Result<bool, String> {
    let deadline = Duration::try_from_secs_f64(timeout)
        .ok()
        .and_then(|d| Instant::now().checked_add(d))
        .ok_or_else(|| format!("--timeout {timeout}: give a number of seconds"))?;
    let client = connect(cli)?;
    // The running job and what it does, from the next heartbeat (10 Hz).
    let heartbeat = client.status(Duration::from_secs(1));
    let job_id = match (job, &heartbeat) {
        (Some(j), _) => j,
        (None, Err(StatusError::NoHeartbeat)) => {
            return Err("no heartbeat from herbd (is it running?)".into());
        }
        (None, Ok(s)) if s.job_id == 0 => return Err("no job is running".into()),
        (None, Ok(s)) => s.job_id,
    };
    let before = heartbeat.ok().filter(|s| s.job_id == job_id).map(|s| {
        (
            JobState::from_code(s.state).unwrap_or(JobState::Idle),
            Fault::from_code(s.fault).unwrap_or(Fault::None),
        )
    });
    client.cancel(job_id).map_err(|e| e.to_string())?;
    println!("cancelling job {job_id}");
    // Followed without waiting for a lost herbd to come back.
    let mut watch = client.watch(job_id, deadline, Duration::ZERO);
    let (mut braked, mut stopped_by) = (false, None);
    loop {
        let s = match watch.next_event() {
            Ok(Some(JobEvent::Status(s))) => s,
            Ok(Some(JobEvent::Lost { .. } | JobEvent::Back)) => continue,
            Err(WatchError::DaemonLost { .. } | WatchError::CameBackWithoutJob { .. }) => {
                return Err("daemon lost: no status from herbd".into());
            }
            Ok(None) | Err(WatchError::TimedOut { .. }) => {
                return Err(format!("job {job_id} not cancelled within {timeout} s"));
            }
        };
        let fault = Fault::from_code(s.fault).unwrap_or(Fault::None);
        match StatusEvent::from_code(s.event) {
            Some(StatusEvent::Fault) => stopped_by = Some(fault),
            Some(StatusEvent::Braked) => {
                braked = true;
                println!("{}", words::stopped(stopped_by));
            }
            Some(StatusEvent::JobCancelled) => {
                println!(
                    "job {job_id} cancelled: {}; {}",
                    words::cancel_outcome(before, braked, fault),
                    words::placed_count(s.objects_done, s.objects_total, 0)
                );
                return Ok(true);
            }
            Some(e @ (StatusEvent::JobDone | StatusEvent::JobFailed)) => {
                println!("job {job_id} ended before the cancel took effect: {e:?}");
                return Ok(false);
            }
            Some(StatusEvent::Shutdown) => return Err("herbd shut down".into()),
            _ => {}
        }
    }
}

/// `herbctl replay`.
fn replay(
    cli: &Cli,
    path: &std::path::Path,
    force: bool,
    events: Option<&std::path::Path>,
) -> ExitCode {
    let run = || -> Result<(Outcome, Replayed, Log), String> {
        let log = Log::read(path).map_err(|e| e.to_string())?;
        let opts = ReplayOptions {
            boxed: cli.boxed.clone(),
            force,
            explain: None,
        };
        let (o, r) = herb_daemon::replay::replay(&log, &opts).map_err(|e| e.to_string())?;
        Ok((o, r, log))
    };
    match run() {
        Err(e) => {
            eprintln!("herbctl: error: {e}");
            ExitCode::from(2)
        }
        Ok((outcome, r, log)) => {
            println!(
                "{} (segment {}), recorded on {}",
                log.header.herbd, log.header.segment, log.header.cpu
            );
            if let Some(p) = events {
                match write_events(p, &r) {
                    Ok(n) => println!("{n} events written to {}", p.display()),
                    Err(e) => {
                        eprintln!("herbctl: error: {}: {e}", p.display());
                        return ExitCode::from(2);
                    }
                }
            }
            let done = format!(
                "{} cycles, {} joint commands, {} planner responses, {} decisions",
                r.cycles, r.joint_commands, r.responses, r.decisions
            );
            match outcome {
                Outcome::Reproduced => {
                    println!("reproduced bit for bit: {done}");
                    ExitCode::SUCCESS
                }
                Outcome::Incomplete(why) => {
                    println!("log incomplete ({why}); reproduced before that: {done}");
                    ExitCode::from(3)
                }
                Outcome::Diverged { cycle, at_s, what } => {
                    println!("DIVERGED at cycle {cycle} ({at_s:.3} s into the segment): {what}");
                    println!("reproduced before that: {done}");
                    ExitCode::from(1)
                }
            }
        }
    }
}

/// The replay's statuses (heartbeats left out) and decision heightmaps as JSON lines, in time
/// order; the number of lines.
fn write_events(path: &std::path::Path, r: &Replayed) -> std::io::Result<usize> {
    use std::io::Write;
    let mut w = std::io::BufWriter::new(std::fs::File::create(path)?);
    let mut n = 0;
    for (_, s) in &r.statuses {
        let line = serde_json::json!({
            "status": {
                "stamp_ns": s.header.stamp_ns,
                "job_id": s.job_id,
                "event": s.event,
                "state": s.state,
                "fault": s.fault,
                "objects_total": s.objects_total,
                "objects_done": s.objects_done,
                "object_index": s.object_index,
                "object_type": s.object_type,
                "decision_wait_ms": s.decision_wait_ms,
                "pose": s.pose,
                "decision_ns": s.decision_ns,
            }
        });
        writeln!(w, "{line}")?;
        n += 1;
        // The heightmap the object was decided on, at the time of its decision.
        if s.event == StatusEvent::Decided as u32
            && let Some((_, f)) = r.decision_frames.iter().find(|(i, _)| *i == s.object_index)
        {
            let line = serde_json::json!({
                "heightmap": {
                    "stamp_ns": s.header.stamp_ns,
                    "nx": f.nx,
                    "ny": f.ny,
                    "cell_m": f.cell_m,
                    "cells": f.cells(),
                }
            });
            writeln!(w, "{line}")?;
            n += 1;
        }
    }
    w.flush()?;
    Ok(n)
}

fn write_png(f: &HeightmapFrame, path: &std::path::Path) -> Result<(), String> {
    let spec = GridSpec::for_box(f.cell_m).map_err(|e| e.to_string())?;
    let hm = Heightmap::from_data(spec, f.cells().to_vec()).map_err(|e| e.to_string())?;
    if let Some(d) = path.parent() {
        let _ = std::fs::create_dir_all(d);
    }
    herb_sim::image::write_heightmap_png(path, &hm, 0.3, 4).map_err(|e| e.to_string())
}

/// `herbctl catalog`: the catalog (meshes from BoxED when present) as one JSON document.
fn catalog_json(cli: &Cli) -> Result<bool, String> {
    use herb_sim::frames::{BOX_HALF_X, BOX_HALF_Y, BOX_HEIGHT, BOX_WALL_THICKNESS};
    let root = paths::boxed_root(cli.boxed.as_deref());
    let meshes = paths::mesh_source(None, root.as_deref());
    let catalog = Catalog::builtin(&meshes).map_err(|e| format!("catalog: {e}"))?;
    let objects: Vec<serde_json::Value> = catalog
        .types()
        .map(|t| {
            let (spec, shape) = (catalog.spec(t), catalog.shape(t));
            serde_json::json!({
                "index": t.0,
                "id": spec.id,
                "name": spec.name,
                "vertices": shape.vertices.iter().map(|v| [v.x, v.y, v.z]).collect::<Vec<_>>(),
                "triangles": shape.triangles,
            })
        })
        .collect();
    let doc = serde_json::json!({
        "format": 1,
        "box": {
            "half_x": BOX_HALF_X,
            "half_y": BOX_HALF_Y,
            "height": BOX_HEIGHT,
            "wall": BOX_WALL_THICKNESS,
        },
        "objects": objects,
    });
    use std::io::Write;
    writeln!(std::io::stdout(), "{doc}").map_err(|e| format!("stdout: {e}"))?;
    Ok(true)
}

/// `herbctl explain`.
fn explain(
    cli: &Cli,
    catalog: &Catalog,
    path: &std::path::Path,
    object: u32,
    out: &std::path::Path,
    force: bool,
) -> Result<bool, String> {
    if object == 0 {
        return Err("--object counts from 1".into());
    }
    let index = object - 1;
    let log = Log::read(path).map_err(|e| e.to_string())?;
    let opts = ReplayOptions {
        boxed: cli.boxed.clone(),
        force,
        explain: Some(index),
    };
    let (outcome, r) = herb_daemon::replay::replay(&log, &opts).map_err(|e| e.to_string())?;
    let cfg: herb_daemon::config::Config =
        toml::from_str(&log.header.config_toml).map_err(|e| e.to_string())?;
    let e = r.explained.ok_or_else(|| {
        format!(
            "object {object} was never decided in this log (it holds {} decisions)",
            r.decisions
        )
    })?;
    let f = &e.frame;
    println!(
        "object {object}: {} (decision request {})",
        name(catalog, e.object as u32),
        e.request
    );
    println!(
        "heightmap: stamp {} ns, {}x{} cells of {:.4} m, {} objects in the box{}",
        f.header.stamp_ns,
        f.nx,
        f.ny,
        f.cell_m,
        f.objects,
        if f.objects == 0 { " (or unknown)" } else { "" }
    );
    println!("method: {}", e.method);
    if let Some(rep) = &e.search {
        let allowed = e.response.allowed;
        println!(
            "search: {} feasible candidates on the lattice; the budget allowed {allowed} rollout{} (replayed as that count){}",
            rep.candidates,
            if allowed == 1 { "" } else { "s" },
            if allowed == 0 {
                ": none finished, so the prior's first (lattice BLBF's) was taken"
            } else {
                ""
            }
        );
        for (c, o) in &rep.finished {
            let p = &o.placement;
            println!(
                "  candidate {:>2} (x {:+.3} y {:+.3} yaw {:+.2}): return {:+.4}, {} objects placed inside{}{}",
                c + 1,
                p.x,
                p.y,
                p.theta(),
                o.ret,
                o.packed,
                if o.success {
                    ", all"
                } else {
                    ", then a failure"
                },
                if Some(*c) == rep.chosen {
                    "  <- chosen"
                } else {
                    ""
                }
            );
        }
    }
    match e.response.outcome {
        Ok(p) => println!(
            "placement: x {:+.4} m, y {:+.4} m, yaw {:+.3} rad; z {:.4} m (resting height from the heightmap + {:.3} m clearance)",
            p[0], p[1], p[3], p[2], cfg.models.clearance_m
        ),
        Err(why) => println!("no placement: {why:?}"),
    }
    let mine: Vec<&Status> = r
        .statuses
        .iter()
        .map(|(_, s)| s)
        .filter(|s| s.object_index == index || s.event == StatusEvent::JobDone as u32)
        .collect();
    for s in &mine {
        let ev = StatusEvent::from_code(s.event);
        let fault = Fault::from_code(s.fault).unwrap_or(Fault::None);
        match ev {
            Some(StatusEvent::Decided) => println!(
                "decided in {:.3} ms (as measured in the run)",
                s.decision_ns as f64 / 1e6
            ),
            Some(StatusEvent::Placed) => println!(
                "outcome: released at x {:+.4} y {:+.4} z {:.4} m, yaw {:+.3} rad; {} of {} placed",
                s.pose[0], s.pose[1], s.pose[2], s.pose[3], s.objects_done, s.objects_total
            ),
            Some(StatusEvent::Fault) if s.object_index == index => {
                println!("fault while handling it: {fault:?}")
            }
            Some(StatusEvent::JobFailed) if s.object_index == index => {
                println!("outcome: the job failed on it ({fault:?})")
            }
            Some(StatusEvent::JobCancelled) if s.object_index == index => {
                println!("outcome: the job was cancelled while handling it")
            }
            _ => {}
        }
    }
    let before = out.join(format!("object-{object}-before.png"));
    write_png(f, &before)?;
    println!("heightmap it was decided on: {}", before.display());
    match r.decision_frames.iter().find(|(i, _)| *i > index) {
        Some((_, next)) => {
            let after = out.join(format!("object-{object}-after.png"));
            write_png(next, &after)?;
            println!(
                "the next decision's heightmap (after it settled): {}",
                after.display()
            );
        }
        None => println!("no later heightmap in this log (it was the last decision)"),
    }
    if let Outcome::Diverged { cycle, what, .. } = outcome {
        println!("warning: the replay diverged at cycle {cycle}: {what}");
    }
    Ok(true)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let catalog = match Catalog::builtin(&paths::MeshSource::None("herbctl needs no meshes".into()))
    {
        Ok(c) => c,
        Err(e) => {
            eprintln!("herbctl: catalog: {e}");
            return ExitCode::from(2);
        }
    };
    let r = match &cli.cmd {
        Cmd::Pack {
            session,
            objects,
            picture,
            timeout,
            json,
            operator,
            operator_wait,
            reconnect,
            detach,
        } => {
            let args = pack::PackArgs {
                session,
                ids: objects,
                picture,
                timeout: *timeout,
                json: *json,
                operator: *operator,
                operator_wait: *operator_wait,
                reconnect: *reconnect,
                detach: *detach,
            };
            return match pack::pack(&cli, &catalog, &args) {
                Ok(code) => ExitCode::from(code),
                Err(e) => {
                    eprintln!("herbctl: error: {e}");
                    ExitCode::from(2)
                }
            };
        }
        Cmd::Status { timeout } => status(&cli, *timeout),
        Cmd::Catalog => catalog_json(&cli),
        Cmd::CalibrateCell {
            corners,
            tip_offset,
        } => {
            let stdin = std::io::stdin();
            herb_daemon::cellcal::run(
                &cli.prefix,
                *corners,
                *tip_offset,
                &mut stdin.lock(),
                &mut std::io::stderr(),
            )
            .map_err(|e| e.to_string())
            .map(|cell| {
                println!("[cell]\n{cell}");
                true
            })
        }
        Cmd::Watch {
            period,
            duration,
            plain,
        } => watch(&cli, &catalog, *period, *duration, *plain),
        Cmd::Reset { timeout } => reset(&cli, *timeout),
        Cmd::Cancel { job, timeout } => cancel(&cli, *job, *timeout),
        Cmd::Replay { log, force, events } => {
            return replay(&cli, log, *force, events.as_deref());
        }
        Cmd::Explain {
            log,
            object,
            out,
            force,
        } => explain(&cli, &catalog, log, *object, out, *force),
    };
    match r {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("herbctl: error: {e}");
            ExitCode::from(2)
        }
    }
}
