//! Baxter left-arm kinematics: Jacobian against finite differences, FK/IK round trips over
//! random configurations and random top-down poses, unreachable targets reported.

use herb_robot::kinematics::{Arm, DOF, IkError, IkOptions, top_down};
use nalgebra::Isometry3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn errors(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
    (
        (a.translation.vector - b.translation.vector).norm(),
        a.rotation.angle_to(&b.rotation),
    )
}

fn random_q(arm: &Arm, rng: &mut ChaCha8Rng) -> [f64; DOF] {
    let mut q = [0.0; DOF];
    for (a, j) in q.iter_mut().zip(arm.joints()) {
        *a = rng.random_range(j.lower..=j.upper);
    }
    q
}

#[test]
fn the_jacobian_matches_finite_differences_of_fk() {
    let arm = Arm::baxter_left();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    for _ in 0..20 {
        let q = random_q(&arm, &mut rng);
        let (j, pose) = arm.jacobian(&q);
        assert!(errors(&pose, &arm.fk(&q)).0 < 1e-12);
        for i in 0..DOF {
            let h = 1e-6;
            let mut qp = q;
            qp[i] += h;
            let p1 = arm.fk(&qp);
            let dv = (p1.translation.vector - pose.translation.vector) / h;
            let dw = (p1.rotation * pose.rotation.inverse()).scaled_axis() / h;
            for k in 0..3 {
                assert!((dv[k] - j[(k, i)]).abs() < 1e-4, "v joint {i}");
                assert!((dw[k] - j[(k + 3, i)]).abs() < 1e-4, "w joint {i}");
            }
        }
    }
}

#[test]
fn fk_ik_round_trip_over_random_configurations() {
    let arm = Arm::baxter_left();
    let opts = IkOptions::default();
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let (mut ok, n) = (0, 200);
    for _ in 0..n {
        let q_true = random_q(&arm, &mut rng);
        let target = arm.fk(&q_true);
        // Seeded near the true configuration, as from the current joint state.
        let mut seed = q_true;
        for a in &mut seed {
            *a += rng.random_range(-0.2..0.2);
        }
        if let Ok(q) = arm.ik(&target, &seed, &opts) {
            let (dp, da) = errors(&arm.fk(&q), &target);
            assert!(dp < 1e-3 && da < 0.5f64.to_radians(), "{dp} m, {da} rad");
            assert!(arm.within_limits(&q));
            ok += 1;
        }
    }
    eprintln!("random configurations: {ok} of {n} converged");
    assert!(ok >= n * 95 / 100, "{ok} of {n} converged");
}

/// Top-down poses over a packing area in front of the left arm: each solved from the previous
/// solution (as in a sequence of moves), with yaw modulo a half turn; the round trip is within
/// 1 mm and 0.5 degrees.
#[test]
fn fk_ik_round_trip_over_random_top_down_poses() {
    let arm = Arm::baxter_left();
    let opts = IkOptions::default();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut seed = herb_robot::kinematics::LEFT_TOP_DOWN_NOMINAL;
    let (mut ok, n) = (0, 200);
    let mut failures = Vec::new();
    for _ in 0..n {
        let (x, y, z, yaw) = (
            rng.random_range(0.55..0.85),
            rng.random_range(0.05..0.45),
            rng.random_range(-0.1..0.15),
            rng.random_range(-1.5..1.5),
        );
        let target = top_down(x, y, z, yaw);
        match arm.ik_top_down((x, y, z), yaw, &seed, &opts) {
            Ok(q) => {
                // The same grasp at yaw or yaw + pi (a parallel gripper's symmetry).
                let flipped = top_down(x, y, z, yaw + std::f64::consts::PI);
                let (dp, da) = errors(&arm.fk(&q), &target);
                let (dp2, da2) = errors(&arm.fk(&q), &flipped);
                let (dp, da) = if da <= da2 { (dp, da) } else { (dp2, da2) };
                assert!(dp < 1e-3 && da < 0.5f64.to_radians(), "{dp} m, {da} rad");
                assert!(arm.within_limits(&q));
                seed = q;
                ok += 1;
            }
            Err(e) => failures.push(format!("{:?}: {e}", target.translation.vector)),
        }
    }
    eprintln!("top-down: {ok} of {n} converged");
    assert!(
        ok >= n * 95 / 100,
        "{ok} of {n} converged; failures: {failures:?}"
    );
}

#[test]
fn unreachable_targets_are_reported_not_clamped() {
    let arm = Arm::baxter_left();
    let seed = [0.0; DOF];
    let far = top_down(3.0, 0.5, 0.0, 0.0);
    match arm.ik(&far, &seed, &IkOptions::default()) {
        Err(IkError::Unreachable {
            position_error_m, ..
        }) => assert!(position_error_m > 1.0, "{position_error_m}"),
        other => panic!("expected Unreachable, got {other:?}"),
    }
    let mut bad = seed;
    bad[2] = f64::NAN;
    assert_eq!(
        arm.ik(&top_down(0.7, 0.2, 0.0, 0.0), &bad, &IkOptions::default()),
        Err(IkError::NotFinite)
    );
}
