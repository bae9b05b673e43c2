//! herbd's offline tools: `herbd replay` and `herbd explain` re-run a run log (`herbd --record`)
//! through the same job state machine, planner and decision core; `herbd calibrate-cell`
//! measures the cell with the arm moved by hand. They need herbd's own code, which is why they
//! live here and not in the client (`herbctl`).

use herb_core::{Catalog, GridSpec, Heightmap};
use herb_daemon::config::Config;
use herb_daemon::record::Log;
use herb_daemon::replay::{self, Outcome, ReplayOptions, Replayed};
use herb_ipc::{Fault, HeightmapFrame, Status, StatusEvent};
use std::path::PathBuf;
use std::process::ExitCode;

/// Type `t`'s catalog id and name (`-` if none).
fn name(catalog: &Catalog, t: u32) -> String {
    catalog.label(t)
}

/// `herbd replay`.
pub(crate) fn replay(
    boxed: Option<PathBuf>,
    path: &std::path::Path,
    force: bool,
    events: Option<&std::path::Path>,
) -> ExitCode {
    let run = || -> Result<(Outcome, Replayed, Log), String> {
        let log = Log::read(path).map_err(|e| e.to_string())?;
        let opts = ReplayOptions {
            boxed,
            force,
            explain: None,
            joint_states_every_ns: events.map(|_| EVENTS_JOINT_PERIOD_NS),
        };
        let (o, r) = replay::replay(&log, &opts).map_err(|e| e.to_string())?;
        Ok((o, r, log))
    };
    match run() {
        Err(e) => {
            eprintln!("herbd: error: {e}");
            ExitCode::from(2)
        }
        Ok((outcome, r, log)) => {
            println!(
                "{} (segment {}), recorded on {}",
                log.header.herbd, log.header.segment, log.header.cpu
            );
            if let Some(p) = events {
                match write_events(p, &log, &r) {
                    Ok(n) => println!("{n} events written to {}", p.display()),
                    Err(e) => {
                        eprintln!("herbd: error: {}: {e}", p.display());
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

/// The arm's joint states in `herbd replay --events`: at most one per 50 ms (20 Hz), as the
/// live view draws them.
const EVENTS_JOINT_PERIOD_NS: u64 = 50_000_000;

/// The cell as the run had it ([`herb_robot::model::CellModel`], from the run log's own
/// configuration), for viewers.
pub(crate) fn cell_model(cfg: &Config) -> herb_robot::model::CellModel {
    herb_robot::model::CellModel::new(&cfg.cell, &herb_robot::kinematics::Arm::baxter_left())
}

/// What the replay saw, as JSON lines for a recording, in time order: first the cell (`cell`,
/// from the run's configuration), then the statuses (heartbeats left out), the heightmap each
/// decision was made on, the arm's joint states (20 Hz) and the gripper's changes. The number
/// of lines.
fn write_events(path: &std::path::Path, log: &Log, r: &Replayed) -> std::io::Result<usize> {
    use std::io::Write;
    let cfg: Config = toml::from_str(&log.header.config_toml)
        .map_err(|e| std::io::Error::other(format!("the recorded configuration: {e}")))?;
    let mut lines: Vec<(u64, serde_json::Value)> = Vec::new();
    for (_, s) in &r.statuses {
        lines.push((
            s.header.stamp_ns,
            serde_json::json!({
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
            }),
        ));
        // The heightmap the object was decided on, at the time of its decision.
        if s.event == StatusEvent::Decided as u32
            && let Some((_, f)) = r.decision_frames.iter().find(|(i, _)| *i == s.object_index)
        {
            lines.push((
                s.header.stamp_ns,
                serde_json::json!({
                    "heightmap": {
                        "stamp_ns": s.header.stamp_ns,
                        "nx": f.nx,
                        "ny": f.ny,
                        "cell_m": f.cell_m,
                        "cells": f.cells(),
                    }
                }),
            ));
        }
    }
    for (t, q) in &r.joint_states {
        lines.push((
            *t,
            serde_json::json!({"joint_state": {"stamp_ns": t, "position": q}}),
        ));
    }
    for (t, closed, holding) in &r.gripper_states {
        lines.push((
            *t,
            serde_json::json!({"gripper": {"stamp_ns": t, "closed": closed, "holding": holding}}),
        ));
    }
    // Stable: a decision's heightmap stays after its status.
    lines.sort_by_key(|(t, _)| *t);
    let mut w = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(w, "{}", serde_json::json!({ "cell": cell_model(&cfg) }))?;
    for (_, l) in &lines {
        writeln!(w, "{l}")?;
    }
    w.flush()?;
    Ok(lines.len() + 1)
}

pub(crate) fn write_png(f: &HeightmapFrame, path: &std::path::Path) -> Result<(), String> {
    let spec = GridSpec::for_box(f.cell_m).map_err(|e| e.to_string())?;
    let hm = Heightmap::from_data(spec, f.cells().to_vec()).map_err(|e| e.to_string())?;
    if let Some(d) = path.parent() {
        let _ = std::fs::create_dir_all(d);
    }
    herb_core::image::write_heightmap_png(path, &hm, 0.3, 4).map_err(|e| e.to_string())
}

/// `herbd explain`.
pub(crate) fn explain(
    boxed: Option<PathBuf>,
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
        boxed,
        force,
        explain: Some(index),
        joint_states_every_ns: None,
    };
    let (outcome, r) = replay::replay(&log, &opts).map_err(|e| e.to_string())?;
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
        let threads = cfg.decision.search_threads();
        println!(
            "search: {} feasible candidates on the lattice; the budget allowed {allowed} rollout{} on {} thread{} (replayed as that count){}",
            rep.candidates,
            if allowed == 1 { "" } else { "s" },
            threads,
            if threads == 1 { "" } else { "s" },
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
        if rep.unsupported > 0 {
            println!(
                "support rule: {} ranked as failures (above the rim on too little of their footprint)",
                rep.unsupported
            );
        }
        if rep.live_checked > 0 {
            println!(
                "rigid pile: the best {} rolled out again on the live pile, {} passed over (an object pushed out or gone out there)",
                rep.live_checked, rep.live_rejected
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
