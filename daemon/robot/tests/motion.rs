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
