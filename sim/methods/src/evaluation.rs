//! One evaluation of Table I's rows, as `herb-sim eval` runs it and as a sweep's tasks run it
//! through the Python bindings (`herb_sim.sweep`): the settings the rows share
//! ([`EvalSettings`], the flags of `herb-sim eval`), a row ([`Row`]), the run of one row over a
//! batch of episodes ([`EvalRun`], through the one episode loop), the per-episode CSV
//! ([`csv_rows`]) and the Markdown report ([`report`]).
//!
//! An episode's seed is the base seed plus the episode's index in the whole episode set, never
//! its place in a batch or the worker that ran it: any split of the episodes into batches gives
//! the same rows.

use crate::{Method, MethodSettings};
use herb_decide::{Order, PolicySpec, SequenceModel};
use herb_search::{Budget, ReleaseCheck, RobustRollouts, SearchSettings, TwinKind};
use herb_sim::boxed::Episode;
use herb_sim::eval::{self, EpisodeOutcome, EvalError, Summary};
use herb_sim::field::FieldModel;
use herb_sim::{PackingEnv, RewardMode, SharedCatalog, WorldConfig};
use serde::Deserialize;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Any error of an evaluation's setup (settings, models, data), with its message.
pub type SetupError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// The per-episode CSV's header line (with its newline).
pub const CSV_HEADER: &str = "method,sequence,episode,objects,packed,success,placements,stable,final_compactness,physics_steps,latency_mean_ms\n";

/// One row of an evaluation: a method, its object order when given as `METHOD@ORDER`, and for
/// `herb` its policy.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Row {
    /// The method.
    pub method: Method,
    /// The row's own order (`METHOD@ORDER`); `None`: the settings' order or the method's.
    pub order: Option<Order>,
    /// The placement policy of `herb` (a shipped policy's name or an ONNX file).
    pub policy: Option<PolicySpec>,
}

impl std::str::FromStr for Row {
    type Err = herb_decide::NameError;

    /// Parses `METHOD` or `METHOD@ORDER` (no policy).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let (method, order) = match s.split_once('@') {
            Some((m, o)) => (m, Some(o.parse::<Order>()?)),
            None => (s, None),
        };
        Ok(Row {
            method: method.parse()?,
            order,
            policy: None,
        })
    }
}

/// Objects per episode of a sampled episode set, at least and at most by default (the HERB
/// paper's training distribution): the sweeps' `set = "sample"`.
pub const SAMPLED_OBJECTS: std::ops::RangeInclusive<usize> = 10..=25;

/// A sampled episode set: `count` episodes of the training distribution, episode `i` named
/// `sample-{seed + i}` and its objects drawn ([`herb_sim::sample_objects`]) from a generator
/// seeded with `seed + i`, `objects` objects each. The one definition of the sweeps'
/// `set = "sample"` (the bindings) and of the diagnostics that replay it.
pub fn sampled_episodes(
    catalog_len: usize,
    seed: u64,
    count: usize,
    objects: std::ops::RangeInclusive<usize>,
) -> Vec<Episode> {
    use rand::SeedableRng;
    (0..count)
        .map(|i| {
            let s = seed.wrapping_add(i as u64);
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(s);
            Episode {
                name: format!("sample-{s}"),
                objects: herb_sim::sample_objects(&mut rng, catalog_len, objects.clone()),
                human: Vec::new(),
            }
        })
        .collect()
}

/// The settings every row of an evaluation shares: the flags of `herb-sim eval` other than
/// the rows, the data and the outputs, with the same names and defaults. A sweep's
/// configuration gives them by these names (`deny_unknown_fields`: a misspelt key is an error).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EvalSettings {
    /// Object order of the rows without `@ORDER` (`None`: each method's default).
    #[serde(deserialize_with = "de_order")]
    pub order: Option<Order>,
    /// The folder of the behaviour-cloning models.
    pub bc_models: PathBuf,
    /// The sequence model for Beam-3.
    pub sequence_model: PathBuf,
    /// Candidates the lookahead teacher simulates per decision.
    pub lookahead_k: usize,
    /// Reward the lookahead teacher and the search maximise (`simple`, `c`, `cs<alpha>`).
    pub lookahead_reward: String,
    /// Objects per lookahead rollout (`None`: to the episode's end).
    pub lookahead_horizon: Option<usize>,
    /// Rollouts the search may run per decision.
    pub search_rollouts: usize,
    /// The search's budget as a time per decision (s) instead of a count.
    pub search_time_s: Option<f64>,
    /// Candidates the search considers at most.
    pub search_k: usize,
    /// Threads of each search decision's rollouts.
    pub search_threads: usize,
    /// Objects per search rollout (`None`: to the job's end).
    pub search_horizon: Option<usize>,
    /// The search's world: `heightmap`, `job` or `exact`.
    pub search_world: String,
    /// The search's rollouts on a live pile instead of a rigid one
    /// (`SearchSettings::rigid_pile`; for measurements).
    pub search_live_pile: bool,
    /// The search's clearance against what its candidates' pushes stopped at, in fine lattice
    /// cells of 6.25 mm (`SearchSettings::push_gap`; 0: tight).
    pub search_gap: usize,
    /// The search's clearance from the walls where its candidates stand above the rim, in
    /// fine lattice cells of 6.25 mm (`SearchSettings::wall_gap`; 0: none).
    pub search_wall_gap: usize,
    /// The robust search: rollouts per candidate under `search_noise` (0: one, exact releases).
    pub search_samples: usize,
    /// The release error the robust search assumes: sd in mm (x, y) and degrees (yaw); also
    /// the corners the release check tries.
    pub search_noise: (f32, f32),
    /// The search's release check (`SearchSettings::release_check`; on, as herbd's): each of
    /// its best candidates released off its placement by the four corners of `search_noise`
    /// first.
    pub search_check: bool,
    /// The search's support rule (`SearchSettings::min_support`; 0: off, as herbd's): a
    /// candidate standing above the rim on less than this share of its footprint is ranked as
    /// a failed rollout.
    pub search_min_support: f32,
    /// The search finds its candidates on the camera's heightmap filtered by a 3 x 3 median
    /// (`SearchSettings::median`; on, as herbd's).
    pub search_median: bool,
    /// The evaluation's world: `ideal` (no error), `field` (the shipped field model,
    /// `models/field.toml`) or a field model file.
    pub world: String,
    /// Release noise of the evaluation's world: sd in mm (x, y) and degrees (yaw).
    pub release_noise: Option<(f32, f32)>,
    /// Physics settings (`KEY=VALUE[,KEY=VALUE...]`), applied in turn.
    pub world_set: Vec<String>,
    /// Base seed: episode `i` of the episode set uses `seed + i`.
    pub seed: u64,
}

impl Default for EvalSettings {
    fn default() -> Self {
        let search = SearchSettings::default();
        Self {
            order: None,
            bc_models: PathBuf::from(PolicySpec::DEFAULT_MODELS_DIR),
            sequence_model: PathBuf::from("models/sequence.json"),
            lookahead_k: 8,
            lookahead_reward: "cs0.6".into(),
            lookahead_horizon: None,
            // One rollout a candidate: the reproducible budget.
            search_rollouts: search.k,
            search_time_s: None,
            search_k: search.k,
            search_threads: 1,
            search_horizon: None,
            search_world: TwinKind::Job.name().into(),
            search_live_pile: false,
            search_gap: search.push_gap,
            search_wall_gap: 0,
            search_samples: 0,
            search_noise: (
                herb_search::DEFAULT_RELEASE_ERROR_MM as f32,
                herb_search::DEFAULT_RELEASE_ERROR_DEG as f32,
            ),
            search_check: search.release_check.is_some(),
            search_min_support: search.min_support.unwrap_or(0.0),
            search_median: search.median,
            world: "ideal".into(),
            release_noise: None,
            world_set: Vec::new(),
            seed: 0,
        }
    }
}

fn de_order<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<Order>, D::Error> {
    Option::<String>::deserialize(d)?
        .map(|s| s.parse::<Order>().map_err(serde::de::Error::custom))
        .transpose()
}

impl EvalSettings {
    /// The checks that need no data: ranges, names, the physics settings.
    pub fn validate(&self) -> Result<(), SetupError> {
        let max_k = herb_sim::lattice::MAX_CANDIDATES;
        if !(1..=max_k).contains(&self.lookahead_k) {
            return Err(format!("lookahead_k {}: need 1 to {max_k}", self.lookahead_k).into());
        }
        let (max_samples, max_mm, max_deg) = (
            RobustRollouts::MAX_SAMPLES,
            RobustRollouts::MAX_ERROR_MM,
            RobustRollouts::MAX_ERROR_DEG,
        );
        if self.search_samples > max_samples {
            return Err(format!(
                "search_samples {}: need 0 to {max_samples}",
                self.search_samples
            )
            .into());
        }
        let (mm, deg) = self.search_noise;
        if !(mm.is_finite()
            && (0.0..=max_mm).contains(&f64::from(mm))
            && deg.is_finite()
            && (0.0..=max_deg).contains(&f64::from(deg)))
        {
            return Err(format!(
                "search_noise {mm},{deg}: need 0 to {max_mm} mm and 0 to {max_deg} degrees"
            )
            .into());
        }
        let max_gap = herb_sim::lattice::MAX_PUSH_GAP;
        if self.search_gap > max_gap {
            return Err(format!("search_gap {}: need 0 to {max_gap}", self.search_gap).into());
        }
        if self.search_wall_gap > max_gap {
            return Err(format!(
                "search_wall_gap {}: need 0 to {max_gap}",
                self.search_wall_gap
            )
            .into());
        }
        herb_search::support_rule(self.search_min_support)
            .map_err(|e| format!("search_min_support {e}"))?;
        if !(1..=64).contains(&self.search_threads) {
            return Err(format!("search_threads {}: need 1 to 64", self.search_threads).into());
        }
        if self.lookahead_horizon == Some(0) || self.search_horizon == Some(0) {
            return Err("a horizon of 0 objects: need at least 1".into());
        }
        if let Some(s) = self.search_time_s.filter(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(format!("search_time_s {s}: need a time > 0").into());
        }
        if let Some((mm, deg)) = self.release_noise
            && !(mm.is_finite() && mm >= 0.0 && deg.is_finite() && deg >= 0.0)
        {
            return Err(format!("release_noise ({mm}, {deg}): need two numbers >= 0").into());
        }
        RewardMode::parse(&self.lookahead_reward)?;
        TwinKind::parse(&self.search_world)?;
        self.world()?;
        Ok(())
    }

    /// The checks of one row: `herb` has a policy and no other method has one; a replay keeps
    /// the human order.
    pub fn check_row(&self, row: &Row) -> Result<(), SetupError> {
        match (row.method, &row.policy) {
            (Method::Herb, None) => Err("herb needs a policy (e.g. cs06)".into()),
            (m, Some(_)) if m != Method::Herb => {
                Err(format!("{m}: a policy is used by herb only").into())
            }
            (m, _) if m.replay().is_some() && (row.order.is_some() || self.order.is_some()) => {
                Err(format!(
                    "{m}: a replay keeps the human order (the order and @ORDER apply to the \
                     deciding methods only)"
                )
                .into())
            }
            _ => Ok(()),
        }
    }

    /// The field model of the evaluation's world (`None` for `ideal`).
    pub fn field_model(&self) -> Result<Option<FieldModel>, SetupError> {
        Ok(FieldModel::by_name(&self.world)?)
    }

    /// The evaluation's world: today's defaults, its field model, the release noise, then each
    /// `world_set`.
    pub fn world(&self) -> Result<WorldConfig, SetupError> {
        let mut cfg = WorldConfig::default();
        if let Some(m) = self.field_model()? {
            if self.release_noise.is_some() {
                return Err(format!(
                    "world {} and release_noise both set the release error: give one",
                    self.world
                )
                .into());
            }
            cfg = m.apply(&cfg)?;
        }
        if let Some((mm, deg)) = self.release_noise {
            cfg.release_noise_m = mm * 1e-3;
            cfg.release_noise_deg = deg;
            cfg.validate()?;
        }
        for list in &self.world_set {
            cfg.set_all(list)?;
        }
        Ok(cfg)
    }

    /// The settings of the method placers (the policy `None`: [`MethodSettings::policy`] is
    /// set per row by [`EvalSettings::row_settings`]).
    pub fn method_settings(&self, world: &WorldConfig) -> Result<MethodSettings, SetupError> {
        let reward = RewardMode::parse(&self.lookahead_reward)?;
        Ok(MethodSettings {
            policy: None,
            bc_models: self.bc_models.clone(),
            lookahead_k: self.lookahead_k,
            lookahead_reward: reward,
            lookahead_horizon: self.lookahead_horizon,
            search: SearchSettings {
                k: self.search_k,
                budget: match self.search_time_s {
                    Some(s) => Budget::Time(Duration::from_secs_f64(s)),
                    None => Budget::Rollouts(self.search_rollouts),
                },
                horizon: self.search_horizon,
                reward,
                twin: TwinKind::parse(&self.search_world)?,
                robust: RobustRollouts::assumed(
                    self.search_samples,
                    self.search_noise.0.into(),
                    self.search_noise.1.into(),
                ),
                rigid_pile: !self.search_live_pile,
                threads: self.search_threads,
                push_gap: self.search_gap,
                wall_gap: self.search_wall_gap,
                release_check: self
                    .search_check
                    .then(|| {
                        ReleaseCheck::assumed(
                            self.search_noise.0.into(),
                            self.search_noise.1.into(),
                        )
                    })
                    .flatten(),
                min_support: herb_search::support_rule(self.search_min_support)
                    .map_err(|e| format!("search_min_support {e}"))?,
                median: self.search_median,
            },
            world: world.clone(),
        })
    }

    /// The order `row` runs in (`None`: the human order of the replays).
    pub fn order_of(&self, row: &Row) -> Option<Order> {
        row.method.order(row.order.or(self.order))
    }

    /// Whether `row` needs the sequence model (it orders by Beam-3).
    pub fn needs_sequence_model(&self, row: &Row) -> bool {
        self.order_of(row).is_some_and(|o| o.uses_sequence_model())
    }

    /// `base` with `row`'s policy, resolved against `models_dir` (a shipped policy's name
    /// becomes its file there).
    pub fn row_settings(
        &self,
        row: &Row,
        base: &MethodSettings,
        models_dir: &Path,
    ) -> MethodSettings {
        MethodSettings {
            policy: row.policy.as_ref().map(|p| p.resolved(models_dir)),
            ..base.clone()
        }
    }

    /// `row`'s names: in the CSV's `method` column (`herb policy-cs06`, `blbf`...), in its
    /// `sequence` column (the order's name, `human` for the replays), and its label in the
    /// table (the budget and twin of the search, the k of the teacher, the order).
    pub fn row_names(&self, row: &Row, settings: &MethodSettings) -> RowNames {
        let m = row.method;
        let policy_file = match &settings.policy {
            Some(PolicySpec::Onnx(p)) => Some(p),
            _ => None,
        };
        let name = match policy_file {
            Some(p) => format!(
                "{} {}",
                m.name(),
                p.file_stem().and_then(|s| s.to_str()).unwrap_or("policy")
            ),
            None => m.name().to_string(),
        };
        let shown = match (m, policy_file) {
            (_, Some(_)) => name.clone(),
            (Method::Search, _) => {
                let budget = match self.search_time_s {
                    Some(s) => format!("{s} s"),
                    None => format!("{} rollouts", self.search_rollouts),
                };
                let world = TwinKind::parse(&self.search_world)
                    .map(|t| t.name().to_string())
                    .unwrap_or_else(|_| self.search_world.clone());
                let mut extra = String::new();
                if self.search_samples > 0 {
                    let (mm, deg) = self.search_noise;
                    extra += &format!(", {} samples of {mm} mm / {deg} deg", self.search_samples);
                }
                if self.search_check {
                    let (mm, deg) = self.search_noise;
                    extra += &format!(", release check of {mm} mm / {deg} deg");
                }
                if self.search_min_support > 0.0 {
                    let pct = 100.0 * self.search_min_support;
                    extra += &format!(", support {pct:.0} % above the rim");
                }
                if self.search_median {
                    extra += ", median-filtered camera";
                }
                if self.search_live_pile {
                    extra += ", live pile";
                }
                if self.lookahead_reward != Self::default().lookahead_reward {
                    extra += &format!(", ranked by {}", self.lookahead_reward);
                }
                if self.search_gap > 0 {
                    let mm = self.search_gap as f32 * herb_sim::lattice::FINE_CELL_M * 1000.0;
                    extra += &format!(", gap {mm:.2} mm");
                }
                if self.search_wall_gap > 0 {
                    let mm = self.search_wall_gap as f32 * herb_sim::lattice::FINE_CELL_M * 1000.0;
                    extra += &format!(", walls {mm:.2} mm above the rim");
                }
                format!("search ({budget}, k = {}, {world}{extra})", self.search_k)
            }
            (Method::Lookahead, _) => {
                let horizon = self
                    .lookahead_horizon
                    .map(|h| format!(", horizon {h}"))
                    .unwrap_or_default();
                format!("lookahead (teacher, k = {}{horizon})", self.lookahead_k)
            }
            _ => m.label().to_string(),
        };
        match self.order_of(row) {
            Some(o) => RowNames {
                label: format!("{shown} ({})", o.name()),
                sequence: o.name().to_string(),
                name,
            },
            None => RowNames {
                label: shown,
                sequence: "human".into(),
                name,
            },
        }
    }
}

/// A row's names ([`EvalSettings::row_names`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RowNames {
    /// The CSV's `method` column.
    pub name: String,
    /// The CSV's `sequence` column.
    pub sequence: String,
    /// The row's label in the table.
    pub label: String,
}

/// What every row of one evaluation over a batch of episodes shares.
pub struct EvalRun<'a> {
    /// The objects.
    pub catalog: &'a SharedCatalog,
    /// The evaluation's world.
    pub cfg: &'a WorldConfig,
    /// The batch of episodes.
    pub episodes: &'a [Episode],
    /// The index of the batch's first episode in the whole episode set (its seeds follow).
    pub first: usize,
    /// The sequence model, for the rows ordered by Beam-3.
    pub model: Option<&'a SequenceModel>,
    /// The base seed: episode `i` of the whole set uses `seed + i`.
    pub seed: u64,
    /// Threads the batch's episodes run on.
    pub threads: usize,
}

impl EvalRun<'_> {
    /// The seed of the batch's episode `k`.
    pub fn episode_seed(&self, k: usize) -> u64 {
        self.seed.wrapping_add((self.first + k) as u64)
    }

    /// Runs method `m` over the batch, each episode ordered by `order` (the human order when
    /// `None`), one placer per worker thread, through the one episode loop
    /// ([`eval::run_episode`]); the humans' recorded poses are scored without physics.
    pub fn method(
        &self,
        m: Method,
        order: Option<Order>,
        settings: &MethodSettings,
    ) -> Result<Vec<EpisodeOutcome>, SetupError> {
        let (catalog, cfg, model) = (self.catalog, self.cfg, self.model);
        if m == Method::HumanRecorded {
            let (tol, tilt) = (cfg.inside_tolerance_m, cfg.stability_tilt_deg);
            return Ok(eval::run_all_with(
                catalog,
                cfg,
                self.episodes,
                self.threads,
                || {
                    Ok(move |_: &mut PackingEnv, ep: &Episode, _| {
                        Ok(eval::recorded_episode(catalog, ep, tol, tilt)?)
                    })
                },
            )?);
        }
        // Built once up front: a bad model is one clear error, not one per episode.
        m.placer(catalog, settings).map_err(|e| -> SetupError {
            match m.bc_models(&settings.bc_models) {
                Some(_) => format!("{e} (train with training/bc.py)").into(),
                None => e.to_string().into(),
            }
        })?;
        let make = || -> Result<_, EvalError> {
            let mut placer = m
                .placer(catalog, settings)
                .map_err(|e| EvalError::Placer(e.into()))?;
            Ok(move |env: &mut PackingEnv, ep: &Episode, k: usize| {
                let s = self.episode_seed(k);
                let objects = match order {
                    Some(o) => o
                        .order(catalog, model, &ep.objects, s)
                        .map_err(|e| EvalError::Placer(e.into()))?,
                    None => ep.objects.clone(),
                };
                eval::run_episode(env, ep, &objects, placer.as_mut(), s)
            })
        };
        Ok(eval::run_all_with(
            catalog,
            cfg,
            self.episodes,
            self.threads,
            make,
        )?)
    }
}

/// The per-episode CSV rows of one row's results (the episodes that could not be run have no
/// line: the report lists them).
pub fn csv_rows(name: &str, sequence: &str, results: &[EpisodeOutcome]) -> String {
    let mut text = String::new();
    for r in results.iter().filter_map(|r| r.as_ref().ok()) {
        let lat = eval::mean_std(r.decision_ns.iter().map(|&n| n as f64 / 1e6)).0;
        text.push_str(&format!(
            "{},{},{},{},{},{},{},{},{:.4},{},{}\n",
            name,
            sequence,
            r.name,
            r.objects,
            r.packed,
            r.success,
            r.placements,
            r.stable,
            r.final_compactness(),
            r.physics_steps,
            if lat.is_nan() {
                String::new()
            } else {
                format!("{lat:.4}")
            }
        ));
    }
    text
}

/// The Markdown report of an evaluation: Table I's rows beside the paper's
/// ([`eval::format_table`]; `target`: the episodes' objects mean and std), then for each row its
/// failures by cause and its decision-time quantiles, then `notes` (one line each), then the
/// episodes each row could not run.
pub fn report(
    rows: &[(String, Vec<EpisodeOutcome>)],
    target: (f64, f64),
    episodes: usize,
    notes: &[String],
) -> String {
    let summaries: Vec<Summary> = rows
        .iter()
        .map(|(label, results)| eval::summarize(label, results))
        .collect();
    let mut table = eval::format_table(&summaries, target, episodes);
    table.push('\n');
    for r in &summaries {
        let causes: Vec<String> = r
            .failures
            .iter()
            .map(|(k, n)| format!("{k}: {n}"))
            .collect();
        table.push_str(&format!(
            "- {} failures by cause: {}\n",
            r.method,
            causes.join(", ")
        ));
        if let Some([p50, p95, p99]) = r.latency_quantiles_ms {
            table.push_str(&format!(
                "- {} decision time p50 / p95 / p99: {p50:.3} / {p95:.3} / {p99:.3} ms\n",
                r.method
            ));
        }
    }
    for n in notes {
        table.push_str(&format!("- {n}\n"));
    }
    for (label, results) in rows {
        let errors: Vec<String> = results
            .iter()
            .filter_map(|r| r.as_ref().err())
            .map(ToString::to_string)
            .collect();
        if !errors.is_empty() {
            table.push_str(&format!(
                "- {label}: {} episodes skipped: {}\n",
                errors.len(),
                errors.join("; ")
            ));
        }
    }
    table
}

/// The note of a field model, for [`report`].
pub fn field_note(m: &FieldModel, source: &str) -> String {
    let (r, c, o) = (m.release, m.camera, m.object);
    // Figures as the file gives them (f32 scaled to mm or % prints its rounding otherwise).
    let g = |v: f32| format!("{}", (f64::from(v) * 1e3).round() / 1e3);
    format!(
        "world (every row): field model {} ({source}): each release off its decided pose by \
         normal noise, sd {} mm in x and y, {} deg in yaw, {} mm in height (never lower than \
         touching); the camera's depth noise sd {} mm, dropouts {} % of cells and {} % at \
         step edges; each object's size, mass and friction off the catalog's by sd {} %, {} % \
         and {} % per episode",
        m.name,
        g(r.xy_sd_m * 1e3),
        g(r.yaw_sd_deg),
        g(r.height_sd_m * 1e3),
        g(c.depth_sd_m * 1e3),
        g(c.dropout * 100.0),
        g(c.edge_dropout * 100.0),
        g(o.size_sd * 100.0),
        g(o.mass_sd * 100.0),
        g(o.friction_sd * 100.0)
    )
}

/// The note of the release noise, for [`report`].
pub fn release_noise_note((mm, deg): (f32, f32)) -> String {
    format!(
        "release noise (every row): each object released off its decided pose by normal \
         noise, sd {mm} mm in x and y, {deg} deg in yaw"
    )
}
