//! `herb-camera`: depth images from ROS 1 to herbd's heightmap service. The ROS side (a
//! single-threaded tokio runtime in its own thread) projects each image into a heightmap and
//! hands it over; the main thread publishes it in shared memory. SIGINT/SIGTERM: prints a JSON
//! summary on stdout and exits 0.

use clap::Parser;
use herb_adapter::{CameraPort, Heightmap};
use herb_camera::config::CameraConfig;
use herb_camera::project::{Depth, FrameStats, Intrinsics, Median, Projector};
use herb_core::heightmap::GridSpec;
use herb_ipc::bus::Bus;
use herb_ipc::{Services, monotonic_ns};
use herb_process::config_file::ConfigFile;
use herb_ros1::Advertised;
use herb_ros1::node::{MasterView, Next, announce_again, connect, master_view, next, topic_of};
use herb_ros1::sensor_msgs::{CameraInfo, Image};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use std::time::{Duration, SystemTime};

/// Depth camera (ROS 1) to heightmap (iceoryx2).
#[derive(Debug, Parser)]
#[command(name = "herb-camera", version)]
struct Cli {
    /// herbd's configuration file (the IPC prefix).
    #[arg(long)]
    config: Option<PathBuf>,
    /// This adapter's file (ROS master, topics, camera pose, depth limits, heightmap).
    #[arg(long)]
    camera: Option<PathBuf>,
    /// IPC service-name prefix (overrides herbd's file).
    #[arg(long)]
    prefix: Option<String>,
    /// ROS master URI (overrides the adapter's file).
    #[arg(long)]
    master_uri: Option<String>,
    /// Also write the final summary (JSON) here.
    #[arg(long)]
    report: Option<PathBuf>,
    #[command(subcommand)]
    command: Option<Sub>,
}

#[derive(Debug, clap::Subcommand)]
enum Sub {
    /// Fit the camera's pose from depth images of the EMPTY box with its whole rim in view,
    /// and print it as the `[pose]` table of the camera file (nothing is published).
    Calibrate {
        /// Depth images to take (their per-pixel median is fitted).
        #[arg(long, default_value_t = 5)]
        frames: usize,
        /// The image direction the box's +x (long side) points closest to: u, -u, v or -v
        /// (settles the box's 180-degree symmetry by how the camera is mounted).
        #[arg(long, default_value = "u", allow_hyphen_values = true)]
        x_hint: String,
        /// Give up after this long (s).
        #[arg(long, default_value_t = 30.0)]
        timeout_s: f64,
    },
}

/// `herb-camera calibrate`: the fitted pose as TOML.
fn calibrate(
    cfg: &CameraConfig,
    frames: usize,
    x_hint: &str,
    timeout_s: f64,
) -> Result<String, String> {
    let hint = match x_hint {
        "u" => nalgebra::Vector3::x(),
        "-u" => -nalgebra::Vector3::x(),
        "v" => nalgebra::Vector3::y(),
        "-v" => -nalgebra::Vector3::y(),
        h => return Err(format!("--x-hint {h:?}: expected u, -u, v or -v")),
    };
    if !((1..=100).contains(&frames) && timeout_s.is_finite() && timeout_s > 0.0) {
        return Err(format!(
            "--frames {frames} (1 to 100) or --timeout-s {timeout_s} out of range"
        ));
    }
    let stop = AtomicBool::new(false);
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| format!("tokio runtime: {e}"))?;
    let (intr, depths) = rt.block_on(async {
        // Its own node name: a running adapter keeps its registration.
        let name = format!("{}_calibrate", cfg.ros.node_name);
        let nh = connect(
            &cfg.ros.master_uri,
            &name,
            |m| herb_adapter::log!("herb-camera: {m}"),
            &stop,
        )
        .await
        .ok_or("stopped")?;
        let t = &cfg.topics;
        let mut images = nh.subscribe::<Image>(&t.image, 4).await.map_err(|e| format!("subscribe {}: {e}", t.image))?;
        let mut infos = nh.subscribe::<CameraInfo>(&t.camera_info, 4).await.map_err(|e| format!("subscribe {}: {e}", t.camera_info))?;
        let mut intr = None;
        let mut depths: Vec<Vec<f64>> = Vec::new();
        let deadline = tokio::time::Instant::now() + Duration::from_secs_f64(timeout_s);
        while depths.len() < frames {
            tokio::select! {
                _ = tokio::time::sleep_until(deadline) => {
                    return Err(format!("{} of {frames} images in {timeout_s} s (camera info: {})", depths.len(), intr.is_some()));
                }
                m = next(&mut infos) => if let Next::Msg(ci) = m {
                    intr = Some(Intrinsics::from_k(ci.width, ci.height, &ci.K).map_err(|e| e.to_string())?);
                },
                m = next(&mut images) => if let (Next::Msg(img), Some(i)) = (m, intr) {
                    let d = Depth::from_image(&img.encoding, img.is_bigendian, img.width, img.height, img.step, &img.data, &i).map_err(|e| e.to_string())?;
                    depths.push((0..(i.width * i.height) as usize).map(|k| d.depth_m(k).unwrap_or(f64::NAN)).collect());
                },
            }
        }
        Ok::<_, String>((intr.expect("set before any image is taken"), depths))
    })?;
    // Per-pixel median of the valid readings, as a 32FC1 image.
    let mut column = Vec::with_capacity(depths.len());
    let median: Vec<u8> = (0..depths[0].len())
        .flat_map(|k| {
            column.clear();
            column.extend(depths.iter().map(|d| d[k]).filter(|v| v.is_finite()));
            column.sort_unstable_by(f64::total_cmp);
            let m = column.get(column.len() / 2).copied().unwrap_or(f64::NAN);
            (m as f32).to_le_bytes()
        })
        .collect();
    let depth = Depth::from_image(
        "32FC1",
        0,
        intr.width,
        intr.height,
        4 * intr.width,
        &median,
        &intr,
    )
    .map_err(|e| e.to_string())?;
    let pose =
        herb_camera::calibrate::fit_pose(&depth, &intr, cfg.depth.min_m, cfg.depth.max_m, hint)
            .map_err(|e| e.to_string())?;
    let (t, q) = (pose.translation.vector, pose.rotation.coords);
    Ok(format!(
        "# herb-camera calibrate: {frames} images of the empty box\n[pose]\ntranslation = [{:.5}, {:.5}, {:.5}]\nrotation = [{:.6}, {:.6}, {:.6}, {:.6}]\n",
        t.x, t.y, t.z, q.x, q.y, q.z, q.w
    ))
}

/// The prefix from herbd's file; its other tables are herbd's.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(default)]
struct HerbdPrefix {
    ipc_prefix: String,
}

impl Default for HerbdPrefix {
    fn default() -> Self {
        Self {
            ipc_prefix: Services::DEFAULT_PREFIX.into(),
        }
    }
}

impl ConfigFile for HerbdPrefix {
    fn validate(&self) -> Result<(), herb_process::config_file::Invalid> {
        Services::new(&self.ipc_prefix)
            .map(|_| ())
            .map_err(|e| e.to_string().into())
    }
}

/// A projected frame on its way to the publisher.
struct Frame {
    /// When the image arrived (CLOCK_MONOTONIC ns).
    received_ns: u64,
    stamp_ns: u64,
    cells: Vec<f32>,
    stats: FrameStats,
}

/// Counters of the ROS side.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
struct Counters {
    images: u64,
    /// Images that arrived before the first camera info: expected at start (ROS connects the
    /// image and camera info topics separately, so either may come first), not bad input.
    images_before_info: u64,
    /// Images refused as bad input (undecodable, or disagreeing with the camera info).
    images_rejected: u64,
    camera_infos_rejected: u64,
    lagged: u64,
    published: u64,
    cells_filled: u64,
}

fn lock(c: &Mutex<Counters>) -> std::sync::MutexGuard<'_, Counters> {
    c.lock().unwrap_or_else(|e| e.into_inner())
}

/// Logs `what` when it differs from the last thing logged this way.
fn say_once(last: &mut String, what: String) {
    if *last != what {
        herb_adapter::log!("herb-camera: {what}");
        *last = what;
    }
}

/// How often the master is asked whether it still knows this node.
const MASTER_CHECK: Duration = Duration::from_millis(500);

/// The ROS side: one registration after another (a restarted master forgets this node: it
/// registers again) until `stop` is set; an error ends it.
async fn ros_side(
    cfg: CameraConfig,
    spec: GridSpec,
    frames: mpsc::SyncSender<Frame>,
    spare: mpsc::Receiver<Vec<f32>>,
    counters: Arc<Mutex<Counters>>,
    stop: Arc<AtomicBool>,
) -> Result<(), String> {
    while session(&cfg, spec, &frames, &spare, &counters, &stop).await? {
        herb_adapter::log!("herb-camera: no image since registering again: connecting anew");
    }
    Ok(())
}

/// After announcing this node again to a master that already listed the camera's publishers,
/// a new node is made if no image arrived within this long.
const REANNOUNCE_GRACE: Duration = Duration::from_secs(2);

/// One registration; true when the camera stayed silent after this node announced itself
/// again to a restarted master (make a new node).
async fn session(
    cfg: &CameraConfig,
    spec: GridSpec,
    frames: &mpsc::SyncSender<Frame>,
    spare: &mpsc::Receiver<Vec<f32>>,
    counters: &Mutex<Counters>,
    stop: &AtomicBool,
) -> Result<bool, String> {
    let Some(nh) = connect(
        &cfg.ros.master_uri,
        &cfg.ros.node_name,
        |m| herb_adapter::log!("herb-camera: {m}"),
        stop,
    )
    .await
    else {
        return Ok(false);
    };
    let t = &cfg.topics;
    let mut images = nh
        .subscribe::<Image>(&t.image, 4)
        .await
        .map_err(|e| format!("subscribe {}: {e}", t.image))?;
    let mut infos = nh
        .subscribe::<CameraInfo>(&t.camera_info, 4)
        .await
        .map_err(|e| format!("subscribe {}: {e}", t.camera_info))?;
    let (pose, params) = (cfg.b_from_c(), cfg.params());
    let max_age_ns = (cfg.depth.max_age_s * 1e9) as u64;
    let mut projector = Projector::new(spec);
    let mut median = Median::new(cfg.heightmap.median_frames, spec.len());
    let mut raw = vec![0.0f32; spec.len()];
    let mut intr: Option<Intrinsics> = None;
    let mut last_said = String::new();
    let mut poll = tokio::time::interval(Duration::from_millis(100));
    let client_uri = nh
        .get_client_uri()
        .await
        .map_err(|e| format!("node URI: {e}"))?;
    let master =
        roslibrust::ros1::MasterClient::new(&cfg.ros.master_uri, client_uri, &cfg.ros.node_name)
            .await
            .map_err(|e| format!("master client: {e}"))?;
    let subscribed = [
        topic_of::<Image>(&t.image),
        topic_of::<CameraInfo>(&t.camera_info),
    ];
    let mut announced_at: Option<tokio::time::Instant> = None;
    let mut last_image: Option<tokio::time::Instant> = None;
    let mut mono16_said = false;
    let mut check = tokio::time::interval(MASTER_CHECK);
    check.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    while !stop.load(Ordering::Relaxed) {
        tokio::select! {
            m = next(&mut infos) => match m {
                Next::Msg(ci) => match Intrinsics::from_k(ci.width, ci.height, &ci.K) {
                    Ok(i) => intr = Some(i),
                    Err(e) => {
                        lock(counters).camera_infos_rejected += 1;
                        say_once(&mut last_said, format!("camera info refused: {e}"));
                    }
                },
                Next::Lagged(n) => lock(counters).lagged += n,
                Next::Bad(e) => {
                    lock(counters).camera_infos_rejected += 1;
                    say_once(&mut last_said, format!("camera info undecodable: {e}"));
                }
                Next::Closed => return Err(format!("subscription {} closed", t.camera_info)),
            },
            m = next(&mut images) => {
                let img = match m {
                    Next::Msg(img) => img,
                    Next::Lagged(n) => {
                        lock(counters).lagged += n;
                        continue;
                    }
                    Next::Bad(e) => {
                        let mut c = lock(counters);
                        c.images += 1;
                        c.images_rejected += 1;
                        drop(c);
                        say_once(&mut last_said, format!("image undecodable: {e}"));
                        continue;
                    }
                    Next::Closed => return Err(format!("subscription {} closed", t.image)),
                };
                let received_ns = monotonic_ns();
                last_image = Some(tokio::time::Instant::now());
                if img.encoding == "mono16" && !mono16_said {
                    // Some drivers label 16-bit depth mono16: read as 16UC1 (millimetres).
                    herb_adapter::log!("herb-camera: image encoding mono16 read as 16UC1 (depth in millimetres)");
                    mono16_said = true;
                }
                lock(counters).images += 1;
                let Some(intr) = intr else {
                    lock(counters).images_before_info += 1;
                    say_once(&mut last_said, "image dropped: no camera info yet".into());
                    continue;
                };
                let checked = Depth::from_image(&img.encoding, img.is_bigendian, img.width, img.height, img.step, &img.data, &intr)
                    .map_err(|e| e.to_string())
                    .and_then(|d| {
                        let stamp = herb_ros1::time::to_monotonic(&img.header.stamp, monotonic_ns(), SystemTime::now(), max_age_ns).map_err(|e| e.to_string())?;
                        Ok((intr, d, stamp))
                    });
                let (i, depth, stamp_ns) = match checked {
                    Ok(v) => v,
                    Err(e) => {
                        lock(counters).images_rejected += 1;
                        say_once(&mut last_said, format!("image refused: {e}"));
                        continue;
                    }
                };
                let stats = projector.project(&depth, &i, &pose, &params, &mut raw);
                let mut cells = spare.try_recv().unwrap_or_else(|_| vec![0.0; spec.len()]);
                median.push(&raw, &mut cells);
                if frames.try_send(Frame { received_ns, stamp_ns, cells, stats }).is_err() {
                    // The publisher is behind: this frame is dropped, the next one goes.
                    lock(counters).lagged += 1;
                }
                if !last_said.is_empty() {
                    say_once(&mut last_said, "images accepted".into());
                }
            }
            _ = poll.tick() => {}
            _ = check.tick() => {
                if master_view(&master, &t.image, &cfg.ros.node_name, MASTER_CHECK).await == MasterView::Forgotten {
                    herb_adapter::log!("herb-camera: the ROS master restarted and forgot this node: registering again");
                    let known = announce_again(&master, &subscribed, &[]).await.map_err(|e| e.to_string())?;
                    announced_at = known.then(tokio::time::Instant::now);
                }
                if let Some(at) = announced_at {
                    if last_image.is_some_and(|t| t > at) {
                        announced_at = None;
                    } else if at.elapsed() > REANNOUNCE_GRACE {
                        return Ok(true);
                    }
                }
            }
        }
    }
    Ok(false)
}

fn run(cli: Cli) -> Result<serde_json::Value, String> {
    let mut herbd =
        HerbdPrefix::load_or_default(cli.config.as_deref()).map_err(|e| e.to_string())?;
    if let Some(p) = &cli.prefix {
        herbd.ipc_prefix = p.clone();
    }
    herbd.validate().map_err(|e| e.to_string())?;
    let mut cfg =
        CameraConfig::load_or_default(cli.camera.as_deref()).map_err(|e| e.to_string())?;
    if let Some(u) = &cli.master_uri {
        cfg.ros.master_uri = u.clone();
    }
    cfg.validate().map_err(|e| e.to_string())?;
    // SAFETY: no other thread runs yet (the bus, the ROS thread and the signal handler start
    // below), so nothing reads the environment concurrently.
    let advertised =
        unsafe { Advertised::set(&cfg.ros.ip, &cfg.ros.hostname) }.map_err(|e| e.to_string())?;
    let spec = GridSpec::for_box(cfg.heightmap.cell_m).map_err(|e| e.to_string())?;
    let services = Services::new(&herbd.ipc_prefix).map_err(|e| e.to_string())?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let s = stop.clone();
        ctrlc::set_handler(move || s.store(true, Ordering::Relaxed)).map_err(|e| e.to_string())?;
    }
    let bus = Bus::open("herb-camera", &services).map_err(|e| e.to_string())?;
    let camera = CameraPort::open(&bus).map_err(|e| e.to_string())?;
    let counters = Arc::new(Mutex::new(Counters::default()));
    let (tx, rx) = mpsc::sync_channel::<Frame>(2);
    let (spare_tx, spare_rx) = mpsc::channel::<Vec<f32>>();
    let ros = {
        let (cfg, counters, stop) = (cfg.clone(), counters.clone(), stop.clone());
        std::thread::Builder::new()
            .name("herb-camera-ros".into())
            .spawn(move || {
                let r = tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build()
                    .map_err(|e| format!("tokio runtime: {e}"))
                    .and_then(|rt| {
                        rt.block_on(ros_side(cfg, spec, tx, spare_rx, counters, stop.clone()))
                    });
                stop.store(true, Ordering::Relaxed);
                r
            })
            .map_err(|e| e.to_string())?
    };
    herb_adapter::log!(
        "herb-camera: prefix {:?}, master {}, reached at {advertised}, {} x {} cells of {} m",
        herbd.ipc_prefix,
        cfg.ros.master_uri,
        spec.nx,
        spec.ny,
        spec.cell
    );
    let mut seq = 0u64;
    // Image arrival to heightmap published (projection, median, hand-over, shared-memory write).
    let mut latency = herb_adapter::latency();
    while !stop.load(Ordering::Relaxed) {
        let Ok(f) = rx.recv_timeout(Duration::from_millis(100)) else {
            continue;
        };
        seq += 1;
        let hm = Heightmap {
            stamp_ns: f.stamp_ns,
            nx: spec.nx as u32,
            ny: spec.ny as u32,
            cell_m: spec.cell,
            objects: 0,
            cells: &f.cells,
        };
        match camera.publish(seq, &hm) {
            Ok(()) => {
                if seq == 1 {
                    herb_adapter::log!("herb-camera: first heightmap published");
                }
                let _ = latency.record(monotonic_ns().saturating_sub(f.received_ns).max(1));
                let mut c = lock(&counters);
                c.published += 1;
                c.cells_filled += u64::from(f.stats.filled_near + f.stats.filled_far);
            }
            Err(e) => herb_adapter::log!("herb-camera: heightmap not published: {e}"),
        }
        let _ = spare_tx.send(f.cells);
    }
    let ros_result = ros
        .join()
        .unwrap_or_else(|_| Err("the ROS thread panicked".into()));
    let c = *lock(&counters);
    let summary = serde_json::json!({ "camera_final": {
        "counters": c,
        "cells_per_frame": spec.len(),
        "image_to_heightmap_ms": herb_adapter::latency_json(&latency),
        "ros_error": ros_result.as_ref().err(),
    }});
    herb_adapter::summary_or_error(summary, ros_result)
}

fn main() -> ExitCode {
    let mut cli = Cli::parse();
    if let Some(Sub::Calibrate {
        frames,
        x_hint,
        timeout_s,
    }) = cli.command.take()
    {
        let cfg = CameraConfig::load_or_default(cli.camera.as_deref())
            .map(|mut c| {
                if let Some(u) = &cli.master_uri {
                    c.ros.master_uri = u.clone();
                }
                c
            })
            .and_then(|c| c.validate().map(|()| c).map_err(Into::into))
            .map_err(|e| e.to_string());
        let cfg = cfg.and_then(|c| {
            // SAFETY: only this thread runs (calibrate's runtime, on this thread, comes after).
            let a = unsafe { Advertised::set(&c.ros.ip, &c.ros.hostname) };
            a.map(|a| (c, a)).map_err(|e| e.to_string())
        });
        return match cfg.and_then(|(c, a)| {
            herb_adapter::log!(
                "herb-camera calibrate: master {}, reached at {a}",
                c.ros.master_uri
            );
            calibrate(&c, frames, &x_hint, timeout_s)
        }) {
            Ok(toml) => {
                print!("{toml}");
                ExitCode::SUCCESS
            }
            Err(e) => {
                herb_adapter::log!("herb-camera calibrate: error: {e}");
                ExitCode::from(2)
            }
        };
    }
    let report = cli.report.clone();
    herb_adapter::finish("herb-camera", run(cli), report.as_deref())
}
