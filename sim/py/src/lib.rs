//! `herb_sim._native`: the packing world for Python training.
//!
//! [`VecEnv`] holds N independent [`PackingEnv`]s and steps them in parallel on a rayon pool,
//! with the GIL released: one Python call advances every environment. Observations are the
//! shared layout (`herb_sim::ObsLayout`, `[N, 2, 224, 224]` f32), actions `[N, 3]` in
//! `[-1, 1]`. Episodes are sampled as in the paper's training: a random multiset of catalog
//! objects (size uniform in `[min_objects, max_objects]`, types uniform), ordered by HERB's
//! Beam-3 over the human transition model (`Order::HERB`), by the other Beam-3 reading, or in
//! random order for the ablation. With `autoreset`, an environment whose episode ended starts
//! the next one in the same step (its returned observation is the new episode's first).
//!
//! [`VecEnv::expert_actions`] labels every environment's current state with the BLBF
//! heuristic's action (`Blbf` through herbd's `Decider`, the same path the `blbf` rows of Table I run), for
//! demonstration-guided training.
//!
//! The Gymnasium classes are in the Python package (`herb_sim/__init__.py`).

use herb_decide::sequence::SequenceModel;
use herb_decide::{Blbf, Decider, Order};
use herb_methods::Method;
use herb_search::{Budget, Search, SearchSettings, TwinKind};
use herb_sim::features::{self, CANDIDATE_LEN, CONTEXT_LEN, DecisionFeatures};
use herb_sim::lattice::{Lattice, MAX_CANDIDATES, Placement};
use herb_sim::paths::{self, MeshSource};
use herb_sim::teacher::{LatticeRule, Lookahead};
use herb_sim::{Catalog, ObsLayout, PackingEnv, RewardMode, SharedCatalog, TypeIdx, WorldConfig};
use numpy::ndarray::{Array1, Array2, Array3, Array4};
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyArray4, PyArrayDyn, PyReadonlyArray1,
    PyReadonlyArray2, PyReadonlyArrayDyn,
};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::path::Path;
use std::sync::Arc;

mod evaluation;
mod functions;
use functions::{half_turn_candidates, half_turn_context, human_demonstrations};

fn value_err(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// Samples training episodes.
struct Sampler {
    catalog_len: u16,
    order: Order,
    model: Option<Arc<SequenceModel>>,
    min_objects: usize,
    max_objects: usize,
}

impl Sampler {
    fn episode(&self, rng: &mut ChaCha8Rng) -> Vec<TypeIdx> {
        let mut v = herb_sim::sample_objects(
            rng,
            self.catalog_len as usize,
            self.min_objects..=self.max_objects,
        );
        match (self.order.beam_search(), &self.model) {
            (Some(search), Some(m)) => search(m, &v).unwrap_or(v),
            _ => {
                v.shuffle(rng);
                v
            }
        }
    }
}

struct Slot {
    env: PackingEnv,
    rng: ChaCha8Rng,
    running: bool,
    ret: f32,
    len: u32,
    /// The expert for [`VecEnv::expert_actions`]: BLBF through herbd's decision path.
    expert: Decider<Blbf>,
    /// The lattice rule of [`VecEnv::step_rule`], made on first use.
    rule: Option<LatticeRule>,
    /// The search of [`VecEnv::step_rule`] (`"search"`), made on first use.
    search: Option<Search>,
    /// The candidate inputs of the current state, once computed.
    feats: DecisionFeatures,
    /// `feats` describe the current state.
    feats_fresh: bool,
    /// Lattice and teacher for [`VecEnv::candidates`] and [`VecEnv::teacher`], made on first use.
    lattice: Option<Lattice>,
    teacher: Option<Lookahead>,
}

/// Results of one environment's step.
#[derive(Default, Clone, Copy)]
struct Out {
    reward: f32,
    terminated: bool,
    packed: u32,
    success: bool,
    ep_return: f32,
    ep_len: u32,
    /// The placement's C and S (0 without a placement).
    compactness: f32,
    stable: bool,
}

impl Out {
    /// The results of a placement step (episode totals are filled in later).
    fn of_step(r: &herb_sim::env::StepResult<'_>) -> Self {
        Self {
            reward: r.reward,
            terminated: r.terminated,
            packed: r.info.packed as u32,
            success: r.info.success,
            compactness: r.info.outcome.compactness,
            stable: r.info.outcome.stable,
            ..Self::default()
        }
    }
}

/// N packing environments stepped together.
#[pyclass(module = "herb_sim._native")]
struct VecEnv {
    slots: Vec<Slot>,
    sampler: Sampler,
    pool: rayon::ThreadPool,
    autoreset: bool,
    catalog: SharedCatalog,
}

impl VecEnv {
    fn reset_slot(sampler: &Sampler, s: &mut Slot) -> Result<(), String> {
        let ep = sampler.episode(&mut s.rng);
        let seed = s.rng.random();
        s.env.reset(&ep, seed).map_err(|e| e.to_string())?;
        s.running = true;
        s.ret = 0.0;
        s.len = 0;
        s.feats_fresh = false;
        Ok(())
    }

    /// An error naming the first environment whose episode has ended (without autoreset).
    fn ensure_running(&self) -> PyResult<()> {
        match self.slots.iter().position(|s| !s.running) {
            Some(i) => Err(PyRuntimeError::new_err(format!(
                "environment {i} has ended its episode: call reset()"
            ))),
            None => Ok(()),
        }
    }

    /// Computes the slot's candidate inputs for its current state.
    fn slot_features(catalog: &Catalog, s: &mut Slot) {
        let lattice = s.lattice.get_or_insert_with(|| Lattice::new(catalog));
        let remaining = s.env.remaining();
        match remaining.split_first() {
            Some((&next, after)) => {
                s.feats
                    .compute(lattice, catalog, s.env.camera(), next, after);
            }
            None => s.feats.clear(),
        }
        s.feats_fresh = true;
    }

    /// Stacks every slot's candidate inputs: `(context [N, G], candidates [N, C, F], mask
    /// [N, C])`.
    #[allow(clippy::type_complexity)]
    fn stack_features<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(
        Bound<'py, PyArray2<f32>>,
        Bound<'py, PyArray3<f32>>,
        Bound<'py, PyArray2<f32>>,
    )> {
        let n = self.slots.len();
        let ctx = Array2::from_shape_vec(
            (n, CONTEXT_LEN),
            self.slots
                .iter()
                .flat_map(|s| s.feats.context.iter().copied())
                .collect(),
        )
        .map_err(value_err)?;
        let cands = Array3::from_shape_vec(
            (n, MAX_CANDIDATES, CANDIDATE_LEN),
            self.slots
                .iter()
                .flat_map(|s| s.feats.candidates.iter().copied())
                .collect(),
        )
        .map_err(value_err)?;
        let mask = Array2::from_shape_vec(
            (n, MAX_CANDIDATES),
            self.slots
                .iter()
                .flat_map(|s| s.feats.mask.iter().copied())
                .collect(),
        )
        .map_err(value_err)?;
        Ok((
            ctx.into_pyarray(py),
            cands.into_pyarray(py),
            mask.into_pyarray(py),
        ))
    }

    fn observations<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray4<f32>>> {
        let n = self.slots.len();
        let mut buf = vec![0.0f32; n * ObsLayout::LEN];
        let slots = &self.slots;
        py.detach(|| {
            buf.par_chunks_mut(ObsLayout::LEN)
                .zip(slots.par_iter())
                .for_each(|(dst, s)| dst.copy_from_slice(s.env.observation()));
        });
        let a = Array4::from_shape_vec(
            (n, ObsLayout::CHANNELS, ObsLayout::SIZE, ObsLayout::SIZE),
            buf,
        )
        .map_err(value_err)?;
        Ok(a.into_pyarray(py))
    }
}

#[pymethods]
impl VecEnv {
    /// `num_envs` environments. `reward`: `simple`, `c` or `cs<alpha>`; `sequence`:
    /// `beam3` (HERB's order, Algorithm 1 read literally, `herb_decide::sequence::beam3`;
    /// the default, `HERB_ORDER`; alias `beam3-start`), `beam3-last` (each search rooted at
    /// the last object chosen) or `random`; `boxed`: the BoxED folder
    /// (meshes; default `HERB_BOXED` or ../shared/boxed, primitives without it);
    /// `meshes=False` forces primitives; `sequence_model`: the transition counts (default
    /// `models/sequence.json` in the working directory, else in the checkout the extension was
    /// built from); `threads`: rayon threads (default: all cores); `world`: `ideal` (default),
    /// `field` (the shipped field model, `models/field.toml`) or a field model file: the errors
    /// of a real cell the environments add, told to no rule, twin or policy.
    #[new]
    #[pyo3(signature = (num_envs, reward="cs0.6", sequence=None, seed=0, min_objects=10, max_objects=25, boxed=None, meshes=true, sequence_model=None, threads=None, autoreset=true, world=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        num_envs: usize,
        reward: &str,
        sequence: Option<&str>,
        seed: u64,
        min_objects: usize,
        max_objects: usize,
        boxed: Option<String>,
        meshes: bool,
        sequence_model: Option<String>,
        threads: Option<usize>,
        autoreset: bool,
        world: Option<&str>,
    ) -> PyResult<Self> {
        let cfg = world_config(world)?;
        if !(1..=4096).contains(&num_envs) {
            return Err(value_err(format!("num_envs {num_envs} outside 1..=4096")));
        }
        if min_objects == 0 || min_objects > max_objects || max_objects > 64 {
            return Err(value_err(format!(
                "objects per episode {min_objects}..={max_objects}: need 1 <= min <= max <= 64"
            )));
        }
        let reward = RewardMode::parse(reward).map_err(value_err)?;
        // Sampled episodes have no human order to keep and no reason to go largest first.
        let sequence = sequence.unwrap_or(Order::HERB.name());
        let order = match sequence.parse::<Order>() {
            Ok(o @ (Order::Beam3Last | Order::Beam3 | Order::Random)) => o,
            _ => {
                return Err(value_err(format!(
                    "sequence {sequence:?}: expected beam3, beam3-last or random"
                )));
            }
        };
        let root = paths::boxed_root(boxed.as_deref().map(Path::new));
        let source = if meshes {
            paths::mesh_source(None, root.as_deref())
        } else {
            MeshSource::None("meshes=False".into())
        };
        let catalog: SharedCatalog = Arc::new(Catalog::builtin(&source).map_err(value_err)?);
        let model = if order.uses_sequence_model() {
            let p = sequence_model
                .map(std::path::PathBuf::from)
                .unwrap_or_else(|| {
                    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models/sequence.json")
                });
            Some(Arc::new(
                SequenceModel::load(&p, &catalog).map_err(value_err)?,
            ))
        } else {
            None
        };
        let sampler = Sampler {
            catalog_len: catalog.len() as u16,
            order,
            model,
            min_objects,
            max_objects,
        };
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads.unwrap_or(0))
            .build()
            .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
        let mut root_rng = ChaCha8Rng::seed_from_u64(seed);
        let slots = (0..num_envs)
            .map(|_| {
                Ok(Slot {
                    env: PackingEnv::new(catalog.clone(), cfg.clone(), reward)
                        .map_err(value_err)?,
                    rng: ChaCha8Rng::seed_from_u64(root_rng.random()),
                    running: false,
                    ret: 0.0,
                    len: 0,
                    expert: Decider::new(
                        Box::new(Blbf::new()),
                        catalog.clone(),
                        WorldConfig::default().clearance_m,
                    ),
                    rule: None,
                    search: None,
                    feats: DecisionFeatures::default(),
                    feats_fresh: false,
                    lattice: None,
                    teacher: None,
                })
            })
            .collect::<PyResult<Vec<_>>>()?;
        Ok(Self {
            slots,
            sampler,
            pool,
            autoreset,
            catalog,
        })
    }

    /// Environments.
    #[getter]
    fn num_envs(&self) -> usize {
        self.slots.len()
    }

    /// Object types in the catalog.
    #[getter]
    fn catalog_len(&self) -> usize {
        self.catalog.len()
    }

    /// The observation shape of one environment, `(2, 224, 224)`.
    #[staticmethod]
    fn observation_shape() -> (usize, usize, usize) {
        (ObsLayout::CHANNELS, ObsLayout::SIZE, ObsLayout::SIZE)
    }

    /// Starts new episodes everywhere (reseeding every environment first when `seed` is
    /// given) and returns the observations `[N, 2, 224, 224]`.
    #[pyo3(signature = (seed=None))]
    fn reset<'py>(
        &mut self,
        py: Python<'py>,
        seed: Option<u64>,
    ) -> PyResult<Bound<'py, PyArray4<f32>>> {
        if let Some(seed) = seed {
            let mut r = ChaCha8Rng::seed_from_u64(seed);
            for s in &mut self.slots {
                s.rng = ChaCha8Rng::seed_from_u64(r.random());
            }
        }
        let (slots, sampler, pool) = (&mut self.slots, &self.sampler, &self.pool);
        py.detach(|| {
            pool.install(|| {
                slots
                    .par_iter_mut()
                    .map(|s| Self::reset_slot(sampler, s))
                    .collect::<Result<Vec<_>, _>>()
            })
        })
        .map_err(PyRuntimeError::new_err)?;
        self.observations(py)
    }

    /// The BLBF heuristic's action for each environment's next object, from the current
    /// heightmap: `(actions [N, 3], valid [N])`. `valid[i]` is false (and its action 0) where
    /// BLBF rejects the state (the object fits between the walls in neither yaw), or the
    /// environment's episode has ended (without autoreset).
    fn expert_actions<'py>(
        &mut self,
        py: Python<'py>,
    ) -> (Bound<'py, PyArray2<f32>>, Bound<'py, PyArray1<bool>>) {
        let (slots, pool) = (&mut self.slots, &self.pool);
        let labels: Vec<Option<[f32; 3]>> = py.detach(|| {
            pool.install(|| {
                slots
                    .par_iter_mut()
                    .map(|s| {
                        s.env.next_object()?;
                        // herbd's decision itself (`Decider::decide_on`): the labels are the
                        // placements the `blbf` rows of Table I send, as actions.
                        let heightmap = s.env.camera().into();
                        let d = s
                            .expert
                            .decide_on(heightmap, s.env.remaining(), s.len as usize);
                        let p = d.ok()?.placement;
                        Some(herb_sim::observation::placement_to_action(
                            p.x, p.y, p.theta,
                        ))
                    })
                    .collect()
            })
        });
        let acts =
            Array2::from_shape_fn((labels.len(), 3), |(i, k)| labels[i].map_or(0.0, |a| a[k]));
        let valid = Array1::from_iter(labels.iter().map(Option::is_some));
        (acts.into_pyarray(py), valid.into_pyarray(py))
    }

    /// Places each environment's next object at `actions[i]` (`[N, 3]`, clipped to
    /// `[-1, 1]`; NaN is an error). Returns `(observations, rewards, terminated, info)`;
    /// `info` holds arrays `packed`, `success`, the placement's `compactness` and `stable`,
    /// and, for environments whose episode just ended, `episode_return` and `episode_length`
    /// (others 0).
    #[allow(clippy::type_complexity)]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        actions: PyReadonlyArray2<'py, f32>,
    ) -> PyResult<(
        Bound<'py, PyArray4<f32>>,
        Bound<'py, PyArray1<f32>>,
        Bound<'py, PyArray1<bool>>,
        Bound<'py, PyDict>,
    )> {
        let a = actions.as_array();
        let n = self.slots.len();
        if a.shape() != [n, 3] {
            return Err(value_err(format!(
                "actions of shape {:?}, expected [{n}, 3]",
                a.shape()
            )));
        }
        if let Some(i) = a.iter().position(|v| !v.is_finite()) {
            return Err(value_err(format!(
                "action value {} at {} is not finite",
                a.iter().nth(i).unwrap(),
                i
            )));
        }
        self.ensure_running()?;
        let acts: Vec<[f32; 3]> = (0..n)
            .map(|i| std::array::from_fn(|k| a[[i, k]].clamp(-1.0, 1.0)))
            .collect();
        let (slots, sampler, pool, autoreset) =
            (&mut self.slots, &self.sampler, &self.pool, self.autoreset);
        let outs: Result<Vec<Out>, String> = py.detach(|| {
            pool.install(|| {
                slots
                    .par_iter_mut()
                    .zip(acts.par_iter())
                    .map(|(s, act)| {
                        let r = s.env.step(*act).map_err(|e| e.to_string())?;
                        let o = Out::of_step(&r);
                        Self::finish_step(sampler, s, o, autoreset)
                    })
                    .collect()
            })
        });
        self.step_result(py, outs)
    }

    /// The candidate policy's inputs for every environment's current state (the shared
    /// layout, `herb_sim::features`): `(context [N, CONTEXT_LEN], candidates [N,
    /// MAX_CANDIDATES, CANDIDATE_LEN], mask [N, MAX_CANDIDATES])`. An environment with no
    /// feasible placement (or whose episode ended) has an all-zero mask.
    #[allow(clippy::type_complexity)]
    fn candidates<'py>(
        &mut self,
        py: Python<'py>,
    ) -> PyResult<(
        Bound<'py, PyArray2<f32>>,
        Bound<'py, PyArray3<f32>>,
        Bound<'py, PyArray2<f32>>,
    )> {
        let (slots, pool, catalog) = (&mut self.slots, &self.pool, &self.catalog);
        py.detach(|| {
            pool.install(|| {
                slots
                    .par_iter_mut()
                    .for_each(|s| Self::slot_features(catalog, s))
            })
        });
        self.stack_features(py)
    }

    /// The lookahead teacher on every environment's current state: computes the candidate
    /// inputs (as [`VecEnv::candidates`]) and simulates the first `k` candidates, each followed
    /// by the lattice BLBF rule to the episode's end, under this environment's reward.
    /// Returns `(context, candidates, mask, returns [N, MAX_CANDIDATES], packed [N,
    /// MAX_CANDIDATES], choice [N], parts [N, MAX_CANDIDATES, 3])`: each simulated candidate's
    /// return and objects packed (NaN and -1 where not simulated), the teacher's choice (-1
    /// without candidates), and the return's parts, sum of C, sum of S and failed (0 or 1), so
    /// that it can be relabelled for another reward (NaN where not simulated). Step with
    /// [`VecEnv::step_candidates`]. With `horizon`, each rollout stops after that many objects
    /// (the candidate's included; returns then cover those placements only).
    #[allow(clippy::type_complexity)]
    #[pyo3(signature = (k=8, horizon=None))]
    fn teacher<'py>(
        &mut self,
        py: Python<'py>,
        k: usize,
        horizon: Option<usize>,
    ) -> PyResult<(
        Bound<'py, PyArray2<f32>>,
        Bound<'py, PyArray3<f32>>,
        Bound<'py, PyArray2<f32>>,
        Bound<'py, PyArray2<f32>>,
        Bound<'py, PyArray2<i32>>,
        Bound<'py, PyArray1<i64>>,
        Bound<'py, PyArray3<f32>>,
    )> {
        if !(1..=MAX_CANDIDATES).contains(&k) {
            return Err(value_err(format!("k {k} outside 1..={MAX_CANDIDATES}")));
        }
        if horizon == Some(0) {
            return Err(value_err("horizon 0: need at least 1 object"));
        }
        let horizon = horizon.unwrap_or(usize::MAX);
        let (slots, pool, catalog) = (&mut self.slots, &self.pool, &self.catalog);
        type Sim = (Vec<f32>, Vec<i32>, i64, Vec<f32>);
        let sims: Result<Vec<Sim>, String> = py.detach(|| {
            pool.install(|| {
                slots
                    .par_iter_mut()
                    .map(|s| {
                        Self::slot_features(catalog, s);
                        let mut rets = vec![f32::NAN; MAX_CANDIDATES];
                        let mut packed = vec![-1i32; MAX_CANDIDATES];
                        let mut parts = vec![f32::NAN; MAX_CANDIDATES * 3];
                        if s.feats.placements.is_empty() {
                            return Ok((rets, packed, -1, parts));
                        }
                        let reward = s.env.reward_mode();
                        let make = || Lookahead::new(catalog, k, reward).with_horizon(horizon);
                        let t = s.teacher.get_or_insert_with(make);
                        if t.k() != k || t.horizon() != horizon {
                            *t = make();
                        }
                        let chosen = t
                            .decide(s.env.world(), s.env.remaining())
                            .map_err(|e| e.to_string())?;
                        // The teacher's lattice saw the same state: its candidates are the rows.
                        for (j, o) in t.outcomes().iter().enumerate() {
                            debug_assert_eq!(o.placement, s.feats.placements[j]);
                            rets[j] = o.ret;
                            packed[j] = o.packed as i32;
                            parts[3 * j..3 * j + 3].copy_from_slice(&[
                                o.sum_c,
                                o.sum_s,
                                o.failed() as u8 as f32,
                            ]);
                        }
                        let choice = chosen
                            .and_then(|p| s.feats.placements.iter().position(|q| *q == p))
                            .map_or(-1, |j| j as i64);
                        Ok((rets, packed, choice, parts))
                    })
                    .collect()
            })
        });
        let sims = sims.map_err(PyRuntimeError::new_err)?;
        let (ctx, cands, mask) = self.stack_features(py)?;
        let n = sims.len();
        let rets = Array2::from_shape_vec(
            (n, MAX_CANDIDATES),
            sims.iter().flat_map(|x| x.0.iter().copied()).collect(),
        )
        .map_err(value_err)?;
        let packed = Array2::from_shape_vec(
            (n, MAX_CANDIDATES),
            sims.iter().flat_map(|x| x.1.iter().copied()).collect(),
        )
        .map_err(value_err)?;
        let choice = Array1::from_iter(sims.iter().map(|x| x.2));
        let parts = Array3::from_shape_vec(
            (n, MAX_CANDIDATES, 3),
            sims.iter().flat_map(|x| x.3.iter().copied()).collect(),
        )
        .map_err(value_err)?;
        Ok((
            ctx,
            cands,
            mask,
            rets.into_pyarray(py),
            packed.into_pyarray(py),
            choice.into_pyarray(py),
            parts.into_pyarray(py),
        ))
    }

    /// Places each environment's next object at its candidate `index[i]` from the last
    /// [`VecEnv::candidates`] or [`VecEnv::teacher`] call (which must describe the current
    /// state). An environment without candidates ends its episode, failed, with reward -1
    /// (its index is ignored); an index that is not a candidate is an error. Returns
    /// `(rewards, terminated, info)` as [`VecEnv::step`] without the observations; call
    /// `candidates()` for the next state.
    #[allow(clippy::type_complexity)]
    fn step_candidates<'py>(
        &mut self,
        py: Python<'py>,
        index: PyReadonlyArray1<'py, i64>,
    ) -> PyResult<(
        Bound<'py, PyArray1<f32>>,
        Bound<'py, PyArray1<bool>>,
        Bound<'py, PyDict>,
    )> {
        let idx = index.as_array();
        let n = self.slots.len();
        if idx.len() != n {
            return Err(value_err(format!(
                "{} indices for {n} environments",
                idx.len()
            )));
        }
        self.ensure_running()?;
        for (i, s) in self.slots.iter().enumerate() {
            if !s.feats_fresh {
                return Err(PyRuntimeError::new_err(format!(
                    "environment {i}: call candidates() or teacher() before step_candidates()"
                )));
            }
            let c = s.feats.placements.len();
            if c > 0 && !(0..c as i64).contains(&idx[i]) {
                return Err(value_err(format!(
                    "index {} of environment {i} is not one of its {c} candidates",
                    idx[i]
                )));
            }
        }
        let idx: Vec<i64> = idx.iter().copied().collect();
        let (slots, sampler, pool, autoreset) =
            (&mut self.slots, &self.sampler, &self.pool, self.autoreset);
        let outs: Result<Vec<Out>, String> = py.detach(|| {
            pool.install(|| {
                slots
                    .par_iter_mut()
                    .zip(idx.par_iter())
                    .map(|(s, &j)| {
                        s.feats_fresh = false;
                        let p = s.feats.placements.get(j as usize).copied();
                        let o = Self::place(s, p)?;
                        Self::finish_step(sampler, s, o, autoreset)
                    })
                    .collect()
            })
        });
        let outs = outs.map_err(PyRuntimeError::new_err)?;
        let info = Self::info_dict(py, &outs)?;
        Ok((
            Array1::from_iter(outs.iter().map(|o| o.reward)).into_pyarray(py),
            Array1::from_iter(outs.iter().map(|o| o.terminated)).into_pyarray(py),
            info,
        ))
    }

    /// Places each environment's next object with a lattice rule decided in Rust: `rule` is
    /// `lattice-blbf` (the BLBF rule restricted to the placement lattice) or `lookahead` (the
    /// teacher: the best of the first `k` lattice candidates by the return, under this
    /// environment's reward, of a lattice-BLBF rollout to the episode's end). An object
    /// without a feasible placement ends its episode, failed, with reward -1. With `active`
    /// (`[N]` bool), only the environments marked true are stepped (the others report reward
    /// 0, not terminated, and keep their state). `horizon` limits the `lookahead` teacher's
    /// rollouts to that many objects (see [`VecEnv::teacher`]). `search` is the decision-time
    /// search (`herb_search`): the first `k` lattice candidates in lattice BLBF's order,
    /// each rolled out (`rollouts`, default `k`), in the job's own twin (`twin="job"`, herbd's
    /// and the default), a twin built from the heightmap (`twin="heightmap"`) or a clone of the
    /// environment's world (`twin="exact"`), on `search_threads` threads per environment (the
    /// environments themselves run in parallel already).
    /// Returns as [`VecEnv::step`].
    #[allow(clippy::type_complexity, clippy::too_many_arguments)]
    #[pyo3(signature = (rule, k=8, active=None, horizon=None, rollouts=None, twin="job", search_threads=1))]
    fn step_rule<'py>(
        &mut self,
        py: Python<'py>,
        rule: &str,
        k: usize,
        active: Option<PyReadonlyArray1<'py, bool>>,
        horizon: Option<usize>,
        rollouts: Option<usize>,
        twin: &str,
        search_threads: usize,
    ) -> PyResult<(
        Bound<'py, PyArray4<f32>>,
        Bound<'py, PyArray1<f32>>,
        Bound<'py, PyArray1<bool>>,
        Bound<'py, PyDict>,
    )> {
        if !(1..=MAX_CANDIDATES).contains(&k) {
            return Err(value_err(format!("k {k} outside 1..={MAX_CANDIDATES}")));
        }
        if horizon == Some(0) {
            return Err(value_err("horizon 0: need at least 1 object"));
        }
        let twin = TwinKind::parse(twin).map_err(value_err)?;
        if !(1..=64).contains(&search_threads) {
            return Err(value_err(format!(
                "search_threads {search_threads} outside 1..=64"
            )));
        }
        let search_settings = SearchSettings {
            k,
            budget: Budget::Rollouts(rollouts.unwrap_or(k)),
            horizon,
            reward: self
                .slots
                .first()
                .map_or(RewardMode::Simple, |s| s.env.reward_mode()),
            twin,
            threads: search_threads,
            ..SearchSettings::default()
        };
        let horizon = horizon.unwrap_or(usize::MAX);
        let method = match rule.parse::<Method>() {
            Ok(m) if m.is_lattice_rule() || m == Method::Search => m,
            _ => {
                return Err(value_err(format!(
                    "rule {rule:?}: expected lattice-blbf, lookahead, lattice-reserve, geo-lookahead or search"
                )));
            }
        };
        let n = self.slots.len();
        let active: Vec<bool> = match active {
            Some(a) => a.as_array().iter().copied().collect(),
            None => vec![true; n],
        };
        if active.len() != n {
            return Err(value_err(format!(
                "active has {} values for {n} environments",
                active.len()
            )));
        }
        self.ensure_running()?;
        let catalog = self.catalog.clone();
        let (slots, sampler, pool, autoreset) =
            (&mut self.slots, &self.sampler, &self.pool, self.autoreset);
        let outs: Result<Vec<Out>, String> = py.detach(|| {
            pool.install(|| {
                slots
                    .par_iter_mut()
                    .zip(active.par_iter())
                    .map(|(s, &on)| {
                        if !on {
                            return Ok(Out::default());
                        }
                        if method == Method::Search {
                            let search = match &mut s.search {
                                Some(x) if *x.settings() == search_settings => x,
                                slot => slot.insert(Search::new(
                                    catalog.clone(),
                                    s.env.world().config().clone(),
                                    search_settings,
                                )),
                            };
                            let exact = (twin == TwinKind::ExactClone).then(|| s.env.world());
                            let p = search
                                .decide(s.env.camera(), s.env.remaining(), exact)
                                .map_err(|e| e.to_string())?;
                            let o = Self::place(s, p)?;
                            return Self::finish_step(sampler, s, o, autoreset);
                        }
                        let fits = match (&s.rule, method) {
                            (Some(LatticeRule::Blbf(_)), Method::LatticeBlbf) => true,
                            (Some(LatticeRule::Lookahead(t)), Method::Lookahead) => {
                                t.k() == k && t.horizon() == horizon
                            }
                            (Some(LatticeRule::Reserve(_)), Method::LatticeReserve) => true,
                            (Some(LatticeRule::Geo(t)), Method::GeoLookahead) => t.k() == k,
                            _ => false,
                        };
                        if !fits {
                            let reward = s.env.reward_mode();
                            s.rule = method.lattice_rule(&catalog, k, reward, Some(horizon));
                        }
                        let r = s.rule.as_mut().expect("set above");
                        let p = r.decide(&s.env).map_err(|e| e.to_string())?;
                        let o = Self::place(s, p)?;
                        Self::finish_step(sampler, s, o, autoreset)
                    })
                    .collect()
            })
        });
        self.step_result(py, outs)
    }
}

impl VecEnv {
    /// Places the slot's next object at `p`; without a placement (no feasible one) the episode
    /// ends, failed, with reward -1.
    fn place(s: &mut Slot, p: Option<Placement>) -> Result<Out, String> {
        let Some(p) = p else {
            return Ok(Out {
                reward: -1.0,
                terminated: true,
                packed: s.env.world().placed().len() as u32,
                success: false,
                ..Out::default()
            });
        };
        let r = s
            .env
            .step_placement(p.x, p.y, p.theta())
            .map_err(|e| e.to_string())?;
        Ok(Out::of_step(&r))
    }

    /// Books a step's reward and, when the episode ended, its return and length, and resets
    /// the slot under autoreset.
    fn finish_step(
        sampler: &Sampler,
        s: &mut Slot,
        mut o: Out,
        autoreset: bool,
    ) -> Result<Out, String> {
        s.ret += o.reward;
        s.len += 1;
        if o.terminated {
            o.ep_return = s.ret;
            o.ep_len = s.len;
            s.running = false;
            if autoreset {
                Self::reset_slot(sampler, s)?;
            }
        }
        Ok(o)
    }

    /// The Python return value of a step.
    #[allow(clippy::type_complexity)]
    fn step_result<'py>(
        &self,
        py: Python<'py>,
        outs: Result<Vec<Out>, String>,
    ) -> PyResult<(
        Bound<'py, PyArray4<f32>>,
        Bound<'py, PyArray1<f32>>,
        Bound<'py, PyArray1<bool>>,
        Bound<'py, PyDict>,
    )> {
        let outs = outs.map_err(PyRuntimeError::new_err)?;
        let obs = self.observations(py)?;
        let info = Self::info_dict(py, &outs)?;
        Ok((
            obs,
            Array1::from_iter(outs.iter().map(|o| o.reward)).into_pyarray(py),
            Array1::from_iter(outs.iter().map(|o| o.terminated)).into_pyarray(py),
            info,
        ))
    }

    /// The `info` dictionary of a step: `packed`, `success`, `episode_return`,
    /// `episode_length`, and the placement's `compactness` (C) and `stable` (S).
    fn info_dict<'py>(py: Python<'py>, outs: &[Out]) -> PyResult<Bound<'py, PyDict>> {
        let info = PyDict::new(py);
        info.set_item(
            "packed",
            Array1::from_iter(outs.iter().map(|o| o.packed)).into_pyarray(py),
        )?;
        info.set_item(
            "success",
            Array1::from_iter(outs.iter().map(|o| o.success)).into_pyarray(py),
        )?;
        info.set_item(
            "episode_return",
            Array1::from_iter(outs.iter().map(|o| o.ep_return)).into_pyarray(py),
        )?;
        info.set_item(
            "episode_length",
            Array1::from_iter(outs.iter().map(|o| o.ep_len)).into_pyarray(py),
        )?;
        info.set_item(
            "compactness",
            Array1::from_iter(outs.iter().map(|o| o.compactness)).into_pyarray(py),
        )?;
        info.set_item(
            "stable",
            Array1::from_iter(outs.iter().map(|o| o.stable)).into_pyarray(py),
        )?;
        Ok(info)
    }
}

/// The environments' world: `ideal` (or `None`), `field` (the shipped field model: the working
/// directory's `models/field.toml`, else the checkout's the extension was built from) or a field
/// model file.
fn world_config(world: Option<&str>) -> PyResult<WorldConfig> {
    match herb_sim::field::FieldModel::by_name(world.unwrap_or("ideal")) {
        Ok(None) => Ok(WorldConfig::default()),
        Ok(Some(m)) => m.apply(&WorldConfig::default()).map_err(value_err),
        Err(e) => Err(value_err(e)),
    }
}

/// The native module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<VecEnv>()?;
    m.add_class::<evaluation::Evaluation>()?;
    m.add_function(wrap_pyfunction!(evaluation::csv_rows, m)?)?;
    m.add_function(wrap_pyfunction!(evaluation::report, m)?)?;
    m.add_function(wrap_pyfunction!(evaluation::release_noise_note, m)?)?;
    m.add_function(wrap_pyfunction!(evaluation::summary, m)?)?;
    m.add_function(wrap_pyfunction!(evaluation::interval_chart, m)?)?;
    m.add("CSV_HEADER", herb_methods::evaluation::CSV_HEADER)?;
    m.add_function(wrap_pyfunction!(half_turn_candidates, m)?)?;
    m.add_function(wrap_pyfunction!(half_turn_context, m)?)?;
    m.add_function(wrap_pyfunction!(human_demonstrations, m)?)?;
    m.add("HERB_ORDER", Order::HERB.name())?;
    m.add("OBS_LEN", ObsLayout::LEN)?;
    m.add("MODEL_INPUT_SHAPE", ObsLayout::INPUT_SHAPE.to_vec())?;
    m.add("OBS_SIZE", ObsLayout::SIZE)?;
    m.add("OBS_CHANNELS", ObsLayout::CHANNELS)?;
    m.add("HEIGHT_SCALE_M", ObsLayout::HEIGHT_SCALE_M)?;
    m.add("MODEL_OUTPUT_SHAPE", ObsLayout::OUTPUT_SHAPE.to_vec())?;
    m.add("INPUT_NAME", ObsLayout::INPUT_NAME)?;
    m.add("OUTPUT_NAME", ObsLayout::OUTPUT_NAME)?;
    m.add("OBS_CELL_M", ObsLayout::CELL_M)?;
    m.add("BOX_HALF_X", herb_sim::frames::BOX_HALF_X)?;
    m.add("BOX_HALF_Y", herb_sim::frames::BOX_HALF_Y)?;
    m.add("CONTEXT_LEN", CONTEXT_LEN)?;
    m.add("CANDIDATE_LEN", CANDIDATE_LEN)?;
    m.add("MAX_CANDIDATES", MAX_CANDIDATES)?;
    Ok(())
}
