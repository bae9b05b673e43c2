//! `herb-chaos`: the chaos soak. herbd (its defaults: the search decides, real time, the job
//! journal), herb-loopback and a client packing random BoxED episodes back to back run for
//! `--minutes`; every `--every-min-s` to `--every-max-s` seconds one fault from the whole list
//! is injected (the kinds in a shuffled round, so that each comes as often as the others):
//!
//! - the arm adapter killed and restarted, or stopped (SIGSTOP) for 2 to 5 s;
//! - herbd killed (SIGKILL) and restarted 2 s later on its journal, as systemd would;
//! - an e-stop held 2 to 5 s; a disable held 4 to 6 s while the arm sags (`--sag`) past
//!   herbd's limits;
//! - a missed grasp; a burst of camera dropouts (3 s) and bad heightmap frames;
//! - the client killed mid-job (its job runs on); a second client cancelling the job.
//!
//! An observer on the bus (not herbd) checks all the time that no joint command leaves the
//! arm's limits or the measured arm's neighbourhood, that no object is decided or placed
//! twice, that every job ends with `JobDone` or a named failure and no `JobDone` comes while the
//! loopback says an object is outside; afterwards, that herbd's log says what the bus said, that
//! its journal was always readable, and that memory and open files stayed flat. A fault is
//! recovered when the cell makes progress again (an object placed or a job accepted) with no
//! person's help. Writes `report.json` and `report.md` into `--out` and exits 1 on any
//! violation or fault not recovered, 2 when it cannot run.

mod cell;
mod observer;

use cell::{Client, Daemon, rss_and_fds, run_logged};
use clap::Parser;
use herb_ipc::monotonic_ns;
use observer::{Event, Observer};
use rand::{Rng, SeedableRng, seq::SliceRandom};
use rand_chacha::ChaCha8Rng;
use serde_json::json;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// The chaos soak (see the crate's documentation).
#[derive(Debug, Parser)]
#[command(name = "herb-chaos")]
struct Cli {
    /// How long to inject faults (minutes).
    #[arg(long, default_value_t = 60.0)]
    minutes: f64,
    /// Shortest time between two faults (s).
    #[arg(long, default_value_t = 60.0)]
    every_min_s: f64,
    /// Longest time between two faults (s).
    #[arg(long, default_value_t = 120.0)]
    every_max_s: f64,
    /// A fault not recovered within this is a violation (s).
    #[arg(long, default_value_t = 300.0)]
    recover_s: f64,
    /// The folder of the built binaries (herbd, herbctl, herb-loopback).
    #[arg(long, default_value = "target/release")]
    bin: PathBuf,
    /// Where the report and the processes' logs go (default runs/chaos-<time>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Seed of the episodes, the faults and their timing.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// How fast the arm sags while disabled or e-stopped (rad/s on s1, half on e1).
    #[arg(long, default_value_t = 0.5)]
    sag: f64,
    /// Fail unless every fault kind was injected at least this many times.
    #[arg(long, default_value_t = 0)]
    require_each: u32,
}

/// The kinds of fault, in the order the report lists them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Kind {
    AdapterRestart,
    AdapterStall,
    DaemonRestart,
    EStop,
    DisableSag,
    MissedGrasp,
    CameraBurst,
    ClientKilled,
    CancelByOther,
}

const KINDS: [Kind; 9] = [
    Kind::AdapterRestart,
    Kind::AdapterStall,
    Kind::DaemonRestart,
    Kind::EStop,
    Kind::DisableSag,
    Kind::MissedGrasp,
    Kind::CameraBurst,
    Kind::ClientKilled,
    Kind::CancelByOther,
];

impl Kind {
    fn name(self) -> &'static str {
        match self {
            Kind::AdapterRestart => "adapter killed and restarted",
            Kind::AdapterStall => "adapter stopped (SIGSTOP)",
            Kind::DaemonRestart => "herbd killed and restarted",
            Kind::EStop => "e-stop",
            Kind::DisableSag => "disable, the arm sagging",
            Kind::MissedGrasp => "missed grasp",
            Kind::CameraBurst => "camera dropouts and bad frames",
            Kind::ClientKilled => "client killed mid-job",
            Kind::CancelByOther => "a second client cancels",
        }
    }
}

/// One injected fault.
#[derive(Debug)]
struct Injected {
    kind: Kind,
    /// Seconds from the start when it began and ended (the cell's own recovery starts then).
    at_s: f64,
    ended_s: f64,
    /// Seconds from its beginning to the cell's progress again (`None`: not recovered).
    recovered_after_s: Option<f64>,
    note: String,
}

/// The harness's state.
struct Harness {
    cli: Cli,
    out: PathBuf,
    prefix: String,
    loopback: Daemon,
    herbd: Daemon,
    observer: Observer,
    rng: ChaCha8Rng,
    t0: Instant,
    /// herbd's SIGKILLs: when (monotonic ns), to excuse the log's lost tail.
    herbd_kills: Vec<u64>,
    /// (seconds, process, incarnation, rss KiB, fds).
    memory: Vec<(f64, &'static str, u32, u64, u64)>,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("herb-chaos: error: {e}");
            ExitCode::from(2)
        }
    }
}

fn run(cli: Cli) -> Result<bool, String> {
    if !(cli.minutes > 0.0 && cli.every_min_s > 0.0 && cli.every_max_s >= cli.every_min_s) {
        return Err(
            "--minutes and --every-min-s must be positive, --every-max-s at least --every-min-s"
                .into(),
        );
    }
    for b in ["herbd", "herbctl", "herb-loopback"] {
        if !cli.bin.join(b).is_file() {
            return Err(format!(
                "{} not found: build it first (cargo build --release --bins) or pass --bin",
                cli.bin.join(b).display()
            ));
        }
    }
    let root = herb_core::paths::boxed_root(None)
        .filter(|p| p.join("sessions").is_dir())
        .ok_or("the BoxED data was not found (set HERB_BOXED or place it at ../shared/boxed)")?;
    let sessions = herb_core::boxed::list_sessions(&root).map_err(|e| e.to_string())?;
    let out = cli.out.clone().unwrap_or_else(|| {
        let secs = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        PathBuf::from(format!("runs/chaos-{secs}"))
    });
    std::fs::create_dir_all(out.join("state")).map_err(|e| format!("{}: {e}", out.display()))?;
    let prefix = format!("chaos{}", std::process::id());
    let cfg = out.join("herbd.toml");
    std::fs::write(
        &cfg,
        format!(
            "ipc_prefix = \"{prefix}\"\n[journal]\ndir = \"{}\"\n",
            std::fs::canonicalize(out.join("state"))
                .map_err(|e| e.to_string())?
                .display()
        ),
    )
    .map_err(|e| e.to_string())?;
    let loopback = Daemon::new(
        cli.bin.join("herb-loopback"),
        vec![
            "--prefix".into(),
            prefix.clone(),
            "--sag".into(),
            cli.sag.to_string(),
        ],
        "loopback",
        &out,
    );
    let herbd = Daemon::new(
        cli.bin.join("herbd"),
        vec!["--config".into(), cfg.display().to_string()],
        "herbd",
        &out,
    );
    let observer = Observer::start(&prefix)?;
    let rng = ChaCha8Rng::seed_from_u64(cli.seed);
    let mut h = Harness {
        cli,
        out,
        prefix,
        loopback,
        herbd,
        observer,
        rng,
        t0: Instant::now(),
        herbd_kills: Vec::new(),
        memory: Vec::new(),
    };
    h.loopback.start()?;
    h.herbd.start()?;
    let mut picks = ChaCha8Rng::seed_from_u64(h.cli.seed ^ 0x5eed);
    let mut client = Client::start(
        h.cli.bin.join("herbctl"),
        h.prefix.clone(),
        &h.out,
        sessions,
        move |n| picks.random_range(0..n),
    );
    let faults = h.soak(&client)?;
    // The end: the running job cancelled (a named end), the client stopped, then the cell.
    client.stop_soon();
    let _ = run_logged(
        &h.cli.bin.join("herbctl"),
        &["--prefix", &h.prefix, "cancel", "--timeout", "30"],
        &h.out.join("herbctl.log"),
        None,
    );
    client.stop();
    std::thread::sleep(Duration::from_secs(2));
    let (herbd_stop, herbd_code) = h.herbd.terminate(Duration::from_secs(10));
    let (_, lb_code) = h.loopback.terminate(Duration::from_secs(10));
    std::thread::sleep(Duration::from_millis(500));
    h.observer.stop();
    let runs = client
        .runs
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .clone();
    h.report(&faults, &runs, herbd_stop, herbd_code, lb_code)
}

impl Harness {
    fn secs(&self) -> f64 {
        self.t0.elapsed().as_secs_f64()
    }

    /// Injects faults for `--minutes`; returns them.
    fn soak(&mut self, client: &Client) -> Result<Vec<Injected>, String> {
        let end = Duration::from_secs_f64(self.cli.minutes * 60.0);
        let mut round: Vec<Kind> = Vec::new();
        let mut faults = Vec::new();
        let mut next = self.gap();
        let mut last_sample = 0.0;
        while self.t0.elapsed() < end {
            self.keep_alive()?;
            if self.secs() - last_sample >= 10.0 {
                last_sample = self.secs();
                self.sample_memory();
            }
            if self.t0.elapsed() >= next {
                if round.is_empty() {
                    round = KINDS.to_vec();
                    round.shuffle(&mut self.rng);
                }
                let kind = round.pop().expect("a kind");
                let f = self.inject(kind, client)?;
                println!(
                    "{:7.1} s  {:<32} {}  {}",
                    f.at_s,
                    kind.name(),
                    f.recovered_after_s
                        .map_or("NOT RECOVERED".to_string(), |s| format!(
                            "recovered in {s:.1} s"
                        )),
                    f.note
                );
                faults.push(f);
                next = self.t0.elapsed() + self.gap();
            }
            std::thread::sleep(Duration::from_millis(200));
        }
        Ok(faults)
    }

    fn gap(&mut self) -> Duration {
        Duration::from_secs_f64(
            self.rng
                .random_range(self.cli.every_min_s..=self.cli.every_max_s),
        )
    }

    /// A process that died by itself (not killed by the harness) is a finding: it is restarted
    /// as systemd would, and reported.
    fn keep_alive(&mut self) -> Result<(), String> {
        if let Some(st) = self.herbd.exited() {
            self.violation(format!("herbd exited by itself ({st}); restarted"));
            std::thread::sleep(Duration::from_secs(2));
            self.herbd.start()?;
        }
        if let Some(st) = self.loopback.exited() {
            self.violation(format!("herb-loopback exited by itself ({st}); restarted"));
            self.loopback.start()?;
        }
        Ok(())
    }

    fn violation(&self, what: String) {
        self.observer
            .seen
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .violations
            .push((monotonic_ns(), what));
    }

    fn sample_memory(&mut self) {
        let t = self.secs();
        for (name, d) in [("herbd", &self.herbd), ("loopback", &self.loopback)] {
            if let Some(pid) = d.pid()
                && let Some((rss, fds)) = rss_and_fds(pid)
            {
                self.memory.push((t, name, d.incarnations, rss, fds));
            }
        }
    }

    fn hold(&mut self, lo: f64, hi: f64) -> f64 {
        let s = self.rng.random_range(lo..=hi);
        std::thread::sleep(Duration::from_secs_f64(s));
        s
    }

    /// Injects one fault, then waits for the cell's progress.
    fn inject(&mut self, kind: Kind, client: &Client) -> Result<Injected, String> {
        let at_s = self.secs();
        let progress0 = self.observer.progress.load(Ordering::Relaxed);
        let note = match kind {
            Kind::AdapterRestart => {
                self.loopback.kill();
                std::thread::sleep(Duration::from_secs(1));
                self.loopback.start()?;
                String::new()
            }
            Kind::AdapterStall => {
                self.loopback.signal(libc::SIGSTOP);
                let s = self.hold(2.0, 5.0);
                self.loopback.signal(libc::SIGCONT);
                format!("{s:.1} s")
            }
            Kind::DaemonRestart => {
                self.herbd.kill();
                self.herbd_kills.push(monotonic_ns());
                std::thread::sleep(Duration::from_secs(2));
                self.herbd.start()?;
                String::new()
            }
            Kind::EStop => {
                self.loopback.signal(libc::SIGUSR2);
                let s = self.hold(2.0, 5.0);
                self.loopback.signal(libc::SIGUSR2);
                format!("{s:.1} s")
            }
            Kind::DisableSag => {
                self.loopback.signal(libc::SIGUSR1);
                let s = self.hold(4.0, 6.0);
                self.loopback.signal(libc::SIGUSR1);
                format!("{s:.1} s")
            }
            Kind::MissedGrasp => {
                self.loopback.signal(libc::SIGRTMIN());
                "the next grasp".into()
            }
            Kind::CameraBurst => {
                self.loopback.signal(libc::SIGRTMIN() + 1);
                let sent = bad_frames(&self.prefix, 40, Duration::from_millis(50))?;
                format!("3 s dropout, {sent} bad frames")
            }
            Kind::ClientKilled => {
                let t = Instant::now();
                let mut pid = 0;
                while t.elapsed() < Duration::from_secs(60) {
                    pid = client.pack_pid.load(Ordering::Relaxed);
                    if pid != 0 {
                        break;
                    }
                    std::thread::sleep(Duration::from_millis(100));
                }
                if pid == 0 {
                    "no client ran".into()
                } else {
                    // Mid-job: after its job has had time to start.
                    std::thread::sleep(Duration::from_secs(3));
                    // SAFETY: kill on the herbctl the client thread started.
                    unsafe { libc::kill(pid, libc::SIGKILL) };
                    format!("herbctl pid {pid}")
                }
            }
            Kind::CancelByOther => {
                let code = run_logged(
                    &self.cli.bin.join("herbctl"),
                    &["--prefix", &self.prefix, "cancel", "--timeout", "30"],
                    &self.out.join("herbctl.log"),
                    None,
                );
                format!("herbctl cancel exit {code:?}")
            }
        };
        let ended_s = self.secs();
        let limit = Duration::from_secs_f64(self.cli.recover_s);
        let t = Instant::now();
        let mut recovered_after_s = None;
        while t.elapsed() < limit {
            self.keep_alive()?;
            if self.observer.progress.load(Ordering::Relaxed) > progress0 && self.secs() > ended_s {
                recovered_after_s = Some(self.secs() - at_s);
                break;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        if recovered_after_s.is_none() {
            self.violation(format!(
                "{} at {at_s:.0} s: no progress within {} s",
                kind.name(),
                self.cli.recover_s
            ));
        }
        Ok(Injected {
            kind,
            at_s,
            ended_s,
            recovered_after_s,
            note,
        })
    }

    /// The report: what ran, each fault, each invariant; true when nothing was violated.
    fn report(
        &mut self,
        faults: &[Injected],
        runs: &[cell::ClientRun],
        herbd_stop: Duration,
        herbd_code: Option<i32>,
        lb_code: Option<i32>,
    ) -> Result<bool, String> {
        let (log_violations, journal_set_aside, recovered_jobs) = self.compare_logs();
        for v in log_violations {
            self.violation(v);
        }
        if journal_set_aside > 0 {
            self.violation(format!(
                "herbd set its journal aside {journal_set_aside} time(s): unreadable"
            ));
        }
        if herbd_stop > Duration::from_secs(2) || herbd_code.is_none() {
            self.violation(format!(
                "herbd took {herbd_stop:?} to exit on SIGTERM (code {herbd_code:?})"
            ));
        }
        let memory = self.memory_verdict();
        if let Some(v) = memory.get("violation").and_then(|v| v.as_str()) {
            self.violation(v.to_string());
        }
        let seen = self.observer.seen.lock().unwrap_or_else(|e| e.into_inner());
        let mut violations: Vec<String> = seen
            .violations
            .iter()
            .map(|(t, v)| format!("{v} (at {:.1} s)", self.at(*t)))
            .collect();
        for (id, j) in &seen.jobs {
            if j.end.is_none() {
                violations.push(format!("job {id} never ended"));
            }
        }
        let mut by_kind: BTreeMap<Kind, (u32, u32, f64)> = BTreeMap::new();
        for f in faults {
            let e = by_kind.entry(f.kind).or_default();
            e.0 += 1;
            if let Some(s) = f.recovered_after_s {
                e.1 += 1;
                e.2 = e.2.max(s);
            }
        }
        let short: Vec<&str> = KINDS
            .iter()
            .filter(|k| by_kind.get(k).map_or(0, |e| e.0) < self.cli.require_each)
            .map(|k| k.name())
            .collect();
        if !short.is_empty() {
            violations.push(format!(
                "injected fewer than {} times: {}",
                self.cli.require_each,
                short.join(", ")
            ));
        }
        let mut ends: BTreeMap<String, u32> = BTreeMap::new();
        let mut outside_limits = 0;
        for j in seen.jobs.values() {
            let k = match j.end {
                Some((e, f)) => format!("{e:?} {f:?}"),
                None => "never ended".into(),
            };
            *ends.entry(k).or_default() += 1;
            outside_limits += j.faults.get("OutsideLimits").copied().unwrap_or(0);
        }
        let report = json!({
            "minutes": self.cli.minutes,
            "seconds": self.secs(),
            "seed": self.cli.seed,
            "prefix": self.prefix,
            "jobs_accepted": seen.jobs.len(),
            "job_ends": ends,
            "objects_placed": seen.jobs.values().map(|j| j.placed.len()).sum::<usize>(),
            "client_runs": runs.iter().map(|r| json!({
                "session": r.session, "exit": r.code, "seconds": r.seconds,
            })).collect::<Vec<_>>(),
            "client_exit_codes": runs.iter().fold(BTreeMap::<String, u32>::new(), |mut m, r| {
                *m.entry(format!("{:?}", r.code)).or_default() += 1;
                m
            }),
            "faults": faults.iter().map(|f| json!({
                "kind": f.kind.name(), "at_s": f.at_s, "ended_s": f.ended_s,
                "recovered_after_s": f.recovered_after_s, "note": f.note,
            })).collect::<Vec<_>>(),
            "faults_by_kind": by_kind.iter().map(|(k, (n, r, worst))| json!({
                "kind": k.name(), "injected": n, "recovered": r, "slowest_recovery_s": worst,
            })).collect::<Vec<_>>(),
            "outside_limits_faults_after_sag": outside_limits,
            "invariants": {
                "commands_checked": seen.commands_checked,
                "commands_compared_with_the_arm": seen.commands_compared,
                "max_command_offset_rad": seen.max_command_offset_rad,
                "status_events": seen.events.len(),
                "jobs_recovered_from_the_journal": recovered_jobs,
                "journal_set_aside": journal_set_aside,
            },
            "herbd_sigterm_s": herbd_stop.as_secs_f64(),
            "herbd_exit": herbd_code,
            "loopback_exit": lb_code,
            "herbd_incarnations": self.herbd.incarnations,
            "loopback_incarnations": self.loopback.incarnations,
            "memory": memory,
            "violations": violations,
        });
        drop(seen);
        let text = serde_json::to_string_pretty(&report).map_err(|e| e.to_string())?;
        std::fs::write(self.out.join("report.json"), format!("{text}\n"))
            .map_err(|e| e.to_string())?;
        let md = markdown(&report);
        std::fs::write(self.out.join("report.md"), &md).map_err(|e| e.to_string())?;
        println!("{md}");
        println!("report: {}", self.out.join("report.md").display());
        let unrecovered = faults.iter().any(|f| f.recovered_after_s.is_none());
        Ok(violations.is_empty() && !unrecovered)
    }

    fn at(&self, t_ns: u64) -> f64 {
        let now = monotonic_ns();
        self.secs() - now.saturating_sub(t_ns) as f64 * 1e-9
    }

    /// herbd's logs against the bus: every status event in a log was seen on the bus, and
    /// every one seen on the bus is in a log, but for those sent in the 2 s before herbd was
    /// killed (a SIGKILL loses what its log writer had not written). Also counts the journal's
    /// troubles and the jobs taken up from it.
    fn compare_logs(&self) -> (Vec<String>, u32, u32) {
        let mut logged: BTreeMap<Event, i64> = BTreeMap::new();
        let (mut set_aside, mut recovered) = (0, 0);
        for n in 1..=self.herbd.incarnations {
            let text = std::fs::read_to_string(self.herbd.log(n)).unwrap_or_default();
            for line in text.lines() {
                set_aside += line.contains("event=journal_set_aside") as u32;
                recovered += line.contains("event=job_recovered") as u32;
                if let Some(e) = parse_log_line(line) {
                    *logged.entry(e).or_default() += 1;
                }
            }
        }
        let seen = self.observer.seen.lock().unwrap_or_else(|e| e.into_inner());
        let mut excused: BTreeMap<Event, i64> = BTreeMap::new();
        let mut on_bus: BTreeMap<Event, i64> = BTreeMap::new();
        for (t, e) in &seen.events {
            *on_bus.entry(e.clone()).or_default() += 1;
            if self
                .herbd_kills
                .iter()
                .any(|k| *k >= *t && k - t < 2_000_000_000)
            {
                *excused.entry(e.clone()).or_default() += 1;
            }
        }
        drop(seen);
        let mut out = Vec::new();
        for (e, n) in &logged {
            let b = on_bus.get(e).copied().unwrap_or(0);
            if *n > b {
                out.push(format!(
                    "herbd's log has {e:?} {n} time(s), the bus {b}: the log says what herbd did not publish"
                ));
            }
        }
        for (e, b) in &on_bus {
            let n = logged.get(e).copied().unwrap_or(0);
            if *b > n + excused.get(e).copied().unwrap_or(0) {
                out.push(format!(
                    "the bus had {e:?} {b} time(s), herbd's log {n}: the log lost events"
                ));
            }
        }
        (out, set_aside, recovered)
    }

    /// Memory and open files over the longest herbd incarnation and loopback incarnation:
    /// the median of the last quarter against the second quarter (the first is warm-up).
    fn memory_verdict(&self) -> serde_json::Value {
        let mut out = serde_json::Map::new();
        let mut violation = None;
        for name in ["herbd", "loopback"] {
            let mut by_inc: BTreeMap<u32, Vec<(f64, u64, u64)>> = BTreeMap::new();
            for (t, n, inc, rss, fds) in &self.memory {
                if *n == name {
                    by_inc.entry(*inc).or_default().push((*t, *rss, *fds));
                }
            }
            let Some((inc, s)) = by_inc.into_iter().max_by_key(|(_, s)| s.len()) else {
                continue;
            };
            let span = s.last().map_or(0.0, |l| l.0) - s[0].0;
            let q = s.len() / 4;
            let median = |v: &[(f64, u64, u64)], f: fn(&(f64, u64, u64)) -> u64| {
                let mut x: Vec<u64> = v.iter().map(f).collect();
                x.sort_unstable();
                x.get(x.len() / 2).copied().unwrap_or(0)
            };
            let (rss_a, rss_b, fd_a, fd_b) = if q >= 2 {
                (
                    median(&s[q..2 * q], |x| x.1),
                    median(&s[s.len() - q..], |x| x.1),
                    median(&s[q..2 * q], |x| x.2),
                    median(&s[s.len() - q..], |x| x.2),
                )
            } else {
                (0, 0, 0, 0)
            };
            let judged = span >= 240.0 && q >= 2;
            let grew = rss_b.saturating_sub(rss_a);
            if judged && (grew > 65_536 && grew * 5 > rss_a) {
                violation = Some(format!(
                    "{name}'s memory grew from {rss_a} to {rss_b} KiB over one incarnation"
                ));
            }
            if judged && fd_b > fd_a + 8 {
                violation = Some(format!(
                    "{name}'s open files grew from {fd_a} to {fd_b} over one incarnation"
                ));
            }
            out.insert(
                name.into(),
                json!({
                    "incarnation": inc, "span_s": span, "samples": s.len(), "judged": judged,
                    "rss_kib_second_quarter": rss_a, "rss_kib_last_quarter": rss_b,
                    "fds_second_quarter": fd_a, "fds_last_quarter": fd_b,
                    "rss_kib_min": s.iter().map(|x| x.1).min(),
                    "rss_kib_max": s.iter().map(|x| x.1).max(),
                }),
            );
        }
        if let Some(v) = violation {
            out.insert("violation".into(), json!(v));
        }
        serde_json::Value::Object(out)
    }
}

/// The status event a line of herbd's log reports (`event=placed job=7 object=2/5 ...`).
fn parse_log_line(line: &str) -> Option<Event> {
    let field = |k: &str| {
        line.split_whitespace()
            .find_map(|w| w.strip_prefix(k)?.strip_prefix('='))
    };
    let name = field("event")?;
    let name = [
        "accepted",
        "decided",
        "placed",
        "fault",
        "braked",
        "resumed",
        "job_done",
        "job_failed",
        "shutdown",
        "job_cancelled",
        "skipped",
        "awaiting_object",
    ]
    .into_iter()
    .find(|n| *n == name)?;
    let job = field("job").and_then(|j| j.parse().ok()).unwrap_or(0);
    let object = field("object")
        .and_then(|o| o.split_once('/'))
        .and_then(|(i, _)| i.parse().ok())
        .unwrap_or(0);
    Some(Event { name, job, object })
}

/// Publishes `n` heightmap frames with a non-finite cell, one every `every`, from a camera
/// publisher of its own (herbd must drop and count each).
fn bad_frames(prefix: &str, n: u32, every: Duration) -> Result<u32, String> {
    let services = herb_ipc::Services::new(prefix).map_err(|e| e.to_string())?;
    let bus =
        herb_ipc::bus::Bus::open("herb-chaos-camera", &services).map_err(|e| e.to_string())?;
    let camera = herb_adapter::CameraPort::open(&bus).map_err(|e| e.to_string())?;
    let cell_m = herb_core::ObsLayout::CELL_M;
    let spec = herb_core::GridSpec::for_box(cell_m).map_err(|e| e.to_string())?;
    let mut cells = vec![0.0f32; spec.len()];
    let mut sent = 0;
    for i in 0..n {
        cells[(i as usize * 7919) % spec.len()] = if i % 2 == 0 { f32::NAN } else { 5.0 };
        let frame = herb_adapter::Heightmap {
            stamp_ns: monotonic_ns(),
            nx: spec.nx as u32,
            ny: spec.ny as u32,
            cell_m,
            objects: 0,
            cells: &cells,
        };
        if camera.publish(u64::from(i) + 1, &frame).is_ok() {
            sent += 1;
        }
        std::thread::sleep(every);
    }
    Ok(sent)
}

/// The report as Markdown.
fn markdown(r: &serde_json::Value) -> String {
    let mut s = String::new();
    let v = |k: &str| r[k].to_string();
    s.push_str(&format!(
        "# Chaos soak: {} minutes, seed {}\n\n- jobs accepted: {}; their ends: {}\n- objects placed: {}\n- herbd incarnations: {}, loopback incarnations: {}\n- herbd's exit on the final SIGTERM: {:.2} s, code {}\n- commands checked: {} (compared with the measured arm: {}, farthest {:.4} rad)\n- jobs taken up from herbd's journal: {}\n\n",
        v("minutes"),
        v("seed"),
        v("jobs_accepted"),
        r["job_ends"],
        v("objects_placed"),
        v("herbd_incarnations"),
        v("loopback_incarnations"),
        r["herbd_sigterm_s"].as_f64().unwrap_or(0.0),
        v("herbd_exit"),
        r["invariants"]["commands_checked"],
        r["invariants"]["commands_compared_with_the_arm"],
        r["invariants"]["max_command_offset_rad"].as_f64().unwrap_or(0.0),
        r["invariants"]["jobs_recovered_from_the_journal"],
    ));
    s.push_str("| fault | injected | recovered without a person | slowest recovery (s) |\n| --- | ---: | ---: | ---: |\n");
    for k in r["faults_by_kind"].as_array().into_iter().flatten() {
        s.push_str(&format!(
            "| {} | {} | {} | {:.1} |\n",
            k["kind"].as_str().unwrap_or("?"),
            k["injected"],
            k["recovered"],
            k["slowest_recovery_s"].as_f64().unwrap_or(0.0)
        ));
    }
    s.push_str(&format!(
        "\nArm sagged past herbd's limits (OutsideLimits faults): {}\n\nMemory: {}\n\n",
        r["outside_limits_faults_after_sag"], r["memory"]
    ));
    let viol = r["violations"].as_array().cloned().unwrap_or_default();
    if viol.is_empty() {
        s.push_str("Violations: none\n");
    } else {
        s.push_str(&format!("Violations ({}):\n", viol.len()));
        for x in viol.iter().take(50) {
            s.push_str(&format!("- {}\n", x.as_str().unwrap_or("?")));
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_log_line_is_read_as_the_bus_event_it_reports() {
        let e = parse_log_line(
            "2026-12-07T20:12:39.238Z herbd: event=placed job=143 object=1/23 placed=1/23",
        )
        .unwrap();
        assert_eq!(
            e,
            Event {
                name: "placed",
                job: 143,
                object: 1
            }
        );
        let e =
            parse_log_line("herbd: event=job_done job=9 placed=3/3 decision_wait_ms=0").unwrap();
        assert_eq!((e.name, e.job, e.object), ("job_done", 9, 0));
        assert!(parse_log_line("herbd: event=stats cycles=10").is_none());
        assert!(parse_log_line("herbd: event=fault job=2 fault=Stop object=none").is_some());
    }
}
