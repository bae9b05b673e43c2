//! `herbctl`: submit a pack job to `herbd`, follow it live, print per-object results and a
//! summary; cancel a running job; empty the simulated box; print the daemon's state.

use clap::{Parser, Subcommand};
use herb_client::{Client, JobEvent, PackOptions, StatusError, SubmitError, WatchError};
use herb_daemon::record::Log;
use herb_daemon::replay::{Outcome, ReplayOptions, Replayed};
use herb_ipc::{
    Fault, Header, HeightmapFrame, JobState, RejectReason, Services, SimOutcome, SimReset, Status,
    StatusEvent, monotonic_ns,
};
use herb_picture::{PictureObject, write_pack_picture};
use herb_sim::{Catalog, GridSpec, Heightmap, TypeIdx, boxed, paths};
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
    /// Submit a job and follow it to the end.
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
        /// Give up after this many seconds.
        #[arg(long, default_value_t = 900.0)]
        timeout: f64,
        /// Print the summary as one JSON line.
        #[arg(long)]
        json: bool,
        /// A real cell fed by hand: say which object to put at the pick station, and when
        /// (as each object is decided, and again after a missed grasp).
        #[arg(long)]
        operator: bool,
        /// When herbd goes silent, wait this long (s) for it to come back with the job (a
        /// restarted herbd takes an unfinished job up from its journal); 0 gives up at once.
        #[arg(long, default_value_t = 60.0)]
        reconnect: f64,
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

fn objects_of(
    cli: &Cli,
    session: &Option<String>,
    ids: &[String],
    catalog: &Catalog,
) -> Result<(Vec<u16>, String), String> {
    if let Some(name) = session {
        let root = paths::boxed_root(cli.boxed.as_deref())
            .ok_or("no BoxED folder found (set --boxed or HERB_BOXED)")?;
        let s = boxed::load_session(&root, name, catalog).map_err(|e| e.to_string())?;
        let ep = s.episode(catalog);
        return Ok((
            ep.objects.iter().map(|t| t.0).collect(),
            format!("session {name}"),
        ));
    }
    if ids.is_empty() {
        return Err("give --session NAME or --objects ID,ID,...".into());
    }
    let v = ids
        .iter()
        .map(|id| {
            catalog
                .by_id(id.trim())
                .map(|t| t.0)
                .map_err(|e| e.to_string())
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok((v, format!("{} objects", ids.len())))
}

fn name(catalog: &Catalog, t: u32) -> String {
    if (t as usize) < catalog.len() {
        let s = catalog.spec(TypeIdx(t as u16));
        format!("{} {}", s.id, s.name)
    } else {
        "-".into()
    }
}

fn pct(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

#[allow(clippy::too_many_arguments)]
fn pack(
    cli: &Cli,
    catalog: &Catalog,
    session: &Option<String>,
    ids: &[String],
    picture: &Option<PathBuf>,
    timeout: f64,
    (json, operator, reconnect): (bool, bool, f64),
) -> Result<bool, String> {
    if !(reconnect.is_finite() && (0.0..=3600.0).contains(&reconnect)) {
        return Err(format!("--reconnect {reconnect} outside 0..=3600 s"));
    }
    let (objects, what) = objects_of(cli, session, ids, catalog)?;
    let client = connect(cli)?;
    let frames = client
        .bus()
        .subscriber::<HeightmapFrame>(&client.services().heightmap())
        .map_err(|e| e.to_string())?;
    let outcomes = client
        .bus()
        .subscriber::<SimOutcome>(&client.services().sim_outcome())
        .map_err(|e| e.to_string())?;
    let job_id = herb_client::new_job_id();
    if what.ends_with(" objects") {
        eprintln!("herbctl: submitting job {job_id}: {what}");
    } else {
        eprintln!(
            "herbctl: submitting job {job_id}: {what}, {} objects",
            objects.len()
        );
    }

    // Submit, waiting for the daemon to come up and the robot to be ready (said at once, and
    // again when the reason changes).
    let options = PackOptions {
        job_id: Some(job_id),
        timeout: Duration::from_secs_f64(timeout),
        reconnect: Duration::from_secs_f64(reconnect),
    };
    let mut not_ready: Option<Fault> = None;
    let submitted = client.pack(&objects, &options, |why| {
        if not_ready != Some(why) {
            println!("robot not ready: {}; waiting", why.describe());
            not_ready = Some(why);
        }
    });
    let mut watch = match submitted {
        Ok(watch) => {
            eprintln!("herbctl: accepted");
            watch
        }
        Err(SubmitError::NotReady(f)) => {
            return Err(format!(
                "robot not ready: {} (gave up after {timeout} s)",
                f.describe()
            ));
        }
        Err(SubmitError::Rejected {
            reason: RejectReason::Holding,
            detail,
        }) => {
            let what = if detail == herb_ipc::NO_OBJECT {
                "an object".to_string()
            } else {
                name(catalog, detail)
            };
            return Err(format!(
                "rejected: the gripper holds {what}; take it out (the loopback: herbctl reset) and submit again"
            ));
        }
        Err(e) => return Err(e.to_string()),
    };

    let job_t0 = std::time::Instant::now();
    let mut decision_ms = Vec::new();
    let mut faults = Vec::new();
    let mut last: Option<Status> = None;
    let mut placed = 0u32;
    let mut skipped = 0u32;
    let mut total = objects.len() as u32;
    let mut ok = None;
    let mut latest_frame: Option<Heightmap> = None;
    let mut last_outcome: Option<SimOutcome> = None;
    let keep_frame = |f: &HeightmapFrame, into: &mut Option<Heightmap>| {
        if f.validate().is_ok()
            && let Ok(spec) = GridSpec::for_box(f.cell_m)
            && (spec.nx, spec.ny) == (f.nx as usize, f.ny as usize)
        {
            *into = Heightmap::from_data(spec, f.cells().to_vec()).ok();
        }
    };
    loop {
        let s = match watch.poll() {
            Ok(Some(JobEvent::Status(s))) => s,
            Ok(Some(JobEvent::Lost { silent_for })) => {
                println!(
                    "herbd lost (no status for {:.1} s): waiting up to {reconnect} s for it to come back with job {job_id} (its journal resumes the job)",
                    silent_for.as_secs_f64()
                );
                continue;
            }
            Ok(Some(JobEvent::Back)) => {
                println!("herbd back: job {job_id} goes on");
                continue;
            }
            Ok(None) => {
                while let Ok(Some(o)) = outcomes.receive() {
                    if o.payload().validate().is_ok() && o.payload().job_id == job_id {
                        last_outcome = Some(*o.payload());
                    }
                }
                while let Ok(Some(f)) = frames.receive() {
                    keep_frame(f.payload(), &mut latest_frame);
                }
                if watch.is_finished() {
                    break;
                }
                std::thread::sleep(Duration::from_millis(5));
                continue;
            }
            Err(WatchError::TimedOut { .. }) => {
                return Err(format!(
                    "timed out after {timeout} s; {placed}/{total} placed"
                ));
            }
            Err(WatchError::CameBackWithoutJob { .. }) => {
                return Err(format!(
                    "herbd came back without job {job_id} (no job journal, or the job was abandoned); {placed}/{total} placed"
                ));
            }
            Err(WatchError::DaemonLost { silent_for, .. }) => {
                let at = last.map_or(String::from("no status yet"), |s| {
                    format!(
                        "object {}/{total} ({}), state {:?}",
                        s.object_index + 1,
                        name(catalog, s.object_type),
                        JobState::from_code(s.state).unwrap_or(JobState::Idle)
                    )
                });
                return Err(format!(
                    "daemon lost: no status from herbd for {:.1} s (it heartbeats at 10 Hz); job {job_id}: {placed}/{total} placed, last known {at}",
                    silent_for.as_secs_f64()
                ));
            }
        };
        last = Some(s);
        total = s.objects_total;
        let fault = Fault::from_code(s.fault).unwrap_or(Fault::None);
        match StatusEvent::from_code(s.event) {
            Some(StatusEvent::Decided) => {
                if operator {
                    println!(
                        "operator: put {} at the pick station",
                        name(catalog, s.object_type)
                    );
                }
                decision_ms.push(s.decision_ns as f64 / 1e6);
                println!(
                    "object {:>2}/{total}: {:<28} x {:+.3} y {:+.3} z {:.3} m yaw {:+.2} rad  decision {:.3} ms",
                    s.object_index + 1,
                    name(catalog, s.object_type),
                    s.pose[0],
                    s.pose[1],
                    s.pose[2],
                    s.pose[3],
                    s.decision_ns as f64 / 1e6
                );
            }
            Some(StatusEvent::Placed) => {
                placed = s.objects_done;
                println!("placed {placed}/{total}");
            }
            Some(StatusEvent::Fault) => {
                faults.push(format!("{fault:?}"));
                println!("FAULT {fault:?} ({}): halting", fault.describe());
                if operator && fault == Fault::MissedGrasp {
                    println!(
                        "operator: put {} at the pick station (the pick is tried again)",
                        name(catalog, s.object_type)
                    );
                }
            }
            Some(StatusEvent::Skipped) => {
                skipped += 1;
                println!(
                    "skipped object {}/{total} ({}): {}",
                    s.object_index + 1,
                    name(catalog, s.object_type),
                    fault.describe()
                );
            }
            Some(StatusEvent::Braked) => println!("braked: standing still"),
            Some(StatusEvent::Resumed) => println!("resumed"),
            Some(StatusEvent::JobDone) => ok = Some(true),
            Some(StatusEvent::JobFailed) => {
                println!("job failed: {fault:?}");
                ok = Some(false)
            }
            Some(StatusEvent::JobCancelled) => {
                println!("job cancelled");
                ok = Some(false)
            }
            Some(StatusEvent::Shutdown) => {
                println!("herbd shut down");
                ok = Some(false)
            }
            _ => {}
        }
    }
    // The last release's settle: wait briefly for its heightmap and outcome.
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_millis(1500) {
        while let Ok(Some(f)) = frames.receive() {
            keep_frame(f.payload(), &mut latest_frame);
        }
        while let Ok(Some(o)) = outcomes.receive() {
            if o.payload().validate().is_ok() && o.payload().job_id == job_id {
                last_outcome = Some(*o.payload());
            }
        }
        if last_outcome.is_some_and(|o| o.objects >= placed) {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let s = last.unwrap_or_else(|| unreachable!("a final status was received"));
    let state = JobState::from_code(s.state).unwrap_or(JobState::Idle);
    let fault = Fault::from_code(s.fault).unwrap_or(Fault::None);
    let verdict = verdict(
        ok == Some(true),
        state,
        fault,
        placed,
        total,
        last_outcome.as_ref(),
        catalog,
    );
    // Per object: inside or where it left the success volume (simulated cells only).
    let listed: Vec<(String, herb_ipc::SimObject)> = last_outcome
        .as_ref()
        .map(|o| {
            let earlier = o.objects.saturating_sub(placed) as usize;
            o.objects_listed()
                .iter()
                .enumerate()
                .map(|(i, so)| {
                    let who = if i < earlier {
                        format!("earlier {}", i + 1)
                    } else {
                        format!("{}", i - earlier + 1)
                    };
                    (who, *so)
                })
                .collect()
        })
        .unwrap_or_default();
    if !json {
        for (who, o) in &listed {
            let where_ = match herb_daemon::watch::crossing(o) {
                None => "inside".to_string(),
                Some(c) => format!(
                    "OUTSIDE: {c} (x {:+.3}..{:+.3}, y {:+.3}..{:+.3}, z {:.3}..{:.3} m)",
                    o.lo[0], o.hi[0], o.lo[1], o.hi[1], o.lo[2], o.hi[2]
                ),
            };
            println!(
                "  object {who:<3} {:<28} {where_}",
                name(catalog, o.object_type)
            );
        }
    }
    if let (Some(p), Some(hm)) = (picture, &latest_frame) {
        let objects: Vec<PictureObject> = listed
            .iter()
            .map(|(who, o)| PictureObject {
                label: format!("{who} {}", id_of(catalog, o.object_type)),
                lo: o.lo,
                hi: o.hi,
                outside: (o.bound != 0).then(|| (o.bound_name().to_string(), o.over_m)),
            })
            .collect();
        // The job's result stands whether or not the picture can be drawn.
        match write_pack_picture(p, &verdict, hm, &objects) {
            Ok(()) => println!("picture of the final pack: {}", p.display()),
            Err(e) => eprintln!("herbctl: the picture was not written: {e}"),
        }
    }
    let mut d = decision_ms.clone();
    let job_s = job_t0.elapsed().as_secs_f64();
    let wait_s = s.decision_wait_ms as f64 / 1e3;
    let summary = serde_json::json!({
        "job_id": job_id,
        "ok": ok == Some(true),
        "state": format!("{:?}", JobState::from_code(s.state).unwrap_or(JobState::Idle)),
        "placed": placed,
        "skipped": skipped,
        "objects": total,
        "decisions": decision_ms.len(),
        "decision_ms_p50": pct(&mut d, 0.5),
        "decision_ms_max": pct(&mut d, 1.0),
        "job_s": job_s,
        "decision_wait_s": wait_s,
        "decision_wait_pct": 100.0 * wait_s / job_s.max(1e-9),
        "faults": faults,
        "verdict": verdict,
        "loop_cycles": s.cycles,
        "deadline_misses": s.deadline_misses,
        "rejected_inputs": s.rejected_inputs,
        "max_cycle_us": s.max_cycle_ns as f64 / 1000.0,
        "sim": last_outcome.map(|o| serde_json::json!({
            "objects_in_box": o.objects,
            "all_inside": o.all_inside == 1,
            "compactness": o.compactness,
            "joint_commands": o.commands.received,
            "joint_commands_rejected": o.commands.rejected,
            "max_limit_excess_rad": o.commands.max_limit_excess_rad,
            "objects": listed.iter().map(|(who, so)| serde_json::json!({
                "n": who,
                "id": id_of(catalog, so.object_type),
                "inside": so.bound == 0,
                "bound": so.bound_name(),
                "over_m": so.over_m,
            })).collect::<Vec<_>>(),
        })),
    });
    if json {
        println!("{summary}");
    } else {
        println!(
            "statistics: decision p50 {:.3} ms (max {:.3}), held waiting for decisions {:.2} s of {:.1} s ({:.1} %), loop {} cycles, {} deadline misses, worst cycle {:.1} us, faults {:?}",
            pct(&mut d, 0.5),
            pct(&mut d, 1.0),
            wait_s,
            job_s,
            100.0 * wait_s / job_s.max(1e-9),
            s.cycles,
            s.deadline_misses,
            s.max_cycle_ns as f64 / 1000.0,
            faults
        );
        if let Some(o) = last_outcome {
            println!(
                "simulation: {} objects in the box, compactness {:.3}",
                o.objects, o.compactness
            );
        }
        println!("verdict: {verdict}");
    }
    Ok(ok == Some(true))
}

/// The job's outcome in one line: SUCCESS only when the job is done and every object ended
/// inside the success volume; else what went wrong first.
fn verdict(
    done: bool,
    state: JobState,
    fault: Fault,
    placed: u32,
    total: u32,
    outcome: Option<&SimOutcome>,
    catalog: &Catalog,
) -> String {
    let outside = outcome.map_or_else(Vec::new, |o| {
        herb_daemon::watch::outside_objects(o, &|t| id_of(catalog, t))
    });
    let outside_text = if outside.is_empty() {
        String::new()
    } else {
        format!(
            "; {} outside the success volume: {}",
            outside.len(),
            outside.join(", ")
        )
    };
    match (done, outcome) {
        (true, Some(_)) if outside.is_empty() => {
            format!("SUCCESS: {placed}/{total} placed, every object inside the success volume")
        }
        (true, Some(_)) => format!("FAILED: {placed}/{total} placed{outside_text}"),
        (true, None) => format!(
            "DONE: {placed}/{total} placed (no simulated outcome: inside the box not checked)"
        ),
        (false, _) => {
            format!("FAILED: job {state:?} ({fault:?}) with {placed}/{total} placed{outside_text}")
        }
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
    let client = connect(cli)?;
    let deadline = Instant::now() + Duration::from_secs_f64(timeout);
    let job_id = match job {
        Some(j) => j,
        // The running job, from the next heartbeat (10 Hz).
        None => match client.current_job(Duration::from_secs(1)) {
            Err(StatusError::NoHeartbeat) => {
                return Err("no heartbeat from herbd (is it running?)".into());
            }
            Ok(None) => return Err("no job is running".into()),
            Ok(Some(j)) => j,
        },
    };
    client.cancel(job_id).map_err(|e| e.to_string())?;
    println!("cancelling job {job_id}");
    // Followed without waiting for a lost herbd to come back.
    let mut watch = client.watch(job_id, deadline, Duration::ZERO);
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
            Some(StatusEvent::Braked) => println!("braked: standing still"),
            Some(StatusEvent::JobCancelled) => {
                let how = if fault == Fault::None {
                    String::new()
                } else {
                    format!(" (last fault {fault:?})")
                };
                println!(
                    "job {job_id} cancelled{how}: {}/{} placed",
                    s.objects_done, s.objects_total
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
            reconnect,
        } => pack(
            &cli,
            &catalog,
            session,
            objects,
            picture,
            *timeout,
            (*json, *operator, *reconnect),
        ),
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
