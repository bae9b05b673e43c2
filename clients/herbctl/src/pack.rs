//! `herbctl pack`: submits a job and follows it to its end, printing each object, the end of
//! each and a verdict. Ctrl-C (or SIGTERM, SIGHUP) and `--timeout` cancel the job and wait for
//! herbd to confirm it (the arm brakes and retreats); `--detach` leaves the job running.

use crate::words::{self, placed_count};
use crate::{Cli, connect, id_of, interrupt, name};
use herb_client::{CancelError, Client, JobEvent, SubmitError, WatchError};
use herb_core::{Catalog, GridSpec, Heightmap, boxed, paths};
use herb_ipc::{Fault, HeightmapFrame, JobState, RejectReason, SimOutcome, Status, StatusEvent};
use herb_picture::{PictureObject, write_pack_picture};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// How long herbctl waits for herbd to confirm a cancel (`JobCancelled`) once it accepted it:
/// herbd's brake (under a second) and its retreat straight up (a few seconds at the shipped
/// joint limits), and a margin.
pub(crate) const CANCEL_WAIT: Duration = Duration::from_secs(15);

/// What `herbctl pack` was asked to do.
#[derive(Debug)]
pub(crate) struct PackArgs<'a> {
    /// A BoxED session whose objects to pack.
    pub session: &'a Option<String>,
    /// Catalog ids (when no session).
    pub ids: &'a [String],
    /// Where to draw the final pack.
    pub picture: &'a Option<PathBuf>,
    /// Submitting and following end after this long (s); the job is then cancelled.
    pub timeout: f64,
    /// The summary as one JSON line.
    pub json: bool,
    /// A person feeds the pick station: each grasp waits for a confirmation.
    pub operator: bool,
    /// Confirm by itself this long (s) after asking, instead of waiting for Enter.
    pub operator_wait: Option<f64>,
    /// How long to wait for a lost herbd to come back with the job (s).
    pub reconnect: f64,
    /// Return once herbd accepted the job, leaving it running.
    pub detach: bool,
}

/// Why herbctl cancels its job.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Why {
    /// Ctrl-C, SIGTERM or SIGHUP.
    Signal,
    /// `--timeout` ran out.
    Timeout,
}

/// A cancel herbctl sent and waits to see confirmed.
#[derive(Debug)]
struct Cancelling {
    why: Why,
    /// Signals counted when it was sent: one more exits without waiting.
    signals: usize,
    /// Until when herbd's `JobCancelled` is waited for.
    deadline: Instant,
    /// The job's state and fault before the cancel (its last status), if any came.
    before: Option<(JobState, Fault)>,
    /// A `Braked` status came after the cancel.
    braked: bool,
}

impl Cancelling {
    /// herbctl's exit code when it ends on this cancel.
    fn exit_code(&self) -> u8 {
        match self.why {
            Why::Signal => interrupt::EXIT_CODE,
            Why::Timeout => 1,
        }
    }
}

/// The catalog type indices of the job and how to name it.
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

fn pct(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// Sends the cancel of job `job_id` (`why`), `last` being the job's last status. The cancel
/// to wait for, or, when herbd cannot be asked, the exit code (the reason printed).
fn begin_cancel(
    client: &Client,
    prefix: &str,
    job_id: u64,
    why: Why,
    last: Option<&Status>,
) -> Result<Cancelling, u8> {
    let c = Cancelling {
        why,
        // A second signal that came before this one was seen still exits without waiting.
        signals: match why {
            Why::Signal => 1,
            Why::Timeout => interrupt::count(),
        },
        deadline: Instant::now() + CANCEL_WAIT,
        before: last.map(|s| {
            (
                JobState::from_code(s.state).unwrap_or(JobState::Idle),
                Fault::from_code(s.fault).unwrap_or(Fault::None),
            )
        }),
        braked: false,
    };
    match client.cancel(job_id) {
        Ok(()) => Ok(c),
        // It ended meanwhile: its end is on its way.
        Err(CancelError::NotRunning { .. }) => Ok(c),
        Err(CancelError::Refused(RejectReason::ShuttingDown)) => {
            println!("herbd is shutting down: it brakes and ends the job itself");
            Ok(c)
        }
        Err(e) => {
            eprintln!(
                "herbctl: error: job {job_id} could not be cancelled: {e}; it may still be running: once herbd answers (`herbctl --prefix {prefix} status`), cancel it with `{}`",
                words::cancel_command(prefix, job_id)
            );
            Err(c.exit_code())
        }
    }
}

/// Interrupted before herbd accepted job `job_id`: nothing to cancel, unless herbd left a
/// request unanswered and may have taken the job after all (then it is cancelled). The cancel
/// to wait for, or the exit code.
fn stopped_before_acceptance(
    client: &Client,
    prefix: &str,
    job_id: u64,
    unanswered: bool,
) -> Result<Cancelling, u8> {
    let none = || {
        println!("interrupted before herbd accepted job {job_id}: no job was started");
        Err(interrupt::EXIT_CODE)
    };
    if !unanswered {
        return none();
    }
    match client.cancel(job_id) {
        Err(CancelError::NotRunning { .. }) => none(),
        Ok(()) => {
            println!("interrupted: herbd had taken job {job_id} after all: cancelling it");
            Ok(Cancelling {
                why: Why::Signal,
                signals: 1,
                deadline: Instant::now() + CANCEL_WAIT,
                before: None,
                braked: false,
            })
        }
        Err(e) => {
            eprintln!(
                "herbctl: interrupted: herbd did not answer job {job_id}'s request and cannot be asked now ({e}); it may still start the job: see `herbctl --prefix {prefix} status` and cancel it with `{}`",
                words::cancel_command(prefix, job_id)
            );
            Err(interrupt::EXIT_CODE)
        }
    }
}

/// `--detach`: what to run next.
fn print_detached(prefix: &str, job_id: u64, objects: usize, json: bool) {
    let (follow, cancel) = (
        words::watch_command(prefix),
        words::cancel_command(prefix, job_id),
    );
    if json {
        println!(
            "{}",
            serde_json::json!({
                "job_id": job_id,
                "detached": true,
                "objects": objects,
                "watch": follow,
                "cancel": cancel,
            })
        );
    } else {
        let noun = if objects == 1 { "object" } else { "objects" };
        println!("job {job_id} accepted ({objects} {noun}): it runs on without herbctl");
        println!("follow it: {follow}");
        println!("cancel it: {cancel}");
    }
}

/// `herbctl pack`: the exit code (0 done; 1 not done: failed, cancelled, timed out, herbd shut
/// down; 130 interrupted by a signal), or an error (exit 2).
pub(crate) fn pack(cli: &Cli, catalog: &Catalog, a: &PackArgs<'_>) -> Result<u8, String> {
    let PackArgs {
        session,
        ids,
        picture,
        timeout,
        json,
        operator,
        operator_wait,
        reconnect,
        detach,
    } = *a;
    let operator_wait = match operator_wait {
        None => None,
        Some(w) if w.is_finite() && (0.0..=3600.0).contains(&w) => Some(Duration::from_secs_f64(w)),
        Some(w) => return Err(format!("--operator-wait {w} outside 0..=3600 s")),
    };
    // The operator's Enter presses, read off the main thread (a closed input confirms nothing).
    let enter = (operator && operator_wait.is_none()).then(crate::operator::enter_presses);
    let mut awaiting: Option<crate::operator::Awaiting> = None;
    if !(reconnect.is_finite() && (0.0..=3600.0).contains(&reconnect)) {
        return Err(format!("--reconnect {reconnect} outside 0..=3600 s"));
    }
    let deadline = Duration::try_from_secs_f64(timeout)
        .ok()
        .filter(|d| !d.is_zero())
        .and_then(|d| Instant::now().checked_add(d))
        .ok_or_else(|| format!("--timeout {timeout}: give a positive number of seconds"))?;
    let reconnect_d = Duration::from_secs_f64(reconnect);
    let (objects, what) = objects_of(cli, session, ids, catalog)?;
    let prefix = cli.prefix.as_str();
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
    // From now on a signal is counted, not fatal: before herbd accepts the job it ends the
    // submission, after it cancels the job.
    if let Err(e) = interrupt::catch() {
        eprintln!(
            "herbctl: warning: signals cannot be caught ({e}): Ctrl-C would end herbctl without cancelling the job"
        );
    }
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
    // The reason last said, and the tries it has gone without its detail.
    let mut not_ready: Option<(Fault, u32)> = None;
    let flags = if operator {
        herb_ipc::PackJobRequest::CONFIRM_PICKS
    } else {
        0
    };
    let submitted = client.submit_or_stop(
        job_id,
        &objects,
        flags,
        deadline,
        |why| {
            // A joint outside its limits: the heartbeat says which, where, and what to do. A
            // heartbeat that does not come in time (a loaded machine) is asked for again at the
            // next refusal, and the reason said without it after a few.
            let limits = matches!(why, Fault::OutsideLimits | Fault::BeyondArmLimits);
            let tries = match not_ready {
                Some((f, _)) if f == why && !limits => return,
                Some((f, n)) if f == why => n,
                _ => 0,
            };
            if tries == u32::MAX {
                return; // said, with its detail or without
            }
            let detail = limits
                .then(|| client.status(Duration::from_millis(500)).ok())
                .flatten()
                .and_then(|s| s.limit_words());
            match detail {
                Some(w) => {
                    println!("robot not ready: {}: {w}; waiting", why.describe());
                    not_ready = Some((why, u32::MAX));
                }
                None if limits && tries < 3 => not_ready = Some((why, tries + 1)),
                None => {
                    println!("robot not ready: {}; waiting", why.describe());
                    not_ready = Some((why, u32::MAX));
                }
            }
        },
        || interrupt::count() > 0,
    );
    let mut cancel: Option<Cancelling> = None;
    match submitted {
        Ok(()) => {
            eprintln!("herbctl: accepted");
            if detach {
                print_detached(prefix, job_id, objects.len(), json);
                return Ok(0);
            }
        }
        Err(SubmitError::Stopped { unanswered }) => {
            match stopped_before_acceptance(&client, prefix, job_id, unanswered) {
                Ok(c) => cancel = Some(c),
                Err(code) => return Ok(code),
            }
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
    }

    let job_t0 = Instant::now();
    let mut decision_ms = Vec::new();
    let mut faults = Vec::new();
    let mut last: Option<Status> = None;
    let mut placed = 0u32;
    let mut skipped = 0u32;
    let mut total = objects.len() as u32;
    let mut ok = None;
    // The fault that stopped the job, until it resumes: what a `Braked` is about.
    let mut stopped_by: Option<Fault> = None;
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
    let mut watch = match &cancel {
        Some(c) => client.watch(job_id, c.deadline, Duration::ZERO),
        None => client.watch(job_id, deadline, reconnect_d),
    };
    let cancel_it = words::cancel_command(prefix, job_id);
    loop {
        // A signal cancels the job; another one while it is cancelled exits without waiting.
        let signals = interrupt::count();
        match &cancel {
            Some(c) if signals > c.signals => {
                eprintln!(
                    "herbctl: interrupted again: exiting without waiting; job {job_id} may still be running: cancel it with `{cancel_it}`"
                );
                return Ok(interrupt::EXIT_CODE);
            }
            Some(c) if Instant::now() > c.deadline => {
                eprintln!(
                    "herbctl: error: herbd did not confirm within {} s that job {job_id} was cancelled; it may still be running: see `herbctl --prefix {prefix} status`, cancel it with `{cancel_it}`",
                    CANCEL_WAIT.as_secs()
                );
                return Ok(c.exit_code());
            }
            None if signals > 0 && ok.is_none() => {
                let arm = if last.is_some_and(|s| s.state == JobState::Faulted as u32) {
                    "it ends where the arm stands"
                } else {
                    "the arm brakes and retreats"
                };
                println!(
                    "interrupted: cancelling job {job_id} ({arm}; interrupt again to exit without waiting)"
                );
                match begin_cancel(&client, prefix, job_id, Why::Signal, last.as_ref()) {
                    Ok(c) => cancel = Some(c),
                    Err(code) => return Ok(code),
                }
            }
            _ => {}
        }
        let s = match watch.poll() {
            Ok(Some(JobEvent::Status(s))) => s,
            Ok(Some(JobEvent::Lost { silent_for })) => {
                if let Some(c) = &cancel {
                    eprintln!(
                        "herbctl: error: herbd lost while job {job_id} was being cancelled (no status for {:.1} s); if herbd restarts with its job journal it takes the job up again: cancel it then with `{cancel_it}`",
                        silent_for.as_secs_f64()
                    );
                    return Ok(c.exit_code());
                }
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
                if let Some(a) = awaiting
                    && cancel.is_none()
                    && a.due(enter.as_ref())
                {
                    awaiting = None;
                    match client.confirm_pick(job_id, a.index, a.attempt) {
                        Ok(()) => println!("confirmed: the arm descends to the pick station"),
                        Err(e) => eprintln!(
                            "herbctl: the confirmation was not taken ({e}); herbd no longer waits for object {}, try {}",
                            a.index + 1,
                            a.attempt + 1
                        ),
                    }
                }
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
                if cancel.is_none() {
                    println!(
                        "timed out after {timeout} s: cancelling job {job_id}; {}",
                        placed_count(placed, total, skipped)
                    );
                    match begin_cancel(&client, prefix, job_id, Why::Timeout, last.as_ref()) {
                        Ok(c) => cancel = Some(c),
                        Err(code) => return Ok(code),
                    }
                }
                // That watch ended at its deadline: the cancel is followed to its own.
                if let Some(c) = &cancel {
                    watch = client.watch(job_id, c.deadline, Duration::ZERO);
                }
                continue;
            }
            Err(WatchError::CameBackWithoutJob { .. }) => {
                return Err(format!(
                    "herbd came back without job {job_id} (no job journal, or the job was abandoned); {}",
                    placed_count(placed, total, skipped)
                ));
            }
            Err(WatchError::DaemonLost { silent_for, .. }) => {
                if let Some(c) = &cancel {
                    eprintln!(
                        "herbctl: error: herbd lost while job {job_id} was being cancelled (no status for {:.1} s); if herbd restarts with its job journal it takes the job up again: cancel it then with `{cancel_it}`",
                        silent_for.as_secs_f64()
                    );
                    return Ok(c.exit_code());
                }
                let at = last.map_or(String::from("no status yet"), |s| {
                    format!(
                        "object {}/{total} ({}), state {:?}",
                        s.object_index + 1,
                        name(catalog, s.object_type),
                        JobState::from_code(s.state).unwrap_or(JobState::Idle)
                    )
                });
                return Err(format!(
                    "daemon lost: no status from herbd for {:.1} s (it heartbeats at 10 Hz); job {job_id}: {}, last known {at}",
                    silent_for.as_secs_f64(),
                    placed_count(placed, total, skipped)
                ));
            }
        };
        last = Some(s);
        total = s.objects_total;
        let fault = Fault::from_code(s.fault).unwrap_or(Fault::None);
        let before_cancel = if cancel.is_some() {
            " before the cancel took effect"
        } else {
            ""
        };
        match StatusEvent::from_code(s.event) {
            Some(StatusEvent::AwaitingObject) => {
                let what = name(catalog, s.object_type);
                let again = if s.attempt > 0 {
                    " again (the pick is tried again)"
                } else {
                    ""
                };
                match operator_wait {
                    Some(w) => println!(
                        "operator: put {what} at the pick station{again}; the arm descends in {:.1} s",
                        w.as_secs_f64()
                    ),
                    None => println!(
                        "operator: put {what} at the pick station{again}, then press Enter (the arm waits above the station)"
                    ),
                }
                if let Some(rx) = &enter {
                    // Enter pressed before this question does not answer it.
                    while rx.try_recv().is_ok() {}
                }
                awaiting = Some(crate::operator::Awaiting::new(&s, operator_wait));
            }
            Some(StatusEvent::Decided) => {
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
                println!(
                    "object {:>2}/{total} placed ({}); {}",
                    s.object_index + 1,
                    name(catalog, s.object_type),
                    placed_count(placed, total, skipped)
                );
            }
            Some(StatusEvent::Fault) => {
                faults.push(format!("{fault:?}"));
                match s.limit_words() {
                    // Not a halt when the job goes on: herbd brings the joint back itself.
                    Some(w) => println!("FAULT {fault:?}: {w}"),
                    None => {
                        stopped_by = Some(fault);
                        println!("FAULT {fault:?} ({}): halting", fault.describe());
                    }
                }
            }
            Some(StatusEvent::Skipped) => {
                skipped += 1;
                // A skipped object stays at the pick station, in the way of the next.
                println!(
                    "skipped object {}/{total} ({}): {}; take it away from the pick station",
                    s.object_index + 1,
                    name(catalog, s.object_type),
                    fault.describe()
                );
            }
            Some(StatusEvent::Braked) => {
                if let Some(c) = &mut cancel {
                    c.braked = true;
                }
                println!("{}", words::stopped(stopped_by));
            }
            Some(StatusEvent::Resumed) => {
                stopped_by = None;
                println!("resumed");
            }
            Some(StatusEvent::JobDone) => {
                if cancel.is_some() {
                    println!("job {job_id} done{before_cancel}");
                }
                ok = Some(true)
            }
            Some(StatusEvent::JobFailed) => {
                println!("job failed{before_cancel}: {fault:?}");
                ok = Some(false)
            }
            Some(StatusEvent::JobCancelled) => {
                let count = placed_count(placed, total, skipped);
                match &cancel {
                    Some(c) => println!(
                        "job {job_id} cancelled: {}; {count}",
                        words::cancel_outcome(c.before, c.braked, fault)
                    ),
                    None => println!("job cancelled by another client; {count}"),
                }
                ok = Some(false)
            }
            Some(StatusEvent::Shutdown) => {
                println!("herbd shut down");
                if cancel.is_some() {
                    eprintln!(
                        "herbctl: herbd shut down before job {job_id} was cancelled (it braked on its own stop); if it restarts with its job journal it takes the job up again: cancel it then with `{cancel_it}`"
                    );
                }
                ok = Some(false)
            }
            _ => {}
        }
    }
    // The last release's settle: wait briefly for its heightmap and outcome (not when
    // interrupted: the operator wants out).
    let t0 = Instant::now();
    while cancel.is_none() && interrupt::count() == 0 && t0.elapsed() < Duration::from_millis(1500)
    {
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
    let Some(s) = last else {
        return Err(format!("no status of job {job_id} was received"));
    };
    let state = JobState::from_code(s.state).unwrap_or(JobState::Idle);
    let fault = Fault::from_code(s.fault).unwrap_or(Fault::None);
    let mut verdict = verdict(
        ok == Some(true),
        state,
        fault,
        placed,
        total,
        last_outcome.as_ref(),
        catalog,
    );
    if skipped > 0 {
        // Not in the box: given up after missed grasps.
        verdict.push_str(&format!("; {skipped} skipped (not packed)"));
    }
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
            let where_ = match herb_client::view::crossing(o) {
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
        "interrupted": cancel.as_ref().map(|c| match c.why {
            Why::Signal => "signal",
            Why::Timeout => "timeout",
        }),
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
        "rejected_requests": s.rejected_requests,
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
    Ok(match &cancel {
        // Interrupted: so says the exit code, even if the job ended first.
        Some(c) if c.why == Why::Signal => interrupt::EXIT_CODE,
        _ if ok == Some(true) => 0,
        _ => 1,
    })
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
        herb_client::view::outside_objects(o, &|t| id_of(catalog, t))
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
