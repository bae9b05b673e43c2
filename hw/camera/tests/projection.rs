//! The depth-to-heightmap projection against a known scene: a truth heightmap (the box with two
//! blocks) rendered through a tilted pinhole camera by ray casting (a **test fixture**
//! renderer), then projected back. Observed cells away from the blocks' edges match the truth
//! within 2 mm (16UC1 millimetres and 32FC1 metres); cells no pixel saw are filled never lower
//! than the truth; bad images are refused with a reason.

use herb_camera::calibrate::fit_pose;
use herb_camera::project::{Depth, Intrinsics, Params, Projector};
use herb_core::ObsLayout;
use herb_core::frames::{BOX_HALF_X, BOX_HALF_Y, BOX_HEIGHT, BOX_WALL_THICKNESS};
use herb_core::heightmap::GridSpec;
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

const W: u32 = 640;
const H: u32 = 480;

fn intrinsics() -> Intrinsics {
    Intrinsics::from_k(W, H, &[600.0, 0.0, 319.5, 0.0, 600.0, 239.5, 0.0, 0.0, 1.0]).unwrap()
}

/// The camera 0.6 m above the floor, 4 cm off centre, tilted 12 degrees about x and 5 about y.
fn pose() -> Isometry3<f64> {
    // Looking down: optical x = B x, optical y = -B y, optical z = -B z.
    let down = Rotation3::from_matrix_unchecked(Matrix3::new(
        1.0, 0.0, 0.0, //
        0.0, -1.0, 0.0, //
        0.0, 0.0, -1.0,
    ));
    let tilt = Rotation3::from_euler_angles(12f64.to_radians(), 5f64.to_radians(), 0.0);
    Isometry3::from_parts(
        Translation3::new(0.04, -0.09, 0.6),
        UnitQuaternion::from_rotation_matrix(&(tilt * down)),
    )
}

/// Height of the scene's surface under (x, y): the truth in the interior, the rim over the
/// walls, the table outside.
fn surface(spec: &GridSpec, t: &[f32], x: f64, y: f64) -> f64 {
    let (hx, hy) = (BOX_HALF_X as f64, BOX_HALF_Y as f64);
    let wall = BOX_WALL_THICKNESS as f64;
    if x.abs() <= hx && y.abs() <= hy {
        let (u, v) = spec.to_pixel(x as f32, y as f32);
        let (c, r) = (
            (u.floor() as usize).min(spec.nx - 1),
            (v.floor() as usize).min(spec.ny - 1),
        );
        t[r * spec.nx + c] as f64
    } else if x.abs() <= hx + wall && y.abs() <= hy + wall {
        BOX_HEIGHT as f64
    } else {
        -wall
    }
}

/// Depth (m along the optical axis) of every pixel by marching its ray and bisecting the hit.
fn render(spec: &GridSpec, t: &[f32]) -> Vec<f64> {
    let (i, b_from_c) = (intrinsics(), pose());
    let o = b_from_c.translation.vector;
    let mut depth = vec![0.0; (W * H) as usize];
    for v in 0..H {
        for u in 0..W {
            let dir = b_from_c.rotation
                * Vector3::new((u as f64 - i.cx) / i.fx, (v as f64 - i.cy) / i.fy, 1.0);
            let below = |d: f64| {
                let p = o + dir * d;
                p.z <= surface(spec, t, p.x, p.y)
            };
            let mut d = 0.3;
            while d < 1.2 && !below(d) {
                d += 0.0005;
            }
            let (mut lo, mut hi) = (d - 0.0005, d);
            for _ in 0..30 {
                let m = 0.5 * (lo + hi);
                if below(m) { hi = m } else { lo = m }
            }
            depth[(v * W + u) as usize] = hi;
        }
    }
    depth
}

fn params() -> Params {
    Params {
        min_depth: 0.2,
        max_depth: 1.5,
        floor_threshold: 0.003,
        fill_radius: 6,
        max_height: 0.3,
    }
}

fn check(depth: &Depth<'_>, spec: &GridSpec, t: &[f32], what: &str) {
    let mut p = Projector::new(*spec);
    let mut hm = vec![0.0f32; spec.len()];
    let stats = p.project(depth, &intrinsics(), &pose(), &params(), &mut hm);
    let filled = (stats.filled_near + stats.filled_far) as usize;
    assert!(
        filled * 10 < spec.len(),
        "{what}: most cells seen: {stats:?}"
    );
    let (flat, worst) = herb_testkit::compare_to_truth(spec, t, &hm, |i| p.seen()[i], 0.002);
    assert!(worst <= 0.002, "{what}: a seen flat cell off by {worst} m");
    assert!(
        flat * 10 > spec.len() * 8,
        "{what}: only {flat} seen flat cells"
    );
    eprintln!("{what}: {stats:?}, {flat} seen flat cells within {worst:.4} m");
}

#[test]
fn a_rendered_scene_projects_back_to_its_heightmap() {
    let spec = GridSpec::for_box(ObsLayout::CELL_M).unwrap();
    let t = herb_testkit::two_blocks(&spec);
    let d = render(&spec, &t);
    let metres: Vec<u8> = d.iter().flat_map(|&x| (x as f32).to_le_bytes()).collect();
    let mm: Vec<u8> = d
        .iter()
        .flat_map(|&x| ((x * 1000.0).round() as u16).to_le_bytes())
        .collect();
    let i = intrinsics();
    let f = Depth::from_image("32FC1", 0, W, H, 4 * W, &metres, &i).unwrap();
    check(&f, &spec, &t, "32FC1");
    let m = Depth::from_image("16UC1", 0, W, H, 2 * W, &mm, &i).unwrap();
    check(&m, &spec, &t, "16UC1");
}

/// `herb-camera calibrate`'s fit: the empty box rendered from the test pose gives that pose
/// back within 2 mm and 0.3 degrees.
#[test]
fn the_camera_pose_is_fitted_from_the_empty_box() {
    let spec = GridSpec::for_box(ObsLayout::CELL_M).unwrap();
    let d = render(&spec, &vec![0.0; spec.len()]);
    let mm: Vec<u8> = d
        .iter()
        .flat_map(|&x| ((x * 1000.0).round() as u16).to_le_bytes())
        .collect();
    let i = intrinsics();
    let depth = Depth::from_image("16UC1", 0, W, H, 2 * W, &mm, &i).unwrap();
    let fitted = fit_pose(&depth, &i, 0.2, 1.5, Vector3::x()).unwrap();
    let truth = pose();
    let dt = (fitted.translation.vector - truth.translation.vector).norm();
    let da = fitted.rotation.angle_to(&truth.rotation).to_degrees();
    eprintln!("fitted {fitted:?}: {dt:.4} m, {da:.3} degrees from the truth");
    assert!(dt < 0.002, "translation off by {dt} m");
    assert!(da < 0.3, "rotation off by {da} degrees");
    // Nothing to fit: a clear error.
    let empty = vec![0u8; (2 * W * H) as usize];
    let none = Depth::from_image("16UC1", 0, W, H, 2 * W, &empty, &i).unwrap();
    let e = fit_pose(&none, &i, 0.2, 1.5, Vector3::x())
        .unwrap_err()
        .to_string();
    assert!(e.contains("too few"), "{e}");
}

#[test]
fn bad_images_and_camera_info_are_refused_with_a_reason() {
    let i = intrinsics();
    let data = vec![0u8; (2 * W * H) as usize];
    let e = Depth::from_image("rgb8", 0, W, H, 2 * W, &data, &i)
        .unwrap_err()
        .to_string();
    assert!(e.contains("rgb8"), "{e}");
    let e = Depth::from_image("16UC1", 0, 320, 240, 640, &data, &i)
        .unwrap_err()
        .to_string();
    assert!(e.contains("camera info"), "{e}");
    let e = Depth::from_image("16UC1", 0, W, H, 2 * W, &data[..100], &i)
        .unwrap_err()
        .to_string();
    assert!(e.contains("bytes"), "{e}");
    let e = Depth::from_image("16UC1", 1, W, H, 2 * W, &data, &i)
        .unwrap_err()
        .to_string();
    assert!(e.contains("big-endian"), "{e}");
    assert!(Intrinsics::from_k(W, H, &[0.0; 9]).is_err());
    assert!(Intrinsics::from_k(W, H, &[600.0; 4]).is_err());
    assert!(Intrinsics::from_k(0, H, &[600.0, 0.0, 1.0, 0.0, 600.0, 1.0, 0.0, 0.0, 1.0]).is_err());
    // No reading anywhere: every cell filled with the frame's highest (0: nothing seen).
    let spec = GridSpec::for_box(ObsLayout::CELL_M).unwrap();
    let mut p = Projector::new(spec);
    let mut hm = vec![1.0f32; spec.len()];
    let d = Depth::from_image("16UC1", 0, W, H, 2 * W, &data, &i).unwrap();
    let s = p.project(&d, &i, &pose(), &params(), &mut hm);
    assert_eq!(s.valid_pixels, 0);
    assert_eq!(s.filled_far as usize, spec.len());
}
