//! The decision core's methods as [`Placer`]s of the one episode loop
//! ([`herb_sim::eval::run_episode`]), and the registry's factory: [`Method::placer`] builds the
//! placer of any method of Table I from one [`MethodSettings`].

use crate::method::Method;
use herb_decide::policy::{PackitSo3, Policy};
use herb_decide::{DecideError, Decider, PolicySpec, Result};
use herb_search::{Search, SearchSettings, TwinKind};
use herb_sim::boxed::{Episode, participant};
use herb_sim::eval::{Decision, PlaceError, Placer, ReplayPlacer, release_at};
use herb_sim::{PackingEnv, RewardMode, SharedCatalog, WorldConfig};
use std::path::PathBuf;

/// herbd's decision path ([`Decider`]) as a placer of the episode loop.
pub struct DeciderPlacer<P: Policy + ?Sized = dyn Policy>(pub Decider<P>);

impl<P: Policy + ?Sized> Placer for DeciderPlacer<P> {
    fn name(&self) -> String {
        self.0.policy_name().into()
    }

    fn begin_episode(&mut self, _ep: &Episode, seed: u64) -> std::result::Result<(), PlaceError> {
        self.0.begin_episode(seed);
        Ok(())
    }

    /// herbd's decision path on the world's heightmap: the policy, the checks and the z
    /// estimate (one [`Decider::decide_on`] call).
    fn decide(
        &mut self,
        env: &mut PackingEnv,
    ) -> std::result::Result<Option<Decision>, PlaceError> {
        decide_in(&mut self.0, env)
    }
}

/// One decision of `decider` on the world's heightmap for the environment's remaining objects
/// (`None` when nothing is left or nothing fits).
fn decide_in<P: Policy + ?Sized>(
    decider: &mut Decider<P>,
    env: &mut PackingEnv,
) -> std::result::Result<Option<Decision>, PlaceError> {
    if env.next_object().is_none() {
        return Ok(None);
    }
    let d = decider.decide_on(env.camera().into(), env.remaining(), env.step_index());
    match d {
        Ok(d) => Ok(Some(Decision::Pose(d.pose()))),
        Err(DecideError::NoFeasiblePlacement) => Ok(None),
        Err(e) => Err(e.into()),
    }
}

/// The search as Table I runs it: herbd's decision path ([`Decider`] with the [`Search`] as
/// its policy), named with its budget and twin. With [`TwinKind::ExactClone`] (a measurement
/// of the twins' fidelity bound, not something herbd can do) the rollouts run in clones of the
/// evaluation's own world, outside the decision core.
pub struct SearchPlacer(pub Decider<Search>);

impl Placer for SearchPlacer {
    fn name(&self) -> String {
        self.0.policy().label()
    }

    /// A new episode is a new job: the job's twin starts from an empty box.
    fn begin_episode(&mut self, _ep: &Episode, seed: u64) -> std::result::Result<(), PlaceError> {
        self.0.begin_episode(seed);
        Ok(())
    }

    fn decide(
        &mut self,
        env: &mut PackingEnv,
    ) -> std::result::Result<Option<Decision>, PlaceError> {
        let search = self.0.policy_mut();
        if search.settings().twin == TwinKind::ExactClone {
            let p = search.decide(env.camera(), env.remaining(), Some(env.world()))?;
            return Ok(release_at(env, p));
        }
        decide_in(&mut self.0, env)
    }
}
/// The PackIt SO(3) heuristic as a placer of the episode loop.
pub struct PackitPlacer(pub PackitSo3);

impl Placer for PackitPlacer {
    fn name(&self) -> String {
        "packit-so3".into()
    }

    /// The PackIt heuristic over the 24 axis-aligned orientations on the world's heightmap,
    /// released at the estimated resting height plus the world's clearance.
    fn decide(
        &mut self,
        env: &mut PackingEnv,
    ) -> std::result::Result<Option<Decision>, PlaceError> {
        let Some(object) = env.next_object() else {
            return Ok(None);
        };
        let world = env.world();
        let shape = world.catalog().shape(object);
        let pose = self
            .0
            .decide(env.camera(), shape, world.config().clearance_m);
        Ok(pose.map(Decision::Pose))
    }
}

/// A behaviour-cloning method: each episode placed by the model trained without its
/// participant (even participants by the `heldout-even` model, odd ones by the other).
pub struct HeldOutPlacer {
    deciders: [DeciderPlacer; 2],
    active: usize,
}

impl Placer for HeldOutPlacer {
    fn name(&self) -> String {
        self.deciders[self.active].0.policy_name().into()
    }

    fn begin_episode(&mut self, ep: &Episode, seed: u64) -> std::result::Result<(), PlaceError> {
        let p = participant(&ep.name)
            .ok_or_else(|| format!("no participant number in the session name {:?}", ep.name))?;
        self.active = (p % 2) as usize;
        self.deciders[self.active].0.begin_episode(seed);
        Ok(())
    }

    fn decide(
        &mut self,
        env: &mut PackingEnv,
    ) -> std::result::Result<Option<Decision>, PlaceError> {
        Placer::decide(&mut self.deciders[self.active], env)
    }
}

/// What the methods of the registry may need besides the catalog: one value for the CLI, the
/// bindings, the benches and the tests.
#[derive(Debug, Clone)]
pub struct MethodSettings {
    /// The placement policy of [`Method::Herb`] (BLBF, a shipped policy or an ONNX file).
    pub policy: Option<PolicySpec>,
    /// The folder of the behaviour-cloning models ([`Method::bc_models`]).
    pub bc_models: PathBuf,
    /// Candidates the lookahead teachers simulate per decision.
    pub lookahead_k: usize,
    /// Reward whose return the lookahead teacher maximises.
    pub lookahead_reward: RewardMode,
    /// Objects per rollout of the lookahead teacher (`None`: to the episode's end).
    pub lookahead_horizon: Option<usize>,
    /// The search's settings ([`Method::Search`]).
    pub search: SearchSettings,
    /// The world's configuration: the release clearance of the decision core's policies and
    /// the physics of the search's twins.
    pub world: WorldConfig,
}

impl Default for MethodSettings {
    fn default() -> Self {
        Self {
            policy: None,
            bc_models: PathBuf::from(PolicySpec::DEFAULT_MODELS_DIR),
            lookahead_k: 8,
            lookahead_reward: RewardMode::CompactnessStability { alpha: 0.6 },
            lookahead_horizon: None,
            search: SearchSettings::default(),
            world: WorldConfig::default(),
        }
    }
}

impl Method {
    /// The placer of this method, built from `settings`: the one factory of the registry.
    /// [`Method::HumanRecorded`] is not a placement in the world
    /// ([`herb_sim::eval::recorded_episode`] scores it) and is an error here, as are a missing
    /// policy for [`Method::Herb`] and a model that does not load.
    pub fn placer(
        &self,
        catalog: &SharedCatalog,
        settings: &MethodSettings,
    ) -> Result<Box<dyn Placer>> {
        let decider = |p: Box<dyn Policy>| {
            DeciderPlacer(Decider::new(p, catalog.clone(), settings.world.clearance_m))
        };
        if let Some(replay) = self.replay() {
            return ReplayPlacer::new(replay)
                .map(|p| Box::new(p) as Box<dyn Placer>)
                .map_err(|e| DecideError::Method {
                    method: self.name(),
                    message: e.to_string(),
                });
        }
        if let Some(rule) = self.lattice_rule(
            catalog,
            settings.lookahead_k,
            settings.lookahead_reward,
            settings.lookahead_horizon,
        ) {
            return Ok(Box::new(rule));
        }
        if let Some(files) = self.bc_models(&settings.bc_models) {
            let [even, odd] = files.map(|f| load_policy_once(&PolicySpec::Onnx(f), catalog));
            return Ok(Box::new(HeldOutPlacer {
                deciders: [decider(even?), decider(odd?)],
                active: 0,
            }));
        }
        Ok(match self {
            Self::Herb => {
                let spec = settings.policy.as_ref().ok_or(DecideError::Method {
                    method: self.name(),
                    message: "needs a policy (e.g. models/policy-cs06.onnx or cs06)".into(),
                })?;
                Box::new(decider(load_policy_once(spec, catalog)?))
            }
            Self::Blbf => Box::new(decider(Box::new(herb_decide::Blbf::new()))),
            Self::PackitSo3 => Box::new(PackitPlacer(PackitSo3::new())),
            Self::Search => {
                let search = Search::new(catalog.clone(), settings.world.clone(), settings.search);
                Box::new(SearchPlacer(Decider::new(
                    Box::new(search),
                    catalog.clone(),
                    settings.world.clearance_m,
                )))
            }
            other => {
                return Err(DecideError::Method {
                    method: other.name(),
                    message: "has no placer".into(),
                });
            }
        })
    }
}

/// A policy loaded from a file in this process: the file as it was (size, time of change) and
/// the catalog it was built for.
struct Loaded {
    path: PathBuf,
    len: u64,
    modified: Option<std::time::SystemTime>,
    catalog: SharedCatalog,
    policy: Box<dyn Policy + Send>,
}

/// The policies loaded from files in this process ([`load_policy_once`]).
static LOADED: std::sync::Mutex<Vec<Loaded>> = std::sync::Mutex::new(Vec::new());

/// The catalogs [`load_policy_once`] read a model file for, once per read.
static READS: std::sync::Mutex<Vec<SharedCatalog>> = std::sync::Mutex::new(Vec::new());

/// [`herb_decide::load_policy`], with each model file loaded once per process: a policy
/// already loaded from the same file (same size and time of change) for the same catalog is
/// forked ([`Policy::fork`]: the optimised network shared, a session of its own) instead of read
/// and optimised again. Every placer of an evaluation's threads, and every task a sweep's
/// worker runs, then shares one load.
pub fn load_policy_once(spec: &PolicySpec, catalog: &SharedCatalog) -> Result<Box<dyn Policy>> {
    let resolved = spec.resolved(std::path::Path::new(PolicySpec::DEFAULT_MODELS_DIR));
    let PolicySpec::Onnx(path) = &resolved else {
        return herb_decide::load_policy(&resolved, catalog);
    };
    let meta = std::fs::metadata(path).ok();
    let len = meta.as_ref().map(|m| m.len());
    let modified = meta.as_ref().and_then(|m| m.modified().ok());
    // Held while loading: threads asking for the same file wait for the one load.
    let mut loaded = LOADED.lock().unwrap_or_else(|p| p.into_inner());
    let known = loaded.iter().find(|l| {
        l.path == *path
            && Some(l.len) == len
            && l.modified == modified
            && std::sync::Arc::ptr_eq(&l.catalog, catalog)
    });
    if let Some(p) = known.and_then(|l| l.policy.fork()) {
        return Ok(p);
    }
    READS
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .push(catalog.clone());
    let policy = herb_decide::load_policy(&resolved, catalog)?;
    if let (Some(len), Some(kept)) = (len, policy.fork()) {
        loaded.retain(|l| !(l.path == *path && std::sync::Arc::ptr_eq(&l.catalog, catalog)));
        loaded.push(Loaded {
            path: path.clone(),
            len,
            modified,
            catalog: catalog.clone(),
            policy: kept,
        });
    }
    Ok(policy)
}

/// How many times [`load_policy_once`] has read a model file for `catalog` in this process.
pub fn policy_file_reads(catalog: &SharedCatalog) -> usize {
    READS
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .iter()
        .filter(|c| std::sync::Arc::ptr_eq(c, catalog))
        .count()
}
