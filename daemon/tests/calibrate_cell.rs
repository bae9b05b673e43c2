//! `herbd calibrate-cell` against a scripted arm: the test publishes the joint states an arm
//! adapter would (the configurations that put the gripper's tip on the corners of a box at a
//! known pose, found by inverse kinematics, then on a pick station), presses Enter at each of
//! its prompts, and reads back the `[cell]` lines it prints.

use herb_core::frames::{BOX_HALF_X, BOX_HALF_Y};
use herb_ipc::bus::Bus;
use herb_ipc::{Header, JointState, Services};
use herb_robot::cell::CellConfig;
use herb_robot::kinematics::{Arm, DOF, IkOptions, LEFT_TOP_DOWN_NOMINAL};
use std::io::{BufRead, BufReader, Write};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use std::time::Duration;

#[test]
fn touched_corners_give_the_box_pose_and_the_pick_station() {
    let prefix = format!("cal{}", std::process::id());
    // The box the operator touches: origin and yaw in Baxter's base frame.
    let (origin, yaw) = ([0.58, 0.28, -0.18], 0.05f64);
    let pick = [0.45, 0.65, -0.25];
    let (hx, hy) = (f64::from(BOX_HALF_X), f64::from(BOX_HALF_Y));
    let (c, s) = (yaw.cos(), yaw.sin());
    let corner = |x: f64, y: f64| {
        [
            origin[0] + c * x - s * y,
            origin[1] + s * x + c * y,
            origin[2],
        ]
    };
    let arm = Arm::baxter_left();
    let opts = IkOptions::default();
    let q_at = |p: [f64; 3]| {
        arm.ik_top_down((p[0], p[1], p[2]), yaw, &LEFT_TOP_DOWN_NOMINAL, &opts)
            .expect("reachable")
    };
    let targets: Vec<[f64; DOF]> = [
        corner(-hx, -hy),
        corner(hx, -hy),
        corner(hx, hy),
        corner(-hx, hy),
        pick,
    ]
    .into_iter()
    .map(q_at)
    .collect();

    // The scripted adapter: publishes the current configuration at 100 Hz.
    let current = Arc::new(Mutex::new(targets[0]));
    let stop = Arc::new(AtomicBool::new(false));
    let publisher = {
        let (current, stop, prefix) = (current.clone(), stop.clone(), prefix.clone());
        std::thread::spawn(move || {
            let services = Services::new(&prefix).unwrap();
            let bus = Bus::open("scripted-arm", &services).unwrap();
            let js = bus
                .publisher::<JointState>(&services.joint_state())
                .unwrap();
            let mut seq = 0;
            while !stop.load(Ordering::Relaxed) {
                seq += 1;
                let q = *current.lock().unwrap();
                let _ = js.send_copy(JointState {
                    header: Header::now(seq),
                    position: q,
                    velocity: [0.0; DOF],
                });
                std::thread::sleep(Duration::from_millis(10));
            }
        })
    };
    let mut ctl = Command::new(env!("CARGO_BIN_EXE_herbd"))
        .args(["--prefix", &prefix, "calibrate-cell", "--corners", "4"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("herbd runs");
    let mut stdin = ctl.stdin.take().unwrap();
    let (tx, rx) = mpsc::channel();
    let stderr = BufReader::new(ctl.stderr.take().unwrap());
    std::thread::spawn(move || {
        for l in stderr.lines().map_while(Result::ok) {
            let _ = tx.send(l);
        }
    });
    let mut said = Vec::new();
    for q in &targets {
        // Wait for the prompt, move the arm there, press Enter.
        loop {
            let l = rx
                .recv_timeout(Duration::from_secs(20))
                .unwrap_or_else(|_| panic!("no prompt; herbd said {said:?}"));
            said.push(l.clone());
            if l.starts_with("Touch") {
                break;
            }
        }
        *current.lock().unwrap() = *q;
        std::thread::sleep(Duration::from_millis(100));
        stdin.write_all(b"\n").unwrap();
    }
    let out = ctl.wait_with_output().unwrap();
    stop.store(true, Ordering::Relaxed);
    publisher.join().unwrap();
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(out.status.success(), "{text}\n{said:?}");
    #[derive(serde::Deserialize)]
    struct File {
        cell: CellConfig,
    }
    let f: File = toml::from_str(&text).unwrap_or_else(|e| panic!("{e}: {text}"));
    for i in 0..3 {
        assert!((f.cell.box_origin[i] - origin[i]).abs() < 2e-3, "{text}");
        assert!((f.cell.pick_origin[i] - pick[i]).abs() < 2e-3, "{text}");
    }
    assert!((f.cell.box_yaw - yaw).abs() < 5e-3, "{text}");
    f.cell.validate().unwrap();
}

#[test]
fn without_an_arm_adapter_it_says_so() {
    let prefix = format!("calnone{}", std::process::id());
    let mut ctl = Command::new(env!("CARGO_BIN_EXE_herbd"))
        .args(["--prefix", &prefix, "calibrate-cell"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    ctl.stdin.take().unwrap().write_all(b"\n").unwrap();
    let out = ctl.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("no joint state from the arm adapter"), "{err}");
}
