//! herb-camera end to end against real ROS 1 peers: a real `rosmaster` on a free port, a rospy
//! fake camera (`fake_camera.py`, a test fixture rendering depth images of a known heightmap
//! through a tilted pinhole camera) and herb-camera; the test reads the published heightmaps
//! over iceoryx2 and compares them with the truth on the cells the camera saw.

use herb_core::ObsLayout;
use herb_core::heightmap::GridSpec;
use herb_ipc::bus::Bus;
use herb_ipc::{HeightmapFrame, Services};
use herb_testkit::ros::{Camera, RosWorld, ros_available};
use herb_testkit::{config, last_json, lines, tmp};
use std::time::{Duration, Instant};

/// Heightmaps as published, matched to the truth within 2 mm on the cells the camera saw away
/// from the blocks' edges, never below it anywhere; bad images (wrong encoding, a size other
/// than the camera info's, data short of the rows) and images before any camera info are
/// refused with a reason and counted; the image-to-heightmap latency is reported.
#[test]
fn depth_images_become_heightmaps_that_match_the_truth() {
    if !ros_available() {
        return;
    }
    let dir = tmp("ros-camera");
    let prefix = format!("cam{}", std::process::id());
    let cfg = config(&dir, &prefix, "blbf");
    let spec = GridSpec::for_box(ObsLayout::CELL_M).unwrap();
    let t = herb_testkit::two_blocks(&spec);
    let ros = RosWorld::new(&dir, None);
    let _master = ros.master("1");
    let Camera {
        mut fake,
        adapter: mut cam,
        seen: seen_file,
        report,
        ..
    } = Camera::start(&ros, &cfg, &spec, &t, 5, 1.5);
    // Camera info only after 1.5 s of images: herb-camera's subscriptions are connected well
    // before then, so it sees images without camera info (counted apart) whatever the load. Then
    // every fifth image is bad: a size, short data and an encoding case all fall in the 30
    // frames waited for below.
    let services = Services::new(&prefix).unwrap();
    let bus = Bus::open("camera-test", &services).unwrap();
    let sub = bus
        .subscriber::<HeightmapFrame>(&services.heightmap())
        .unwrap();
    // Rendering takes the fake a few seconds; then frames come at 10 Hz.
    let (mut frames, t0) = (0, Instant::now());
    let mut hm = Vec::new();
    while frames < 30 {
        if let Some(st) = fake.0.try_wait().unwrap() {
            panic!(
                "the fake camera exited ({st}): {}",
                std::fs::read_to_string(dir.join("fake_camera.log")).unwrap_or_default()
            );
        }
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "{frames} heightmaps in 60 s; herb-camera said: {}",
            std::fs::read_to_string(dir.join("herb-camera.log")).unwrap_or_default()
        );
        while let Ok(Some(s)) = sub.receive() {
            let f = s.payload();
            f.validate().expect("a valid frame");
            assert_eq!((f.nx as usize, f.ny as usize), (spec.nx, spec.ny));
            hm = f.cells().to_vec();
            frames += 1;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let seen = std::fs::read(&seen_file).unwrap();
    assert_eq!(seen.len(), spec.len());
    let (flat, worst) = herb_testkit::compare_to_truth(&spec, &t, &hm, |i| seen[i] == 1, 0.002);
    assert!(worst <= 0.002, "a seen flat cell is {worst} m off");
    assert!(flat * 10 > spec.len() * 8, "only {flat} seen flat cells");

    let rx = lines(&mut cam);
    cam.signal(libc::SIGTERM);
    assert!(cam.wait_for(Duration::from_secs(10)).success());
    let summary = last_json(&rx, "camera_final");
    fake.signal(libc::SIGTERM);
    assert!(fake.wait_for(Duration::from_secs(10)).success());
    let f: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    eprintln!(
        "{flat} seen flat cells within {worst:.4} m\nherb-camera: {summary}\nfake camera: {f}"
    );
    let c = &summary["counters"];
    assert!(c["published"].as_u64().unwrap() >= 30, "{summary}");
    // The bad images (one of each kind at least) are refused; those before the withheld camera
    // info are counted apart, not as bad input.
    assert!(c["images_rejected"].as_u64().unwrap() >= 3, "{summary}");
    assert!(c["images_before_info"].as_u64().unwrap() >= 1, "{summary}");
    let log = std::fs::read_to_string(dir.join("herb-camera.log")).unwrap();
    for why in [
        "no camera info yet",
        "rgb8",
        "camera info 640 x 480",
        "bytes of data",
    ] {
        assert!(log.contains(why), "{why}: {log}");
    }
    assert!(summary["image_to_heightmap_ms"]["p99"].as_f64().unwrap() > 0.0);
}

/// `herb-camera calibrate` against the fake camera showing the empty box: the `[pose]` it
/// prints is the fake's pose within 2 mm and 0.3 degrees, and the adapter reads it.
#[test]
fn calibrate_fits_the_camera_pose_from_the_empty_box() {
    if !ros_available() {
        return;
    }
    let dir = tmp("ros-calibrate");
    let prefix = format!("cal{}", std::process::id());
    let cfg = config(&dir, &prefix, "blbf");
    let spec = GridSpec::for_box(ObsLayout::CELL_M).unwrap();
    let ros = RosWorld::new(&dir, None);
    let _master = ros.master("1");
    let _camera = Camera::start(&ros, &cfg, &spec, &vec![0.0; spec.len()], 0, 0.0);
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_herb-camera"))
        .args(["--master-uri", &ros.uri(), "calibrate", "--frames", "3"])
        .envs(ros.env())
        .output()
        .expect("herb-camera runs");
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let file = dir.join("calibrated.toml");
    std::fs::write(&file, &text).unwrap();
    let c =
        <herb_camera::config::CameraConfig as herb_process::config_file::ConfigFile>::load(&file)
            .expect("the printed pose is a valid camera file");
    let want = herb_testkit::ros::TEST_CAMERA_POSE;
    let t = c.pose.translation;
    let dt =
        ((t[0] - want[0]).powi(2) + (t[1] - want[1]).powi(2) + (t[2] - want[2]).powi(2)).sqrt();
    let q = c.b_from_c().rotation;
    let truth = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
        want[6], want[3], want[4], want[5],
    ));
    let da = q.angle_to(&truth).to_degrees();
    eprintln!("{text}{dt:.4} m and {da:.3} degrees from the fake's pose");
    assert!(dt < 0.002, "{dt} m: {text}");
    assert!(da < 0.3, "{da} degrees: {text}");
}
