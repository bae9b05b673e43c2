//! Ruckig trajectories as sampled for the loop: velocity, acceleration and jerk (finite
//! differences of the samples and Ruckig's own values) never exceed the limits, every
//! position stays inside the joint limits, point-to-point moves end exactly at the target, and
//! brakes from moving states come to a standstill.

use herb_robot::kinematics::DOF;
use herb_robot::motion::{JointLimits, MotionError, MotionPlanner, Setpoint, Setpoints};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const DT: f64 = 0.001;

fn random_q(l: &JointLimits, rng: &mut ChaCha8Rng) -> [f64; DOF] {
    std::array::from_fn(|i| rng.random_range(l.lower[i]..=l.upper[i]))
}

/// Checks every bound on a sampled trajectory that starts at `start`.
fn check_bounds(l: &JointLimits, start: &Setpoint, s: &[Setpoint]) {
    let tol = 1e-6;
    let mut prev = *start;
    for (k, p) in s.iter().enumerate() {
        for j in 0..DOF {
            assert!(
                p.position[j] >= l.lower[j] && p.position[j] <= l.upper[j],
                "sample {k} joint {j} position {} outside limits",
                p.position[j]
            );
            assert!(
                p.velocity[j].abs() <= l.velocity[j] * (1.0 + tol),
                "velocity"
            );
            assert!(
                p.acceleration[j].abs() <= l.acceleration[j] * (1.0 + tol),
                "acc"
            );
            let v_fd = (p.position[j] - prev.position[j]) / DT;
            assert!(
                v_fd.abs() <= l.velocity[j] * (1.0 + tol) + 1e-9,
                "sample {k} joint {j} fd velocity {v_fd}"
            );
            let a_fd = (p.velocity[j] - prev.velocity[j]) / DT;
            assert!(
                a_fd.abs() <= l.acceleration[j] * (1.0 + tol) + 1e-9,
                "fd acceleration {a_fd}"
            );
            let j_fd = (p.acceleration[j] - prev.acceleration[j]) / DT;
            assert!(
                j_fd.abs() <= l.jerk[j] * (1.0 + tol) + 1e-6,
                "sample {k} joint {j} fd jerk {j_fd}"
            );
        }
        prev = *p;
    }
}

#[test]
fn point_to_point_respects_every_limit_and_ends_at_the_target() {
    let l = JointLimits::baxter_left();
    let mut planner = MotionPlanner::new(l, DT);
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut out = Setpoints::with_capacity(60_000);
    for _ in 0..50 {
        let (a, b) = (random_q(&l, &mut rng), random_q(&l, &mut rng));
        out.clear();
        let d = planner.point_to_point(&a, &b, &mut out).unwrap();
        assert!(d > 0.0);
        assert_eq!(out.len(), (d / DT).ceil() as usize);
        check_bounds(&l, &Setpoint::at_rest(a), out.as_slice());
        assert_eq!(*out.as_slice().last().unwrap(), Setpoint::at_rest(b));
    }
}

#[test]
fn targets_outside_the_limits_are_refused_not_clamped() {
    let l = JointLimits::baxter_left();
    let mut planner = MotionPlanner::new(l, DT);
    let mut out = Setpoints::with_capacity(10_000);
    let mut b = [0.0; DOF];
    b[3] = 1.0;
    b[1] = l.upper[1] + 0.01;
    let a = {
        let mut a = [0.0; DOF];
        a[3] = 1.0;
        a
    };
    let e = planner.point_to_point(&a, &b, &mut out).unwrap_err();
    assert!(
        matches!(
            e,
            MotionError::BadState {
                what: "target",
                joint: 1,
                ..
            }
        ),
        "{e}"
    );
    b[1] = f64::NAN;
    assert!(planner.point_to_point(&a, &b, &mut out).is_err());
    assert!(out.is_empty());
    // A buffer too small for the move is an error, not a reallocation.
    let mut small = Setpoints::with_capacity(10);
    let e = planner
        .point_to_point(&a, &l.upper, &mut small)
        .unwrap_err();
    assert_eq!(e, MotionError::TooLong { capacity: 10 });
}

#[test]
fn brakes_stop_moving_joints_within_the_limits() {
    let l = JointLimits::baxter_left();
    let mut planner = MotionPlanner::new(l, DT);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut traj = Setpoints::with_capacity(60_000);
    let mut brake = Setpoints::with_capacity(20_000);
    for _ in 0..30 {
        let (a, b) = (random_q(&l, &mut rng), random_q(&l, &mut rng));
        traj.clear();
        planner.point_to_point(&a, &b, &mut traj).unwrap();
        // Brake from a random moment mid-motion.
        let k = rng.random_range(1..traj.len());
        let state = *traj.get(k).unwrap();
        brake.clear();
        let (d, _clamps) = planner.brake(&state, &mut brake).unwrap();
        assert!(d >= 0.0);
        check_bounds(&l, &state, brake.as_slice());
        let last = brake.as_slice().last().unwrap();
        assert!(last.velocity.iter().all(|v| *v == 0.0));
        // Stopping takes no longer than the slowest joint needs from its speed.
        assert!(d < 3.0, "brake of {d} s");
    }
    let mut bad = Setpoint::at_rest([0.0; DOF]);
    bad.velocity[2] = f64::NAN;
    assert!(planner.brake(&bad, &mut brake).is_err());
}

/// An arm that sagged past herbd's limits (inside the arm's own) is brought back slowly: only
/// the joints outside move, each from its start toward its limit and never farther out, at the
/// reduced speed, ending at rest just inside; a start inside needs no move, one beyond the arm's
/// own limits is refused; a brake that starts outside never jumps to the limit.
#[test]
fn a_start_past_a_limit_is_brought_back_inside_slowly_toward_the_limit_only() {
    let l = JointLimits::baxter_left();
    let hard = herb_robot::motion::baxter_left_arm_range();
    let mut planner = MotionPlanner::new(l, DT);
    let mut from = [0.0; DOF];
    from[0] = 0.1;
    from[1] = l.upper[1] + 0.0034; // left_s1 sagged to 1.0004 rad past 0.997
    from[3] = l.lower[3] - 0.02;
    let mut out = Setpoints::with_capacity(200_000);
    let speed = 0.1;
    let d = planner
        .into_limits(&from, (&hard.0, &hard.1), speed, 0.005, &mut out)
        .expect("planned")
        .expect("a move");
    assert!(d > 0.0);
    let s = out.as_slice();
    let last = s.last().unwrap();
    assert!(l.contains(&last.position), "{:?}", last.position);
    assert_eq!(last.velocity, [0.0; DOF]);
    assert!((last.position[1] - (l.upper[1] - 0.005)).abs() < 1e-12);
    assert!((last.position[3] - (l.lower[3] + 0.005)).abs() < 1e-12);
    let mut prev = from;
    for p in s {
        for j in 0..DOF {
            if j == 1 || j == 3 {
                let (lo, hi) = (from[j].min(last.position[j]), from[j].max(last.position[j]));
                assert!(p.position[j] >= lo && p.position[j] <= hi, "joint {j}");
                // Monotone toward the target.
                assert!((p.position[j] - prev[j]) * (last.position[j] - from[j]) >= -1e-12);
                assert!(p.velocity[j].abs() <= speed * l.velocity[j] * (1.0 + 1e-6));
            } else {
                assert_eq!(p.position[j], from[j], "joint {j} inside stays");
            }
        }
        prev = p.position;
    }
    // Inside already: nothing to do.
    let mut none = Setpoints::with_capacity(10);
    let inside = last.position;
    assert_eq!(
        planner
            .into_limits(&inside, (&hard.0, &hard.1), speed, 0.005, &mut none)
            .unwrap(),
        None
    );
    assert!(none.is_empty());
    // Beyond the arm's own limits: refused.
    let mut beyond = from;
    beyond[1] = hard.1[1] + 0.01;
    assert!(matches!(
        planner.into_limits(&beyond, (&hard.0, &hard.1), speed, 0.005, &mut none),
        Err(MotionError::BadState { joint: 1, .. })
    ));
    // The planner's own limits are restored: a point-to-point afterwards is full speed.
    let a = l.pulled_inside(&from, 0.005);
    let mut b = a;
    b[0] = 0.5;
    let mut p2p = Setpoints::with_capacity(200_000);
    planner.point_to_point(&a, &b, &mut p2p).unwrap();
    let vmax = p2p
        .as_slice()
        .iter()
        .map(|p| p.velocity[0].abs())
        .fold(0.0, f64::max);
    assert!(vmax > 0.5 * l.velocity[0], "{vmax}");
    // A brake from a state still outside (moving back in) starts where it is.
    let mut st = Setpoint::at_rest(from);
    st.velocity[1] = -0.05;
    let mut brake = Setpoints::with_capacity(200_000);
    let (_, clamps) = planner.brake(&st, &mut brake).unwrap();
    let first = brake.as_slice()[0].position[1];
    assert!(
        (first - from[1]).abs() < 1e-3,
        "no jump to the limit: {first}"
    );
    assert!(first > l.upper[1], "{first}");
    assert_eq!(clamps, 0);
}
