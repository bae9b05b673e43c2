//! Policy episodes for the Table I harness: order the episode's objects with a sequence mode,
//! then let a policy place each one, timing every decision the way the paper does (policy
//! plus z estimate).

use crate::error::{DecideError, Result};
use crate::policy::{DecisionInput, Policy, check_action};
use crate::sequence::{SequenceModel, beam3};
use herb_sim::boxed::Episode;
use herb_sim::eval::EpisodeResult;
use herb_sim::observation::action_to_placement;
use herb_sim::{Catalog, PackingEnv, TypeIdx};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use rapier3d::math::Rotation;
use std::time::Instant;

/// How the objects of an episode are ordered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SequenceMode {
    /// Beam-3 over the human transition model.
    Beam3,
    /// The human order.
    Human,
    /// Largest hull volume first (ties: catalog order).
    Largest,
    /// A uniform random permutation (seeded per episode).
    Random,
}

impl SequenceMode {
    /// Name used on the command line and in tables.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Beam3 => "beam3",
            Self::Human => "human",
            Self::Largest => "largest",
            Self::Random => "random",
        }
    }

    /// Orders `objects` (given in the human order). `model` is needed for Beam-3.
    pub fn order(
        &self,
        catalog: &Catalog,
        model: Option<&SequenceModel>,
        objects: &[TypeIdx],
        seed: u64,
    ) -> Result<Vec<TypeIdx>> {
        if objects.is_empty() {
            return Err(DecideError::EmptyObjectList);
        }
        match self {
            Self::Beam3 => {
                let m = model.ok_or_else(|| DecideError::SequenceModel {
                    origin: "beam3".into(),
                    message: "no sequence model loaded".into(),
                })?;
                beam3(m, objects)
            }
            Self::Human => Ok(objects.to_vec()),
            Self::Largest => {
                let mut v = objects.to_vec();
                v.sort_by(|&a, &b| {
                    catalog
                        .shape(b)
                        .volume
                        .total_cmp(&catalog.shape(a).volume)
                        .then(a.cmp(&b))
                });
                Ok(v)
            }
            Self::Random => {
                let mut v = objects.to_vec();
                v.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
                Ok(v)
            }
        }
    }
}

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
