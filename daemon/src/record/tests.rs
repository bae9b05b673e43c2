//! The run log written by the writer thread and read back.

use super::*;
use herb_ipc::{Header, HeightmapFrame, JointState, Payload};
use herb_robot::kinematics::DOF;
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::Duration;

fn js(seq: u64) -> JointState {
    JointState {
        header: Header::at(seq, 1000 + seq),
        position: [0.1 * seq as f64; DOF],
        velocity: [f64::from_bits(0x7ff8_0000_0000_0042); DOF],
    }
}

fn header() -> RunHeader {
    RunHeader {
        herbd: "test".into(),
        cpu: cpu_identity(),
        started_unix_s: 42,
        config_toml: "[loop]\nrate_hz = 1000.0\n".into(),
        catalog: 1,
        policy: 2,
        sequence: 3,
        segment: 0,
    }
}

fn dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("herb-record-{}-{tag}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

#[test]
fn a_recording_reads_back_record_for_record_and_bit_for_bit() {
    let d = dir("rt");
    let rec = start(
        RecordOptions {
            dir: d.clone(),
            segment_bytes: 1 << 30,
            keep_bytes: 1 << 30,
        },
        header(),
    )
    .unwrap();
    let Recording {
        mut recorder,
        frames,
        writer,
        stop,
    } = rec;
    let mut frame: Box<HeightmapFrame> =
        HeightmapFrame::from_bytes(&vec![0u8; std::mem::size_of::<HeightmapFrame>()])
            .unwrap()
            .into();
    frame.nx = 3;
    frame.ny = 2;
    frame.data[5] = 0.25;
    for i in 1..=50u64 {
        recorder.push(LoopRec::Cycle { now: i * 1000 });
        recorder.push(LoopRec::Js {
            publisher: 7,
            received: i,
            m: js(i),
        });
        recorder.push(LoopRec::Tick {
            stop: i == 50,
            digest: i * 3,
        });
    }
    recorder.push(LoopRec::Resp(RespRec { digest: 9 }));
    recorder.push(LoopRec::Decision(DecisionRec {
        digest: 11,
        allowed: 6,
        decision_ns: 400_000,
    }));
    frames(0, Some(&frame));
    frames(1, None);
    frames(2, Some(&frame));
    std::thread::sleep(Duration::from_millis(50));
    stop.store(true, Ordering::Relaxed);
    let files = writer.join().unwrap().unwrap();
    assert_eq!(files.len(), 1);
    let log = Log::read(&files[0]).unwrap();
    assert_eq!(log.header, header());
    assert!(log.incomplete.is_none());
    assert_eq!(log.entries.len(), 152);
    let Entry::Js(p, r, m) = log.entries[1] else {
        panic!("{:?}", log.entries[1])
    };
    assert_eq!((p, r), (7, 1));
    assert_eq!(m.as_bytes(), js(1).as_bytes(), "NaN payloads kept");
    assert!(matches!(log.entries[149], Entry::Tick(true, 150)));
    assert!(matches!(
        log.entries[150],
        Entry::Resp(RespRec { digest: 9 })
    ));
    assert!(matches!(
        log.entries[151],
        Entry::Decision(DecisionRec {
            digest: 11,
            allowed: 6,
            decision_ns: 400_000
        })
    ));
    // Frames: two decisions made on the same frame, stored once.
    assert_eq!(log.frames.len(), 1);
    assert_eq!(log.decision_frames.get(&1), Some(&None));
    let f0 = log.decision_frames[&0].unwrap();
    assert_eq!(log.decision_frames[&2], Some(f0));
    assert_eq!(log.frames[&f0].cells(), frame.cells());

    // A torn tail: what comes before it is read, and the log says where it ends.
    let data = std::fs::read(&files[0]).unwrap();
    let torn = d.join("torn.log");
    std::fs::write(&torn, &data[..data.len() - 3]).unwrap();
    let log = Log::read(&torn).unwrap();
    assert!(log.incomplete.unwrap().contains("torn"));
    // Cut at a record's boundary (herbd killed between two writes): every record reads, and
    // the missing end record says the log is incomplete.
    let end = super::format::FRAMING;
    std::fs::write(&torn, &data[..data.len() - end]).unwrap();
    let log = Log::read(&torn).unwrap();
    assert_eq!(log.entries.len(), 152);
    assert!(log.incomplete.unwrap().contains("no end record"));
    // A flipped bit: a CRC error.
    let mut bad = data.clone();
    let n = bad.len();
    bad[n - 30] ^= 1;
    std::fs::write(&torn, &bad).unwrap();
    assert!(
        Log::read(&torn)
            .unwrap()
            .incomplete
            .unwrap()
            .contains("CRC")
    );
    // Not a log.
    std::fs::write(&torn, b"hello").unwrap();
    assert!(
        Log::read(&torn)
            .unwrap_err()
            .to_string()
            .contains("not a HERB run log")
    );
    // A log of another format: named, with its version, never read as this one.
    let mut old = data.clone();
    old[8..12].copy_from_slice(&1u32.to_le_bytes());
    std::fs::write(&torn, &old).unwrap();
    let e = Log::read(&torn).unwrap_err().to_string();
    assert!(
        e.contains(&torn.display().to_string()) && e.contains("run log format 1"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn segments_rotate_between_jobs_and_the_oldest_are_deleted() {
    let d = dir("rot");
    let Recording {
        mut recorder,
        writer,
        stop,
        ..
    } = start(
        RecordOptions {
            dir: d.clone(),
            segment_bytes: 20_000,
            keep_bytes: 50_000,
        },
        header(),
    )
    .unwrap();
    let cfg = crate::config::Config::default();
    let buf = || Box::new(crate::plan::MotionPlan::with_capacity(1));
    let params = crate::job::JobParams {
        timeouts: (&cfg.timeouts).into(),
        lower: cfg.limits.lower,
        upper: cfg.limits.upper,
        catalog_len: 24,
        grasp_retries: 1,
        decision_timeout_ns: 10_000_000_000,
        arm_range: herb_robot::motion::baxter_left_arm_range(),
        outside: crate::config::OutsideLimits::Recover,
    };
    let snap = crate::job::Job::new(params, buf(), buf())
        .snapshot()
        .expect("idle");
    let mut rotations = 0;
    for i in 1..=2000u64 {
        recorder.push(LoopRec::Cycle { now: i });
        recorder.push(LoopRec::Js {
            publisher: 1,
            received: i,
            m: js(i),
        });
        if recorder.wants_snapshot() {
            recorder.snapshot(
                Sent {
                    requests: i,
                    decisions: i / 2,
                },
                snap,
            );
            rotations += 1;
        }
        if i % 100 == 0 {
            std::thread::sleep(Duration::from_millis(120));
        }
    }
    stop.store(true, Ordering::Relaxed);
    let files = writer.join().unwrap().unwrap();
    assert!(rotations >= 3, "{rotations}");
    let on_disk: Vec<_> = std::fs::read_dir(&d).unwrap().collect();
    let closed: u64 = files[..files.len() - 1]
        .iter()
        .filter_map(|p| std::fs::metadata(p).ok())
        .map(|m| m.len())
        .sum();
    assert_eq!(on_disk.len(), files.len());
    assert!(on_disk.len() < rotations + 1, "old segments deleted");
    assert!(
        closed <= 50_000,
        "closed segments within keep_bytes: {closed}"
    );
    // A later segment starts from its snapshot.
    let last = Log::read(files.last().unwrap()).unwrap();
    let (before, s) = last.snapshot.expect("a snapshot");
    assert!(before.requests > 0 && before.decisions > 0);
    assert_eq!(s, snap);
    assert!(last.header.segment >= 3);
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn a_snapshot_reads_back_bit_for_bit() {
    use crate::job::{Commands, Inputs, JobRecord, JobSnapshot, ObjectPhase, Placement};
    use herb_ipc::{ArmBlocker, Fault, GripperAction, GripperState, InOrder};
    let mut job = JobRecord::NONE;
    job.count = 3;
    job.objects[..3].copy_from_slice(&[4, 5, 6]);
    // A job that failed before it was ordered: the machine still holds an older order.
    job.order[..3].copy_from_slice(&[9, 1, 2]);
    job.index = 1;
    job.done = 1;
    job.holding = true;
    job.phase = ObjectPhase::Idle;
    job.placement = Some(Placement {
        index: 1,
        pose: [0.1, -0.2, 0.05, std::f32::consts::PI],
        release_q: Some([0.1 + 0.2, -1.0 / 3.0, 0.3, 0.4, 0.5, 0.6, 1e-300]),
    });
    let gs = GripperState::from_bytes(&[0u8; std::mem::size_of::<GripperState>()]).unwrap();
    let s = JobSnapshot {
        inputs: Inputs {
            js: Some(JointState {
                velocity: [0.25; DOF],
                ..js(3)
            }),
            js_at: 11,
            js_order: InOrder::with_last(Some((7, 3, 1003))),
            gs: Some(gs),
            gs_at: 12,
            gs_order: InOrder::default(),
            arm_blocker: ArmBlocker::from_code(2).unwrap(),
            arm_at: 13,
            arm_order: InOrder::with_last(Some((u128::MAX, 1, 2))),
            hm_rx_at: 14,
            hm_stamp: 15,
            rejected: 16,
            rejected_requests: 21,
        },
        commands: Commands {
            cmd: herb_robot::motion::Setpoint::at_rest([0.7; DOF]),
            grip_cmd: GripperAction::Close,
            grip_object: 5,
            grip_due: true,
            grip_sent_at: 17,
            last_heartbeat: 18,
            limit_holds: 19,
            from: [0.9; DOF],
        },
        job,
        release_stamp: 20,
        fault: Fault::MissedGrasp,
        stopping: true,
    };
    let sent = Sent {
        requests: 42,
        decisions: 17,
    };
    let b = super::format::encode_snapshot(sent, &s);
    let (before, back) = super::format::decode_snapshot(&b).unwrap();
    assert_eq!((before, back), (sent, s));
    // Cut short or with a byte too many: an error, never a different state.
    assert!(super::format::decode_snapshot(&b[..b.len() - 1]).is_err());
    let mut long = b.clone();
    long.push(0);
    assert!(super::format::decode_snapshot(&long).is_err());
}
