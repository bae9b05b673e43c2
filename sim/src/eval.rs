//! Batch evaluation over BoxED episodes: runs a method on every episode and summarises the
//! paper's metrics (Table I): success rate, objects packed, final compactness, stability.
//!
//! - **success**: every object of the episode placed, all inside the success volume;
//! - **objects packed**: placements that ended inside before the episode ended;
//! - **final compactness**: C after the last placement, averaged over successful episodes;
//! - **stability**: share of all placements made with S = 1 (tilt <= 10 degrees).

use crate::boxed::{Episode, HumanPlacement};
use crate::catalog::Catalog;
use crate::catalog::SharedCatalog;
use crate::env::{PackingEnv, RewardMode, StepResult};
use crate::error::{Result, SimError};
use crate::heightmap::Heightmap;
use crate::world::{SuccessVolume, WorldConfig, bounds_of, compactness_of};
use rapier3d::math::{Pose, Rotation, Vector};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

/// The humans' own packs, replayed or checked: the methods of Table I that take the human order
/// and, but for [`Replay::Random`], the humans' placements. A [`ReplayPlacer`] places them in the
/// world; [`Replay::HumanRecorded`] is scored without physics ([`recorded_episode`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Replay {
    /// The human order with the humans' own planar placements.
    Human,
    /// The human order with the humans' full orientations (tilted placements included) at their
    /// (x, y), z from the heightmap: the closest replay of what the humans did.
    HumanPose,
    /// The human order with uniform random actions (seeded per episode).
    Random,
    /// No physics: the humans' recorded poses (first placements) checked against the success
    /// volume, as the paper scores its human row ([`recorded_episode`]).
    HumanRecorded,
}

impl Replay {
    /// Name used on the command line and in tables.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Human => "human",
            Self::HumanPose => "human-pose",
            Self::Random => "random",
            Self::HumanRecorded => "human-recorded",
        }
    }
}

/// The result of one episode (serialisable: a sweep's tasks send it from the worker that ran it
/// to the one that writes the tables).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EpisodeResult {
    /// Session name.
    pub name: String,
    /// Objects in the episode.
    pub objects: usize,
    /// Objects placed inside before the episode ended.
    pub packed: usize,
    /// All objects placed inside.
    pub success: bool,
    /// Placements attempted.
    pub placements: usize,
    /// Placements with S = 1.
    pub stable: usize,
    /// C after each placement.
    pub compactness_per_step: Vec<f32>,
    /// Simulated physics steps in all.
    pub physics_steps: u64,
    /// Decision latency of each placement (ns): one `herb_decide::Decider::decide` call for the
    /// decision-core policies; empty for replays.
    pub decision_ns: Vec<u64>,
    /// Why the episode failed: the bound crossed (`"floor"`, `"+x wall"`, `"top"`...), and
    /// whether the object outside was the one just placed or an earlier one knocked out.
    pub failure: Option<Failure>,
}

/// The failure bound recorded when a decision found no feasible placement.
pub const NO_FEASIBLE_PLACEMENT: &str = "no feasible placement";

/// The cause of a failed episode.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Failure {
    /// The bound of the success volume crossed most (see `PlacementOutcome::violation`).
    pub bound: &'static str,
    /// By how much (m).
    pub by_m: f32,
    /// The object outside was placed before the last placement (knocked out or pushed).
    pub earlier_object: bool,
}

/// A [`Failure`] as read back (its bound any text until checked).
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct FailureText {
    bound: String,
    by_m: f32,
    earlier_object: bool,
}

impl<'de> serde::Deserialize<'de> for Failure {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        Failure::try_from(FailureText::deserialize(d)?).map_err(serde::de::Error::custom)
    }
}

impl TryFrom<FailureText> for Failure {
    type Error = String;

    /// Takes the bound back as one of the names the world reports ([`SuccessVolume::BOUNDS`],
    /// [`NO_FEASIBLE_PLACEMENT`]).
    fn try_from(f: FailureText) -> std::result::Result<Self, String> {
        let bound = SuccessVolume::BOUNDS
            .into_iter()
            .chain([NO_FEASIBLE_PLACEMENT])
            .find(|b| *b == f.bound)
            .ok_or_else(|| format!("unknown failure bound {:?}", f.bound))?;
        Ok(Failure {
            bound,
            by_m: f.by_m,
            earlier_object: f.earlier_object,
        })
    }
}

impl Failure {
    /// A short label such as `floor (placed)` or `+x wall (earlier)`.
    pub fn label(&self) -> String {
        if self.bound == NO_FEASIBLE_PLACEMENT {
            return self.bound.to_owned();
        }
        format!(
            "{} ({})",
            self.bound,
            if self.earlier_object {
                "earlier object"
            } else {
                "placed object"
            }
        )
    }
}

impl EpisodeResult {
    /// An empty result for an episode of `objects` objects.
    pub fn new(name: &str, objects: usize) -> Self {
        Self {
            name: name.to_owned(),
            objects,
            packed: 0,
            success: false,
            placements: 0,
            stable: 0,
            compactness_per_step: Vec::with_capacity(objects),
            physics_steps: 0,
            decision_ns: Vec::with_capacity(objects),
            failure: None,
        }
    }

    /// Records one step's outcome; true when the episode has ended.
    pub fn record(&mut self, step: &StepResult) -> bool {
        let o = &step.info.outcome;
        self.placements += 1;
        self.stable += o.stable as usize;
        self.physics_steps += o.settle_steps as u64;
        self.compactness_per_step.push(o.compactness);
        self.packed = step.info.packed;
        self.success = step.info.success;
        if let (Some(first), Some((bound, by_m))) = (o.first_outside, o.violation) {
            self.failure = Some(Failure {
                bound,
                by_m,
                earlier_object: first + 1 < self.placements,
            });
        }
        step.terminated
    }

    /// Records that the next object had no feasible placement: the episode ends failed.
    pub fn record_no_feasible_placement(&mut self) {
        self.success = false;
        self.failure = Some(Failure {
            bound: NO_FEASIBLE_PLACEMENT,
            by_m: 0.0,
            earlier_object: false,
        });
    }

    /// C after the last placement (0 if none).
    pub fn final_compactness(&self) -> f32 {
        self.compactness_per_step.last().copied().unwrap_or(0.0)
    }
}

/// How far (m, per axis) a replayed human placement whose footprint crosses a wall is slid
/// back inside: humans push objects against the walls, and our hulls and the recorded poses
/// are a few millimetres off the real objects.
pub const REPLAY_WALL_SLIDE_M: f32 = 0.015;

/// Where a placer puts the next object: a pose (released as is), a planar placement or a
/// rotation at (x, y) (z from the heightmap), or an action in `[-1, 1]^3`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Decision {
    /// The release pose, in B.
    Pose(Pose),
    /// Planar placement: (x, y) in B (m) and yaw (rad); z from the heightmap.
    Planar {
        /// x in B (m).
        x: f32,
        /// y in B (m).
        y: f32,
        /// Yaw (rad).
        theta: f32,
    },
    /// Full orientation at (x, y); z from the heightmap.
    Rotated {
        /// x in B (m).
        x: f32,
        /// y in B (m).
        y: f32,
        /// Orientation.
        rotation: Rotation,
    },
    /// An action in `[-1, 1]^3` ([`PackingEnv::step`]).
    Action([f32; 3]),
}

/// What a placer's own failure carries (a decision-core error, a model error...).
pub type PlaceError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// A placement method as the one episode loop ([`run_episode`]) drives it: every method of
/// Table I (policies, rules, teachers, replays), the training bindings' rules and the benches
/// place through this.
pub trait Placer {
    /// Name for tables and logs.
    fn name(&self) -> String;
    /// Starts an episode: `ep` (its name and the humans' placements), `seed` its seed. Called
    /// after the environment's reset.
    fn begin_episode(&mut self, _ep: &Episode, _seed: u64) -> std::result::Result<(), PlaceError> {
        Ok(())
    }
    /// Where the environment's next object goes; `None` when no placement is feasible (the
    /// episode ends, failed).
    fn decide(&mut self, env: &mut PackingEnv)
    -> std::result::Result<Option<Decision>, PlaceError>;
    /// Whether decisions are timed into [`EpisodeResult::decision_ns`] (the deciding methods;
    /// not the replays, whose "decision" is a lookup).
    fn timed(&self) -> bool {
        true
    }
}

/// Places the environment's next object as `d` says.
pub fn apply<'a>(env: &'a mut PackingEnv, d: Decision) -> Result<StepResult<'a>> {
    match d {
        Decision::Pose(pose) => env.step_pose(pose),
        Decision::Planar { x, y, theta } => env.step_placement(x, y, theta),
        Decision::Rotated { x, y, rotation } => env.step_rotated(x, y, rotation),
        Decision::Action(a) => env.step(a),
    }
}

/// The decision releasing the environment's next object at lattice placement `p`, at the
/// world's release pose (its z estimate is part of the timed decision); `None` without `p` or
/// once the episode is over. The lattice rules and the search decide through this.
pub fn release_at(env: &mut PackingEnv, p: Option<crate::lattice::Placement>) -> Option<Decision> {
    let (p, object) = (p?, env.next_object()?);
    let rotation = Rotation::from_rotation_z(p.theta());
    Some(Decision::Pose(env.release_pose(object, p.x, p.y, rotation)))
}

/// A human replay in the world ([`Replay::Human`], [`Replay::HumanPose`], [`Replay::Random`]).
#[derive(Debug, Clone)]
pub struct ReplayPlacer {
    replay: Replay,
    human: Vec<HumanPlacement>,
    episode: String,
}

impl ReplayPlacer {
    /// A placer replaying `replay`; an error for [`Replay::HumanRecorded`], which is not a
    /// placement in the world.
    pub fn new(replay: Replay) -> Result<Self> {
        if replay == Replay::HumanRecorded {
            return Err(SimError::Config(
                "human-recorded is a check of the recorded poses, not a placement in the world"
                    .into(),
            ));
        }
        Ok(Self {
            replay,
            human: Vec::new(),
            episode: String::new(),
        })
    }
}

impl Placer for ReplayPlacer {
    fn name(&self) -> String {
        self.replay.name().into()
    }

    fn begin_episode(&mut self, ep: &Episode, _seed: u64) -> std::result::Result<(), PlaceError> {
        self.human.clone_from(&ep.human);
        self.episode.clone_from(&ep.name);
        Ok(())
    }

    /// The human replays release at the recorded (x, y), slid inside the walls by up to
    /// [`REPLAY_WALL_SLIDE_M`], at z from the heightmap (the recorded z is not used: our pile
    /// differs from the human's by millimetres, and a body released into another is pushed out
    /// hard).
    fn decide(
        &mut self,
        env: &mut PackingEnv,
    ) -> std::result::Result<Option<Decision>, PlaceError> {
        if self.replay == Replay::Random {
            return Ok(Some(Decision::Action(env.sample_action())));
        }
        let i = env.step_index();
        let (Some(h), Some(ty)) = (self.human.get(i), env.next_object()) else {
            return Err(SimError::Config(format!(
                "episode {} has no human placement {i}",
                self.episode
            ))
            .into());
        };
        let rotation = match self.replay {
            Replay::HumanPose => h.rotation,
            _ => Rotation::from_rotation_z(h.theta),
        };
        let (x, y) = env
            .world()
            .slide_inside(ty, h.x, h.y, rotation, REPLAY_WALL_SLIDE_M);
        Ok(Some(match self.replay {
            Replay::HumanPose => Decision::Rotated { x, y, rotation },
            _ => Decision::Planar {
                x,
                y,
                theta: h.theta,
            },
        }))
    }

    fn timed(&self) -> bool {
        false
    }
}

/// The humans' own packs, scored as the paper scores its human row: each object of `ep` at its
/// recorded pose (the first placement of each instance, in B) checked against the success
/// volume widened by `tolerance_m` ([`SuccessVolume`], the world's own check), with no physics.
/// Objects packed: those before the first object outside (the same rule as the world's
/// episodes); success: every object inside. Stability: recorded tilts within
/// `stability_tilt_deg`; C after each object from the recorded poses. The recorded pose is the
/// object's pose when it was let go: an object later pushed by the human is not seen. An
/// episode with a missing or non-finite recorded pose is an error naming the object.
pub fn recorded_episode(
    catalog: &Catalog,
    ep: &Episode,
    tolerance_m: f32,
    stability_tilt_deg: f32,
) -> Result<EpisodeResult> {
    if ep.human.len() != ep.objects.len() {
        return Err(SimError::Session {
            session: ep.name.clone(),
            message: format!(
                "{} recorded poses for {} objects",
                ep.human.len(),
                ep.objects.len()
            ),
        });
    }
    let volume_ok = SuccessVolume::new(tolerance_m);
    let mut r = EpisodeResult::new(&ep.name, ep.objects.len());
    let (mut lo, mut hi) = (Vector::splat(f32::MAX), Vector::splat(f32::MIN));
    let mut volume = 0.0f32;
    let mut verts = Vec::new();
    for (i, (&ty, h)) in ep.objects.iter().zip(&ep.human).enumerate() {
        let pose = recorded_pose(catalog, ep, i)?;
        let shape = catalog.shape(ty);
        verts.clear();
        verts.extend(shape.vertices.iter().map(|&v| pose.transform_point(v)));
        let (blo, bhi) = bounds_of(&verts);
        lo = lo.min(blo);
        hi = hi.max(bhi);
        volume += shape.volume;
        r.placements += 1;
        r.stable += (h.tilt_rad <= stability_tilt_deg.to_radians()) as usize;
        r.compactness_per_step.push(compactness_of(volume, lo, hi));
        if r.failure.is_none()
            && let Some((bound, by_m)) = volume_ok.violation(blo, bhi)
        {
            r.failure = Some(Failure {
                bound,
                by_m,
                earlier_object: false,
            });
        }
        if r.failure.is_none() {
            r.packed += 1;
        }
    }
    r.success = r.failure.is_none();
    Ok(r)
}

/// The heightmap of the humans' own scene just before object `next` of `ep` is placed: objects
/// `0..next` at their recorded poses, rendered as the world renders its objects, without
/// physics. What the BC rows of Table I learn from. `hm` is cleared first; a missing or
/// non-finite recorded pose is an error naming the object.
pub fn recorded_heightmap(
    catalog: &Catalog,
    ep: &Episode,
    next: usize,
    hm: &mut Heightmap,
) -> Result<()> {
    hm.clear();
    let mut verts = Vec::new();
    for i in 0..next {
        let pose = recorded_pose(catalog, ep, i)?;
        let shape = catalog.shape(ep.objects[i]);
        verts.clear();
        verts.extend(shape.vertices.iter().map(|&v| pose.transform_point(v)));
        hm.raise_to_hull(&mut verts, &shape.triangles);
    }
    Ok(())
}

/// The recorded pose of object `i` of `ep` in B, checked: an error names the episode and the
/// object when it is missing or not finite.
pub fn recorded_pose(catalog: &Catalog, ep: &Episode, i: usize) -> Result<Pose> {
    let bad = |message: String| SimError::Session {
        session: ep.name.clone(),
        message,
    };
    let (Some(&ty), Some(h)) = (ep.objects.get(i), ep.human.get(i)) else {
        return Err(bad(format!(
            "no recorded pose for object {} ({} recorded poses for {} objects)",
            i + 1,
            ep.human.len(),
            ep.objects.len()
        )));
    };
    let pose = Pose::from_parts(Vector::new(h.x, h.y, h.z), h.rotation);
    if !(pose.is_finite() && h.tilt_rad.is_finite()) {
        return Err(bad(format!(
            "object {} ({}): recorded pose is not finite",
            i + 1,
            catalog.spec(ty).id
        )));
    }
    Ok(pose)
}

/// Why an episode could not be run to its end (a failed placement is a result, not this).
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// The world or the environment refused (configuration, data).
    #[error(transparent)]
    Sim(#[from] SimError),
    /// The placer failed (a model error, a broken input...).
    #[error("{0}")]
    Placer(PlaceError),
    /// Episode `episode` could not be run.
    #[error("episode {episode}: {source}")]
    Episode {
        /// The session's name.
        episode: String,
        /// Why.
        source: Box<EvalError>,
    },
    /// The episode was never run (its worker could not start).
    #[error("not run")]
    NotRun,
}

/// The one episode loop: resets `env` with `order` and `seed`, then places each object where
/// `placer` decides until the episode ends (an object outside, or no feasible placement).
/// Each decision is timed when the placer says so. Every evaluation (Table I, the tools, the
/// tests) runs episodes through this.
pub fn run_episode(
    env: &mut PackingEnv,
    ep: &Episode,
    order: &[crate::TypeIdx],
    placer: &mut dyn Placer,
    seed: u64,
) -> std::result::Result<EpisodeResult, EvalError> {
    env.reset(order, seed)?;
    placer.begin_episode(ep, seed).map_err(EvalError::Placer)?;
    let timed = placer.timed();
    let mut r = EpisodeResult::new(&ep.name, order.len());
    while env.next_object().is_some() {
        let t0 = std::time::Instant::now();
        let decided = placer.decide(env).map_err(EvalError::Placer)?;
        if timed {
            r.decision_ns.push(t0.elapsed().as_nanos() as u64);
        }
        let Some(d) = decided else {
            r.record_no_feasible_placement();
            break;
        };
        let step = apply(env, d)?;
        if r.record(&step) {
            break;
        }
    }
    Ok(r)
}

/// An episode's result, or why it could not be run.
pub type EpisodeOutcome = std::result::Result<EpisodeResult, EvalError>;

/// Runs episodes on `jobs` threads, each with its own environment and its own worker made by
/// `make_worker` (e.g. a policy per thread). The worker runs episode `i`. Results keep the
/// episodes' order; an episode that errors is reported and the others go on; a worker that
/// cannot be made is an error for its episodes.
pub fn run_all_with<W, F>(
    catalog: &SharedCatalog,
    cfg: &WorldConfig,
    episodes: &[Episode],
    jobs: usize,
    make_worker: F,
) -> Result<Vec<EpisodeOutcome>>
where
    F: Fn() -> std::result::Result<W, EvalError> + Sync,
    W: FnMut(&mut PackingEnv, &Episode, usize) -> EpisodeOutcome,
{
    // Build one environment up front so configuration errors surface once, not per episode.
    PackingEnv::new(catalog.clone(), cfg.clone(), RewardMode::Simple)?;
    let next = AtomicUsize::new(0);
    let out: Slots = Mutex::new(episodes.iter().map(|_| None).collect());
    std::thread::scope(|s| {
        for _ in 0..jobs.max(1) {
            s.spawn(|| {
                let env = PackingEnv::new(catalog.clone(), cfg.clone(), RewardMode::Simple);
                let (mut env, mut worker) = match (env, make_worker()) {
                    (Ok(e), Ok(w)) => (e, w),
                    (Err(e), _) => return fail_rest(&next, episodes, &out, &e.to_string()),
                    (_, Err(e)) => return fail_rest(&next, episodes, &out, &e.to_string()),
                };
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(ep) = episodes.get(i) else { break };
                    let res = worker(&mut env, ep, i).map_err(|e| EvalError::Episode {
                        episode: ep.name.clone(),
                        source: Box::new(e),
                    });
                    out.lock().unwrap_or_else(|p| p.into_inner())[i] = Some(res);
                }
            });
        }
    });
    Ok(out
        .into_inner()
        .unwrap_or_else(|p| p.into_inner())
        .into_iter()
        .map(|r| r.unwrap_or(Err(EvalError::NotRun)))
        .collect())
}

type Slots = Mutex<Vec<Option<EpisodeOutcome>>>;

fn fail_rest(next: &AtomicUsize, episodes: &[Episode], out: &Slots, why: &str) {
    loop {
        let i = next.fetch_add(1, Ordering::Relaxed);
        let Some(ep) = episodes.get(i) else { break };
        out.lock().unwrap_or_else(|p| p.into_inner())[i] = Some(Err(EvalError::Episode {
            episode: ep.name.clone(),
            source: Box::new(EvalError::Placer(why.into())),
        }));
    }
}

/// Mean and population standard deviation.
pub fn mean_std(v: impl IntoIterator<Item = f64>) -> (f64, f64) {
    let v: Vec<f64> = v.into_iter().collect();
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    (
        m,
        (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n).sqrt(),
    )
}

/// The standard normal's two-sided 95 % quantile: the z of every 95 % interval of the tables.
pub const Z95: f64 = 1.959_963_984_540_054;

/// The 95 % interval of a success rate of `successes` out of `n` (Wilson's score interval,
/// as fractions in `[0, 1]`; `(0, 1)` for `n = 0`): unlike the normal approximation it stays
/// inside `[0, 1]` and is honest near 0 % and 100 %, where the rows of Table I sit.
pub fn success_interval(successes: usize, n: usize) -> (f64, f64) {
    if n == 0 {
        return (0.0, 1.0);
    }
    const Z: f64 = Z95;
    let (k, n) = (successes.min(n) as f64, n as f64);
    let p = k / n;
    let z2 = Z * Z;
    let centre = (p + z2 / (2.0 * n)) / (1.0 + z2 / n);
    let half = Z / (1.0 + z2 / n) * (p * (1.0 - p) / n + z2 / (4.0 * n * n)).sqrt();
    ((centre - half).max(0.0), (centre + half).min(1.0))
}

/// The summary row of one method.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// Method name.
    pub method: String,
    /// Episodes that ran.
    pub episodes: usize,
    /// Episodes that errored.
    pub errors: usize,
    /// Episodes that succeeded.
    pub successes: usize,
    /// Success rate (%).
    pub success_pct: f64,
    /// Objects packed: mean and population std.
    pub packed: (f64, f64),
    /// Final compactness over successful episodes: mean and std.
    pub final_compactness: (f64, f64),
    /// Placements with S = 1 (%).
    pub stability_pct: f64,
    /// Failed episodes per cause ([`Failure::label`]), most frequent first.
    pub failures: Vec<(String, usize)>,
    /// Decision latency over all placements (ms): mean, population std, p99; `None` for
    /// replays that make no decision.
    pub latency_ms: Option<(f64, f64, f64)>,
    /// Decision latency quantiles over all placements (ms): p50, p95, p99; `None` as above.
    pub latency_quantiles_ms: Option<[f64; 3]>,
}

/// Summarises results (errored episodes are counted apart and excluded).
pub fn summarize(method: &str, results: &[EpisodeOutcome]) -> Summary {
    let ok: Vec<&EpisodeResult> = results.iter().filter_map(|r| r.as_ref().ok()).collect();
    let n = ok.len().max(1) as f64;
    let placements: usize = ok.iter().map(|r| r.placements).sum();
    let stable: usize = ok.iter().map(|r| r.stable).sum();
    let lat = latency(&ok);
    Summary {
        method: method.to_owned(),
        episodes: ok.len(),
        errors: results.len() - ok.len(),
        successes: ok.iter().filter(|r| r.success).count(),
        success_pct: 100.0 * ok.iter().filter(|r| r.success).count() as f64 / n,
        packed: mean_std(ok.iter().map(|r| r.packed as f64)),
        final_compactness: mean_std(
            ok.iter()
                .filter(|r| r.success)
                .map(|r| r.final_compactness() as f64),
        ),
        stability_pct: 100.0 * stable as f64 / placements.max(1) as f64,
        failures: count_failures(&ok),
        latency_ms: lat.map(|(m, sd, q)| (m, sd, q[2])),
        latency_quantiles_ms: lat.map(|(_, _, q)| q),
    }
}

/// Mean, population std and the p50, p95 and p99 (nearest rank) of every decision's latency.
fn latency(ok: &[&EpisodeResult]) -> Option<(f64, f64, [f64; 3])> {
    let mut all: Vec<u64> = ok
        .iter()
        .flat_map(|r| r.decision_ns.iter().copied())
        .collect();
    if all.is_empty() {
        return None;
    }
    all.sort_unstable();
    let (m, sd) = mean_std(all.iter().map(|&n| n as f64 / 1e6));
    let q = |p: f64| all[((all.len() - 1) as f64 * p).round() as usize] as f64 / 1e6;
    Some((m, sd, [q(0.5), q(0.95), q(0.99)]))
}

fn count_failures(ok: &[&EpisodeResult]) -> Vec<(String, usize)> {
    let mut counts = std::collections::BTreeMap::<String, usize>::new();
    for f in ok.iter().filter_map(|r| r.failure) {
        *counts.entry(f.label()).or_default() += 1;
    }
    let mut v: Vec<(String, usize)> = counts.into_iter().collect();
    v.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
    v
}

/// A row of the paper's Table I: name, success %, objects packed mean and std, and decision
/// latency mean and std (ms) where reported.
pub type PaperRow = (&'static str, f64, f64, f64, Option<(f64, f64)>);

/// The HERB paper's Table I rows.
pub const PAPER_ROWS: [PaperRow; 7] = [
    ("Human packing", 84.41, 15.22, 4.79, None),
    ("PackIt SO(2)", 82.50, 16.33, 4.46, Some((1.59, 0.28))),
    ("PackIt SO(3)", 55.89, 13.92, 5.07, Some((2.51, 0.52))),
    ("BC-MSE", 7.22, 6.69, 5.16, Some((0.86, 0.25))),
    ("BC-MDN", 13.69, 6.42, 6.05, Some((0.85, 0.31))),
    ("HERB CS0.9", 87.83, 16.76, 3.79, Some((0.83, 0.26))),
    ("HERB CS0.6", 86.31, 16.43, 4.26, Some((0.77, 0.24))),
];

/// A Markdown table of our rows beside the paper's (HERB paper, Table I). `target` is the
/// objects-per-episode mean and std of the evaluated episodes.
pub fn format_table(rows: &[Summary], target: (f64, f64), episodes: usize) -> String {
    let mut s = String::new();
    s.push_str(
        "| method | success % | objects packed mean (std) | latency ms mean (std) | latency p99 ms | final C (std) | stability % |\n",
    );
    s.push_str("| --- | ---: | ---: | ---: | ---: | ---: | ---: |\n");
    s.push_str("| Target (paper) | 100 | 17.40 (3.63) | - | - | - | - |\n");
    s.push_str(&format!(
        "| Target (ours, {episodes} episodes) | 100 | {:.2} ({:.2}) | - | - | - | - |\n",
        target.0, target.1
    ));
    for (name, success, mean, std, lat) in PAPER_ROWS {
        let lat = lat.map_or("-".to_string(), |(m, sd)| format!("{m:.2} ({sd:.2})"));
        s.push_str(&format!(
            "| {name} (paper) | {success:.2} | {mean:.2} ({std:.2}) | {lat} | - | - | - |\n"
        ));
    }
    for r in rows {
        let (lat, p99) = match r.latency_ms {
            Some((m, sd, p99)) => (format!("{m:.3} ({sd:.3})"), format!("{p99:.3}")),
            None => ("-".into(), "-".into()),
        };
        let c = if r.final_compactness.0.is_nan() {
            "-".to_string()
        } else {
            format!(
                "{:.3} ({:.3})",
                r.final_compactness.0, r.final_compactness.1
            )
        };
        s.push_str(&format!(
            "| {} (ours) | {:.2} | {:.2} ({:.2}) | {lat} | {p99} | {c} | {:.1} |\n",
            r.method, r.success_pct, r.packed.0, r.packed.1, r.stability_pct
        ));
    }
    s
}
