//! Policy episodes for the Table I harness: the episode's objects in their order, each placed
//! by a decision-core policy through herbd's one decision path (`herb_decide::Decider`), timing
//! every decision.

use herb_decide::{DecideError, Decider, PackitSo3, Policy, Result};
use herb_sim::boxed::Episode;
use herb_sim::eval::EpisodeResult;
use herb_sim::{PackingEnv, TypeIdx};
use std::time::Instant;

/// Runs one episode: `order` placed by `decider`. Each decision's latency (one
/// [`Decider::decide`] call on the world's heightmap) is recorded, and the object is released at
/// the decided pose. A decision without a feasible placement ends the episode as a failure with
/// that reason.
pub fn run_policy_episode<P: Policy + ?Sized>(
    env: &mut PackingEnv,
    ep: &Episode,
    order: &[TypeIdx],
    decider: &mut Decider<P>,
    seed: u64,
) -> Result<EpisodeResult> {
    env.reset(order, seed)?;
    decider.begin_episode(seed);
    let mut r = EpisodeResult::new(&ep.name, order.len());
    for (step, &object) in order.iter().enumerate() {
        let t0 = Instant::now();
        let decided = decider.decide(
            env.world().heightmap().into(),
            object,
            step,
            &order[step + 1..],
        );
        r.decision_ns.push(t0.elapsed().as_nanos() as u64);
        let d = match decided {
            Ok(d) => d,
            Err(DecideError::NoFeasiblePlacement) => {
                r.record_no_feasible_placement();
                break;
            }
            Err(e) => return Err(e),
        };
        let res = env.step_pose(d.pose())?;
        if r.record(&res) {
            break;
        }
    }
    Ok(r)
}

/// Runs one episode of PackIt SO(3): `order` placed by `packit` in full orientations, each
/// decision (alignment, search and z estimate on the world's heightmap) timed. An object that
/// fits between the walls in no orientation ends the episode as "no feasible placement".
pub fn run_packit_so3_episode(
    env: &mut PackingEnv,
    ep: &Episode,
    order: &[TypeIdx],
    packit: &mut PackitSo3,
    seed: u64,
) -> Result<EpisodeResult> {
    env.reset(order, seed)?;
    let clearance = env.world().config().clearance_m;
    let mut r = EpisodeResult::new(&ep.name, order.len());
    for &object in order {
        let shape = env.world().catalog().shape(object);
        let t0 = Instant::now();
        let decided = packit.decide(env.world().heightmap(), shape, clearance);
        r.decision_ns.push(t0.elapsed().as_nanos() as u64);
        let Some(pose) = decided else {
            r.record_no_feasible_placement();
            break;
        };
        let res = env.step_pose(pose)?;
        if r.record(&res) {
            break;
        }
    }
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::*;
    use herb_decide::{OnnxPolicy, Order};
    use herb_sim::paths::MeshSource;
    use herb_sim::{Catalog, RewardMode, WorldConfig};
    use std::path::Path;
    use std::sync::Arc;

    /// A FIXTURE episode of five objects with primitive shapes.
    fn fixture_episode() -> (herb_sim::SharedCatalog, Episode) {
        let c = Arc::new(Catalog::builtin(&MeshSource::None("test".into())).unwrap());
        let objects = ["003", "004", "005", "007", "013"].map(|i| c.by_id(i).unwrap());
        let ep = Episode {
            name: "fixture".into(),
            objects: objects.to_vec(),
            human: vec![],
        };
        (c, ep)
    }

    /// The Table I path with an ONNX policy: a FIXTURE network packs an episode in the world,
    /// and every decision is timed.
    #[test]
    fn a_fixture_network_packs_an_episode_through_the_harness() {
        let (c, ep) = fixture_episode();
        let objects = ep.objects.clone();
        let order = Order::Largest.order(&c, None, &objects, 0).unwrap();
        let mut env =
            PackingEnv::new(c.clone(), WorldConfig::default(), RewardMode::Simple).unwrap();
        let fixture =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models/fixtures/tiny_policy.onnx");
        let p = OnnxPolicy::load(&fixture).unwrap();
        let clearance = env.world().config().clearance_m;
        let mut d = Decider::new(Box::new(p), c.clone(), clearance);
        let r = run_policy_episode(&mut env, &ep, &order, &mut d, 0).unwrap();
        assert!(r.placements >= 1);
        assert_eq!(r.decision_ns.len(), r.placements);
        assert!(r.decision_ns.iter().all(|&n| n > 0));
    }

    /// PackIt SO(3) lays the objects in the box in their preferred orientations: the cracker
    /// box (7 x 16 x 21 cm upright) goes on its largest face, and every object of a small
    /// episode (primitive shapes, a FIXTURE episode) ends inside.
    #[test]
    fn packit_so3_lays_objects_flat_and_packs_a_small_episode() {
        let (c, ep) = fixture_episode();
        let objects = ep.objects.clone();
        let mut env =
            PackingEnv::new(c.clone(), WorldConfig::default(), RewardMode::Simple).unwrap();
        let mut p = PackitSo3::new();
        let r = run_packit_so3_episode(&mut env, &ep, &objects, &mut p, 0).unwrap();
        assert!(r.success, "{r:?}");
        assert_eq!(r.decision_ns.len(), objects.len());
        let cracker = &env.world().placed()[0];
        let pose = env.world().pose_of(cracker);
        let e = c.shape(cracker.ty).extents();
        let smallest = e.x.min(e.y).min(e.z);
        let (lo, hi) = c.shape(cracker.ty).rotated_bounds(pose.rotation);
        assert!(
            (hi.z - lo.z - smallest).abs() < 0.01,
            "height {} against its smallest side {smallest}",
            hi.z - lo.z
        );
        assert!(hi.x - lo.x >= hi.y - lo.y, "longest side along x");
    }
}
