//! `herbctl`: submit a pack job to `herbd`, follow it live, print per-object results and a
//! summary (Ctrl-C cancels the job); cancel a running job; empty the simulated box; print the
//! daemon's state.

mod interrupt;
mod operator;
mod pack;
mod words;

use clap::{Parser, Subcommand};
use herb_client::{Client, JobEvent, StatusError, WatchError};
use herb_core::{Catalog, TypeIdx, paths};
use herb_ipc::{
    Fault, Header, HeightmapFrame, JobState, Services, SimOutcome, SimReset, StatusEvent,
    monotonic_ns,
};
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
        #[arg(long, default_value_t = 900.0, value_parser = seconds, allow_negative_numbers = true)]
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
        #[arg(long, requires = "operator", value_parser = seconds, allow_negative_numbers = true)]
        operator_wait: Option<f64>,
        /// When herbd goes silent, wait this long (s) for it to come back with the job (a
        /// restarted herbd takes an unfinished job up from its journal); 0 gives up at once.
        #[arg(long, default_value_t = 60.0, value_parser = seconds, allow_negative_numbers = true)]
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
        #[arg(long, default_value_t = 5.0, value_parser = seconds, allow_negative_numbers = true)]
        timeout: f64,
    },
    /// Cancel the running job: the arm brakes, retreats straight up and the job ends
    /// `JobCancelled` (a job stopped on a fault ends where it stands). Waits for that end.
    Cancel {
        /// The job to cancel (default: the running one, from herbd's heartbeat).
        #[arg(long)]
        job: Option<u64>,
        /// Give up after this many seconds.
        #[arg(long, default_value_t = 30.0, value_parser = seconds, allow_negative_numbers = true)]
        timeout: f64,
    },
    /// A live view of herbd: job progress, the last decision, loop statistics, faults, the
    /// simulated box, recent events. Ctrl-C quits.
    Watch {
        /// Seconds between redraws.
        #[arg(long, default_value_t = 0.25, value_parser = seconds, allow_negative_numbers = true)]
        period: f64,
        /// Quit after this many seconds (default: run until Ctrl-C).
        #[arg(long, value_parser = seconds, allow_negative_numbers = true)]
        duration: Option<f64>,
        /// Print each view below the previous one instead of redrawing the screen.
        #[arg(long)]
        plain: bool,
    },
    /// Print the object catalog as JSON for viewers (`python -m herb_client.view`): the box
    /// (half lengths, height, wall thickness; m) and each object type's id, name and convex
    /// hull (vertices in its canonical frame, m, and outward triangles), from the BoxED meshes
    /// (`--boxed`) when present, else the primitives.
    Catalog,
    /// Print the daemon's next heartbeat.
    Status {
        /// Give up after this many seconds.
        #[arg(long, default_value_t = 5.0, value_parser = seconds, allow_negative_numbers = true)]
        timeout: f64,
    },
}

/// A duration given on the command line: a finite number of seconds, at least 0 and at most a
/// year (so it always converts to a [`Duration`]). Negative numbers reach this parser (rather
/// than being taken for flags) so that they are refused by the option's name.
fn seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| "give a number of seconds".to_string())?;
    if v.is_finite() && (0.0..=365.0 * 86_400.0).contains(&v) {
        Ok(v)
    } else {
        Err("give a number of seconds from 0 to a year".into())
    }
}

/// Type `t`'s catalog id and name (`-` if none).
fn name(catalog: &Catalog, t: u32) -> String {
    catalog.label(t)
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

/// `herbctl watch`: redraws [`herb_client::view::WatchView`] every `period` seconds.
fn watch(
    cli: &Cli,
    catalog: &Catalog,
    period: f64,
    duration: Option<f64>,
    plain: bool,
) -> Result<bool, String> {
    use herb_client::view::{WatchView, wall_label};
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

/// `herbctl catalog`: the catalog (meshes from BoxED when present) as one JSON document.
fn catalog_json(cli: &Cli) -> Result<bool, String> {
    use herb_core::frames::{BOX_HALF_X, BOX_HALF_Y, BOX_HEIGHT, BOX_WALL_THICKNESS};
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

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        // --help and --version print to stdout and exit 0, as clap does.
        Err(e) if !e.use_stderr() => e.exit(),
        Err(e) => {
            // clap's message names the option and the value ("error: invalid value ...").
            eprint!("herbctl: {e}");
            return ExitCode::from(2);
        }
    };
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
        Cmd::Watch {
            period,
            duration,
            plain,
        } => watch(&cli, &catalog, *period, *duration, *plain),
        Cmd::Reset { timeout } => reset(&cli, *timeout),
        Cmd::Cancel { job, timeout } => cancel(&cli, *job, *timeout),
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
