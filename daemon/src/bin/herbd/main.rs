//! `herbd`: HERB's packing controller daemon. See `herb_daemon::controller` for the loop and
//! `herb_daemon::config` for the configuration.

use clap::Parser;
use herb_core::{Catalog, paths};
use herb_daemon::config::{Config, ConfigFile, OnRestart};
use herb_daemon::controller::{Controller, LoopStats, Ports, Shared, SlowCycle, StatsLink};
use herb_daemon::notify::{Notice, Notifier};
use herb_daemon::{decision, journal, logfmt, planner, record};
use herb_ipc::bus::{Bus, daemon_node_name, live_nodes_named};
use herb_ipc::{Fault, JobState, Services, Status, StatusEvent};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

mod tools;

/// How often the reporter thread prints statistics and statuses and pings the watchdog.
const REPORT_POLL: Duration = Duration::from_millis(20);

/// herbd is gone this long after SIGINT/SIGTERM whatever it is doing: the loop brakes within
/// `herb_daemon::job::STOP_LIMIT_NS`, and what has not ended by this deadline (a log writer
/// blocked on a full stderr, a journal or run-log write stuck on its disk) is cut short.
const STOP_DEADLINE: Duration = Duration::from_millis(1900);

/// Exit code when [`STOP_DEADLINE`] cut the shutdown short.
const EXIT_STOP_FORCED: i32 = 3;

/// Where the shutdown is, for the line [`stop_deadline`] writes when it cuts it short.
static STOP_STAGE: std::sync::atomic::AtomicU8 = std::sync::atomic::AtomicU8::new(0);

/// What [`STOP_STAGE`] codes name.
const STOP_STAGES: [&str; 6] = [
    "the loop (the arm's brake)",
    "the log writer (stderr blocked?)",
    "the planner thread",
    "the job journal's writer",
    "the run log's writer",
    "the final report (stdout blocked?)",
];

/// Starts the stop's deadline (once, from the signal handler's thread): after [`STOP_DEADLINE`]
/// the process ends with [`EXIT_STOP_FORCED`], naming the stage it was cut in. The line is
/// written by a thread of its own, so that a blocked stderr cannot hold the exit.
fn stop_deadline() {
    let spawned = std::thread::Builder::new()
        .name("herbd-stop".into())
        .spawn(|| {
            std::thread::sleep(STOP_DEADLINE);
            let stage = STOP_STAGES
                .get(STOP_STAGE.load(Ordering::Relaxed) as usize)
                .copied()
                .unwrap_or("?");
            let _ = std::thread::Builder::new().spawn(move || {
                logfmt::log(
                    "stop_forced",
                    &[
                        ("after_s", &STOP_DEADLINE.as_secs_f64()),
                        ("waiting_for", &stage),
                    ],
                )
            });
            std::thread::sleep(Duration::from_millis(50));
            herb_process::rt::exit_now(EXIT_STOP_FORCED);
        });
    // Without a thread for the deadline the stop goes on without one.
    drop(spawned);
}

/// Marks the shutdown's stage ([`STOP_STAGES`]).
fn stop_stage(stage: u8) {
    STOP_STAGE.store(stage, Ordering::Relaxed);
}

/// HERB's real-time packing controller.
#[derive(Debug, Parser)]
#[command(name = "herbd", version)]
struct Cli {
    /// TOML configuration (every key optional; see systemd/herbd.toml).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Loop rate (Hz).
    #[arg(long)]
    rate_hz: Option<f64>,
    /// IPC service-name prefix.
    #[arg(long)]
    prefix: Option<String>,
    /// Policy: `blbf` or an ONNX file.
    #[arg(long)]
    policy: Option<herb_decide::PolicySpec>,
    /// Sequence model (Beam-3 transition counts).
    #[arg(long)]
    sequence_model: Option<PathBuf>,
    /// BoxED folder (object meshes).
    #[arg(long)]
    boxed: Option<PathBuf>,
    /// Busy-wait before each deadline (us).
    #[arg(long)]
    spin_us: Option<u64>,
    /// Seconds between statistics reports.
    #[arg(long)]
    report_interval: Option<f64>,
    /// Stop by itself after this many seconds (benchmarks).
    #[arg(long)]
    run_for: Option<f64>,
    /// Also write the final statistics (JSON) to this file.
    #[arg(long)]
    stats_json: Option<PathBuf>,
    /// Write a run log into this folder (`herbd replay`, `herbd explain`).
    #[arg(long)]
    record: Option<PathBuf>,
    /// An offline tool instead of the daemon.
    #[command(subcommand)]
    tool: Option<Tool>,
}

/// herbd's offline tools (they run herbd's own code, not the daemon).
#[derive(Debug, clap::Subcommand)]
enum Tool {
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
    /// heightmap it was decided on and the next one (PNGs), the method (a search's candidates
    /// and their returns), the placement and its z estimate, the outcome.
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
    /// Print the cell as viewers draw it, as one JSON document (`python -m herb_client.view`):
    /// the arm's kinematic chain (herbd's own), the box and the pick station in the box frame,
    /// from `--config` (or the defaults), and herbd's forward kinematics at one configuration
    /// for a viewer to check its drawing against.
    CellModel,
    /// Measure the box and pick-station poses for the `[cell]` table by touching them with the
    /// gripper (the arm moved by hand; the arm adapter must run, under the configuration's
    /// prefix): prints the lines to paste.
    CalibrateCell {
        /// Box corners to touch: 3 or 4.
        #[arg(long, default_value_t = 4)]
        corners: usize,
        /// From the gripper's endpoint to the touching tip, along its approach axis (m).
        #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
        tip_offset: f64,
    },
}

/// Runs `tool` (the daemon does not start).
fn run_tool(cli: &Cli, tool: &Tool) -> ExitCode {
    let fail = |e: String| {
        eprintln!("herbd: error: {e}");
        ExitCode::from(2)
    };
    match tool {
        Tool::Replay { log, force, events } => {
            tools::replay(cli.boxed.clone(), log, *force, events.as_deref())
        }
        Tool::Explain {
            log,
            object,
            out,
            force,
        } => {
            let catalog = match Catalog::builtin(&paths::MeshSource::None(
                "herbd explain needs no meshes".into(),
            )) {
                Ok(c) => c,
                Err(e) => return fail(e.to_string()),
            };
            match tools::explain(cli.boxed.clone(), &catalog, log, *object, out, *force) {
                Ok(_) => ExitCode::SUCCESS,
                Err(e) => fail(e),
            }
        }
        Tool::CellModel => match config(cli) {
            Ok(c) => {
                println!("{}", serde_json::json!(tools::cell_model(&c)));
                ExitCode::SUCCESS
            }
            Err(e) => fail(e),
        },
        Tool::CalibrateCell {
            corners,
            tip_offset,
        } => {
            let prefix = match (&cli.prefix, &cli.config) {
                (Some(p), _) => p.clone(),
                (None, Some(path)) => match Config::load(path) {
                    Ok(c) => c.ipc_prefix,
                    Err(e) => return fail(e.to_string()),
                },
                (None, None) => Config::default().ipc_prefix,
            };
            let stdin = std::io::stdin();
            match herb_daemon::cellcal::run(
                &prefix,
                *corners,
                *tip_offset,
                &mut stdin.lock(),
                &mut std::io::stderr(),
            ) {
                Ok(cell) => {
                    println!("[cell]\n{cell}");
                    ExitCode::SUCCESS
                }
                Err(e) => fail(e.to_string()),
            }
        }
    }
}

fn config(cli: &Cli) -> Result<Config, String> {
    let mut c = match &cli.config {
        Some(p) => Config::load(p).map_err(|e| e.to_string())?,
        None => Config::default(),
    };
    if let Some(v) = cli.rate_hz {
        c.loop_.rate_hz = v;
    }
    if let Some(v) = &cli.prefix {
        c.ipc_prefix = v.clone();
    }
    if let Some(v) = &cli.policy {
        c.models.policy = v.clone();
    }
    if let Some(v) = &cli.sequence_model {
        c.models.sequence = v.clone();
    }
    if let Some(v) = &cli.boxed {
        c.models.boxed = Some(v.clone());
    }
    if let Some(v) = cli.spin_us {
        c.loop_.spin_us = v;
    }
    if let Some(v) = cli.report_interval {
        c.loop_.report_interval_s = v;
    }
    if let Some(v) = &cli.record {
        c.record.dir = Some(v.clone());
    }
    c.models.policy = c.models.resolved_policy();
    c.validate().map_err(|e| format!("configuration: {e}"))?;
    Ok(c)
}

fn us(h: &hdrhistogram::Histogram<u64>, q: f64) -> f64 {
    if h.is_empty() {
        0.0
    } else {
        h.value_at_quantile(q) as f64 / 1000.0
    }
}

/// The histogram's largest value in microseconds (0 when empty).
fn max_us(h: &hdrhistogram::Histogram<u64>) -> f64 {
    if h.is_empty() {
        0.0
    } else {
        h.max() as f64 / 1000.0
    }
}

fn summary(s: &LoopStats) -> serde_json::Value {
    let h = |h: &hdrhistogram::Histogram<u64>| {
        serde_json::json!({
            "p50": us(h, 0.5), "p99": us(h, 0.99), "max": max_us(h),
            "n": h.len(),
        })
    };
    serde_json::json!({
        "cycles": s.cycles,
        "deadline_misses": s.misses,
        "cycle_us": h(&s.cycle_ns),
        "jitter_us": h(&s.jitter_ns),
        "decision_us": h(&s.decision_ns),
        "jobs": s.jobs,
        "decision_wait_ms": s.decision_wait_ms,
        "slowest_cycle": slow_cycle_json(&s.slowest),
    })
}

/// The log line of a status event (none for heartbeats), in herbd's key=value form.
fn describe(s: &Status) -> Option<String> {
    let ev = StatusEvent::from_code(s.event)?;
    let fault = format!("{:?}", Fault::from_code(s.fault).unwrap_or(Fault::None));
    let state = format!(
        "{:?}",
        JobState::from_code(s.state).unwrap_or(JobState::Idle)
    );
    let placed = format!("{}/{}", s.objects_done, s.objects_total);
    // After the last object there is no current one (not "4/3").
    let object = if s.object_index < s.objects_total {
        format!("{}/{}", s.object_index + 1, s.objects_total)
    } else {
        "none".to_string()
    };
    let ms = format!("{:.3}", s.decision_ns as f64 / 1e6);
    let p = s.pose.map(|v| format!("{v:.4}"));
    let job: &dyn std::fmt::Display = &s.job_id;
    Some(match ev {
        StatusEvent::Heartbeat => return None,
        StatusEvent::Accepted => {
            logfmt::line("accepted", &[("job", job), ("objects", &s.objects_total)])
        }
        StatusEvent::Decided => logfmt::line(
            "decided",
            &[
                ("job", job),
                ("object", &object),
                ("type", &s.object_type),
                ("x", &p[0]),
                ("y", &p[1]),
                ("z", &p[2]),
                ("yaw", &p[3]),
                ("decision_ms", &ms),
            ],
        ),
        StatusEvent::Placed => logfmt::line(
            "placed",
            &[("job", job), ("object", &object), ("placed", &placed)],
        ),
        StatusEvent::Fault => match s.limit_excess() {
            // Which joint, where, and the limit it is beyond.
            Some((j, q, bound)) => logfmt::line(
                "fault",
                &[
                    ("job", job),
                    ("fault", &fault),
                    ("state", &state),
                    ("object", &object),
                    ("joint", &herb_ipc::JOINT_NAMES[j]),
                    ("position_rad", &format!("{q:.4}")),
                    ("limit_rad", &format!("{bound:.4}")),
                    ("beyond_rad", &format!("{:.4}", (q - bound).abs())),
                ],
            ),
            None => logfmt::line(
                "fault",
                &[
                    ("job", job),
                    ("fault", &fault),
                    ("state", &state),
                    ("object", &object),
                ],
            ),
        },
        StatusEvent::AwaitingObject => logfmt::line(
            "awaiting_object",
            &[
                ("job", job),
                ("object", &object),
                ("type", &s.object_type),
                ("attempt", &s.attempt),
            ],
        ),
        StatusEvent::Braked => logfmt::line("braked", &[("job", job), ("fault", &fault)]),
        StatusEvent::Resumed => logfmt::line("resumed", &[("job", job), ("object", &object)]),
        StatusEvent::JobDone => logfmt::line(
            "job_done",
            &[
                ("job", job),
                ("placed", &placed),
                ("decision_wait_ms", &s.decision_wait_ms),
            ],
        ),
        StatusEvent::JobFailed => logfmt::line(
            "job_failed",
            &[
                ("job", job),
                ("fault", &fault),
                ("placed", &placed),
                ("decision_wait_ms", &s.decision_wait_ms),
            ],
        ),
        StatusEvent::JobCancelled => logfmt::line(
            "job_cancelled",
            &[
                ("job", job),
                ("placed", &placed),
                ("decision_wait_ms", &s.decision_wait_ms),
            ],
        ),
        StatusEvent::Shutdown => logfmt::line("shutdown", &[("state", &state)]),
        StatusEvent::Skipped => logfmt::line(
            "skipped",
            &[
                ("job", job),
                ("object", &object),
                ("type", &s.object_type),
                ("fault", &fault),
            ],
        ),
    })
}

/// A cycle whose own work took longer than this is reported on its own line (ns): a cycle's
/// budget at 1 kHz.
const SLOW_CYCLE_NS: u64 = 1_000_000;

/// The interval's slowest cycle taken apart, as a log line, when it took longer than
/// [`SLOW_CYCLE_NS`].
fn slow_cycle_line(s: &LoopStats) -> Option<String> {
    let c = &s.slowest;
    if c.work_ns <= SLOW_CYCLE_NS {
        return None;
    }
    let stages: Vec<String> = SlowCycle::STAGES
        .iter()
        .zip(c.stages_ns)
        .map(|(n, d)| format!("{n}:{:.1}", d as f64 / 1e3))
        .collect();
    Some(logfmt::line(
        "slow_cycle",
        &[
            ("cycle", &c.cycle),
            ("work_us", &format!("{:.1}", c.work_ns as f64 / 1e3)),
            ("stages_us", &stages.join(",")),
            ("page_faults", &(c.met.minflt + c.met.majflt)),
            ("blocked", &c.met.nvcsw),
            ("preempted", &c.met.nivcsw),
        ],
    ))
}

/// The slowest cycle as JSON (the final statistics).
fn slow_cycle_json(c: &SlowCycle) -> serde_json::Value {
    let stages: serde_json::Map<String, serde_json::Value> = SlowCycle::STAGES
        .iter()
        .zip(c.stages_ns)
        .map(|(n, d)| (n.to_string(), serde_json::json!(d as f64 / 1e3)))
        .collect();
    serde_json::json!({
        "cycle": c.cycle,
        "work_us": c.work_ns as f64 / 1e3,
        "stages_us": stages,
        "minor_faults": c.met.minflt,
        "major_faults": c.met.majflt,
        "blocked": c.met.nvcsw,
        "preempted": c.met.nivcsw,
    })
}

/// The statistics of one reporting interval as a log line.
fn stats_line(s: &LoopStats) -> String {
    let f = |h: &hdrhistogram::Histogram<u64>, q: f64| format!("{:.1}", us(h, q));
    logfmt::line(
        "stats",
        &[
            ("cycles", &s.cycles),
            ("deadline_misses", &s.misses),
            ("cycle_p50_us", &f(&s.cycle_ns, 0.5)),
            ("cycle_p99_us", &f(&s.cycle_ns, 0.99)),
            ("cycle_max_us", &format!("{:.1}", max_us(&s.cycle_ns))),
            ("jitter_p99_us", &f(&s.jitter_ns, 0.99)),
            ("decisions", &s.decision_ns.len()),
            ("decision_p99_us", &f(&s.decision_ns, 0.99)),
        ],
    )
}

/// The job journal: an unfinished job is taken up (or abandoned) before the loop starts; a
/// journal that cannot be used is reported and set aside, never a reason not to start. Returns
/// the controller writing to it and the journal's writer thread (none without a folder).
fn open_journal(
    cfg: &Config,
    catalog_len: usize,
    mut controller: Controller,
    stop: &Arc<std::sync::atomic::AtomicBool>,
) -> Result<
    (
        Controller,
        Option<std::thread::JoinHandle<journal::WriterReport>>,
    ),
    String,
> {
    let journal_dir = cfg
        .journal
        .folder(std::env::var("STATE_DIRECTORY").ok().as_deref());
    let writer = match &journal_dir {
        Some(dir) => {
            match journal::load(dir, catalog_len) {
                Ok(None) => {}
                Ok(Some(r)) => {
                    let resume = cfg.journal.on_restart == OnRestart::Resume;
                    logfmt::log(
                        "job_recovered",
                        &[
                            ("job", &r.job_id),
                            ("action", &if resume { "resume" } else { "abandon" }),
                            ("journal", &dir.join(journal::FILE).display()),
                            ("state", &r.describe()),
                        ],
                    );
                    controller.recover(&r, resume);
                }
                Err(e) => {
                    let aside = journal::set_aside(dir)
                        .map(|p| p.display().to_string())
                        .unwrap_or_else(|e| format!("(cannot rename: {e})"));
                    logfmt::log(
                        "journal_set_aside",
                        &[
                            ("error", &e),
                            ("moved_to", &aside),
                            ("action", &"start_idle"),
                        ],
                    );
                }
            }
            let (tx, writer) =
                journal::spawn(dir.clone(), stop.clone()).map_err(|e| e.to_string())?;
            controller = controller.with_journal(tx);
            Some(writer)
        }
        None => {
            logfmt::log(
                "journal_off",
                &[
                    ("reason", &"no journal.dir and no $STATE_DIRECTORY"),
                    ("effect", &"a job does not survive a restart"),
                ],
            );
            None
        }
    };
    Ok((controller, writer))
}

/// The reporter thread: statistics and events, formatted off the loop; the systemd watchdog is
/// pinged only while the loop's cycle counter advances. Returns the statistics of the whole run.
fn spawn_reporter(
    shared: Arc<Shared>,
    notifier: Arc<Notifier>,
    run_for: Option<f64>,
    mut stats_link: StatsLink,
    done: Arc<std::sync::atomic::AtomicBool>,
) -> Result<std::thread::JoinHandle<LoopStats>, String> {
    std::thread::Builder::new()
        .name("herbd-report".into())
        .spawn(move || {
            let mut total = LoopStats::new();
            let t0 = std::time::Instant::now();
            let mut last_cycles = 0;
            // Every event the loop sent, in order; once more after the loop ended, so that
            // the last ones (`braked`, `shutdown`) are written before herbd exits.
            let write_events = |events: &mut rtrb::Consumer<Status>| {
                while let Ok(s) = events.pop() {
                    if let Some(line) = describe(&s) {
                        logfmt::emit(&line);
                    }
                }
            };
            loop {
                let ending = done.load(Ordering::Relaxed);
                while let Ok(mut s) = stats_link.rx.pop() {
                    total.add(&s);
                    logfmt::emit(&stats_line(&s));
                    if let Some(line) = slow_cycle_line(&s) {
                        logfmt::emit(&line);
                    }
                    s.reset();
                    let _ = stats_link.tx.push(s);
                }
                write_events(&mut stats_link.events);
                if ending {
                    break;
                }
                let c = shared.cycles.load(Ordering::Relaxed);
                if c > last_cycles {
                    last_cycles = c;
                    notifier.send(Notice::Watchdog);
                }
                if shared.stop.load(Ordering::Relaxed) {
                    // The loop brakes and ends; systemd hears of the stop now.
                    notifier.send(Notice::Stopping);
                }
                if run_for.is_some_and(|t| t0.elapsed().as_secs_f64() >= t) {
                    shared.stop.store(true, Ordering::Relaxed);
                }
                std::thread::sleep(REPORT_POLL);
            }
            total
        })
        .map_err(|e| format!("cannot start the reporter: {e}"))
}

fn run(cli: Cli) -> Result<(), String> {
    let cfg = config(&cli)?;
    // herbd's own configuration first (iceoryx2 has one of its own, left at its defaults).
    match &cli.config {
        Some(p) => logfmt::log("config", &[("file", &p.display())]),
        None => logfmt::log(
            "config",
            &[
                ("file", &"none"),
                ("using", &"the defaults (--config FILE)"),
            ],
        ),
    }
    let services = Services::new(&cfg.ipc_prefix).map_err(|e| e.to_string())?;
    // One daemon per prefix: two would answer the same jobs and drive the same arm.
    let node_name = daemon_node_name(&cfg.ipc_prefix);
    let running = live_nodes_named(&node_name).map_err(|e| e.to_string())?;
    if let Some(pid) = running.first() {
        return Err(format!(
            "another herbd (pid {pid}) already serves prefix {:?}; stop it first or use another ipc_prefix",
            cfg.ipc_prefix
        ));
    }
    let root = paths::boxed_root(cfg.models.boxed.as_deref());
    let meshes = paths::mesh_source(None, root.as_deref());
    let catalog = Arc::new(Catalog::builtin(&meshes).map_err(|e| format!("catalog: {e}"))?);
    let shared = Arc::new(Shared::default());
    let notifier = Arc::new(Notifier::new());
    {
        let s = shared.clone();
        ctrlc::set_handler(move || {
            if !s.stop.swap(true, Ordering::Relaxed) {
                stop_deadline();
            }
        })
        .map_err(|e| format!("cannot install the signal handler: {e}"))?;
    }
    let planner_stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let recording = match &cfg.record.dir {
        Some(dir) => {
            let header = record::header_for(&cfg, &catalog).map_err(|e| e.to_string())?;
            let opts = record::RecordOptions {
                dir: dir.clone(),
                segment_bytes: cfg.record.segment_mb << 20,
                keep_bytes: cfg.record.keep_mb << 20,
            };
            logfmt::log("recording", &[("dir", &dir.display())]);
            Some(record::start(opts, header).map_err(|e| e.to_string())?)
        }
        None => None,
    };
    let (recorder, frame_log, writer) = match recording {
        Some(record::Recording {
            recorder,
            frames,
            writer,
            stop,
        }) => (Some(recorder), Some(frames), Some((writer, stop))),
        None => (None, None, None),
    };
    let (link, planner_thread) =
        planner::spawn(&cfg, catalog.clone(), planner_stop.clone()).map_err(|e| e.to_string())?;
    // The decision worker is not joined at exit: a search in progress is dropped with the
    // process (nothing it holds outlives it).
    let (decider, _decision_thread) =
        decision::spawn(&cfg, catalog.clone(), planner_stop.clone(), frame_log)
            .map_err(|e| e.to_string())?;
    let bus = Bus::open(&node_name, &services).map_err(|e| e.to_string())?;
    let ports = Ports::open(bus).map_err(|e| e.to_string())?;
    let (controller, stats_link) =
        Controller::new(&cfg, ports, link, decider, shared.clone(), catalog.len());
    let controller = match recorder {
        Some(r) => controller.with_recorder(r),
        None => controller,
    };
    let journal_stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let (controller, journal_writer) =
        open_journal(&cfg, catalog.len(), controller, &journal_stop)?;
    logfmt::log(
        "start",
        &[
            ("rate_hz", &cfg.loop_.rate_hz),
            ("prefix", &cfg.ipc_prefix),
            ("policy", &cfg.models.policy),
            ("catalog_types", &catalog.len()),
            ("pid", &std::process::id()),
        ],
    );

    let done = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let reporter = spawn_reporter(
        shared.clone(),
        notifier.clone(),
        cli.run_for,
        stats_link,
        done.clone(),
    )?;

    // Real time for the loop's thread (this one), after every other thread has started: they
    // stay at normal priority. `_rt` holds the CPU latency request until herbd exits.
    let _rt = herb_process::rt::apply(&cfg.rt);
    match _rt.warning() {
        Some(w) => logfmt::log("warning", &[("what", &w)]),
        None if !_rt.applied.is_empty() => {
            logfmt::log("real_time", &[("applied", &_rt.applied.join(", "))])
        }
        None => {}
    }
    notifier.send(Notice::Ready);
    let last = controller.run();
    done.store(true, Ordering::Relaxed);
    stop_stage(1);
    let mut total = reporter.join().map_err(|_| "reporter thread panicked")?;
    total.add(&last);
    let dropped = shared.log_dropped.load(Ordering::Relaxed);
    if dropped > 0 {
        logfmt::log(
            "log_dropped",
            &[
                ("events", &dropped),
                ("why", &"the log writer fell behind the loop"),
            ],
        );
    }
    planner_stop.store(true, Ordering::Relaxed);
    stop_stage(2);
    let _ = planner_thread.join();
    stop_stage(3);
    journal_stop.store(true, Ordering::Relaxed);
    close_journal(journal_writer);
    stop_stage(4);
    if let Some((writer, stop)) = writer {
        stop.store(true, Ordering::Relaxed);
        match writer.join() {
            Ok(Ok(files)) => {
                for f in files {
                    logfmt::log("run_log", &[("file", &f.display())]);
                }
            }
            Ok(Err(e)) => logfmt::log("run_log_failed", &[("error", &e)]),
            Err(_) => logfmt::log("run_log_failed", &[("error", &"the writer panicked")]),
        }
    }
    stop_stage(5);
    notifier.send(Notice::Stopping);
    for (notice, n) in notifier.failures() {
        logfmt::log("notify_failures", &[("notice", &notice), ("failed", &n)]);
    }
    final_report(&total, dropped, cli.stats_json.as_deref())
}

/// Waits for the journal's writer to end and logs what it wrote.
fn close_journal(writer: Option<std::thread::JoinHandle<journal::WriterReport>>) {
    if let Some(w) = writer {
        match w.join() {
            Ok(r) => logfmt::log(
                "journal_closed",
                &[("writes", &r.writes), ("failures", &r.failures)],
            ),
            Err(_) => logfmt::log("journal_closed", &[("error", &"the writer panicked")]),
        }
    }
}

/// herbd's final statistics as one JSON line on stdout, and into `stats_json` if given.
fn final_report(
    total: &LoopStats,
    dropped: u64,
    stats_json: Option<&std::path::Path>,
) -> Result<(), String> {
    let mut report = serde_json::json!({ "herbd_final": summary(total) });
    report["herbd_final"]["log"] = serde_json::json!({
        "events_dropped": dropped,
        "lines_not_written": logfmt::failed_writes(),
    });
    println!("{report}");
    if let Some(p) = stats_json {
        std::fs::write(p, format!("{report}\n"))
            .map_err(|e| format!("cannot write {}: {e}", p.display()))?;
    }
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Some(tool) = &cli.tool {
        return run_tool(&cli, tool);
    }
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            logfmt::log("error", &[("error", &e)]);
            ExitCode::from(2)
        }
    }
}
