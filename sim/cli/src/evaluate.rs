//! Policy episodes for the Table I harness: the episode's objects in their order, each placed
//! by a decision-core policy, timing every decision the way the paper does (policy plus z
//! estimate).

use herb_decide::policy::{DecisionInput, Policy, check_action};
use herb_decide::{DecideError, Result};
use herb_sim::boxed::Episode;
use herb_sim::eval::EpisodeResult;
use herb_sim::observation::action_to_placement;
use herb_sim::{PackingEnv, TypeIdx};
use rapier3d::math::Rotation;
use std::time::Instant;

/// Runs one episode: `order` placed by `policy`. Each decision's latency (policy plus the z
/// estimate for the chosen placement) is recorded, and the object is released at that pose.
/// A decision without a feasible placement ends the episode as a failure with that reason.
pub fn run_policy_episode(
    env: &mut PackingEnv,
    ep: &Episode,
    order: &[TypeIdx],
    policy: &mut dyn Policy,
    seed: u64,
) -> Result<EpisodeResult> {
    env.reset(order, seed)?;
    policy.begin_episode(seed);
    let catalog = env.world().catalog().clone();
    let mut r = EpisodeResult::new(&ep.name, order.len());
    for (step, &object) in order.iter().enumerate() {
        let t0 = Instant::now();
        let action = {
            let input = DecisionInput {
                observation: env.observation(),
                heightmap: env.world().heightmap(),
                object,
                shape: catalog.shape(object),
                step,
                catalog: &catalog,
                after: &order[step + 1..],
            };
            match policy.decide(&input) {
                Ok(a) => check_action(policy.name(), a)?,
                Err(DecideError::NoFeasiblePlacement) => {
                    r.decision_ns.push(t0.elapsed().as_nanos() as u64);
                    r.record_no_feasible_placement();
                    break;
                }
                Err(e) => return Err(e),
            }
        };
        let (x, y, theta) = action_to_placement(action)?;
        let pose = env
            .world_mut()
            .release_pose(object, x, y, Rotation::from_rotation_z(theta));
        r.decision_ns.push(t0.elapsed().as_nanos() as u64);
        // Release where decided (the same pose `env.step(action)` would compute again).
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

    /// The Table I path with an ONNX policy: a FIXTURE network packs an episode in the world,
    /// and every decision is timed.
    #[test]
    fn a_fixture_network_packs_an_episode_through_the_harness() {
        let c = Arc::new(Catalog::builtin(&MeshSource::None("test".into())).unwrap());
        let ids = ["003", "004", "005", "007", "013"];
        let objects: Vec<_> = ids.iter().map(|i| c.by_id(i).unwrap()).collect();
        let ep = Episode {
            name: "fixture".into(),
            objects: objects.clone(),
            human: vec![],
        };
        let order = Order::Largest.order(&c, None, &objects, 0).unwrap();
        let mut env =
            PackingEnv::new(c.clone(), WorldConfig::default(), RewardMode::Simple).unwrap();
        let fixture =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models/fixtures/tiny_policy.onnx");
        let mut p = OnnxPolicy::load(&fixture).unwrap();
        let r = run_policy_episode(&mut env, &ep, &order, &mut p, 0).unwrap();
        assert!(r.placements >= 1);
        assert_eq!(r.decision_ns.len(), r.placements);
        assert!(r.decision_ns.iter().all(|&n| n > 0));
    }
}
