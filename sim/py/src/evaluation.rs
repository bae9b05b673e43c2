//! `herb-sim eval` for Python: [`Evaluation`] runs one row over a batch of episodes through the
//! same Rust code as the command line (`herb_methods::evaluation`: the settings, the one episode
//! loop, the seeds), and [`report`] and [`csv_rows`] write its Markdown and CSV. A sweep's Ray
//! tasks (`herb_sim.sweep`) are calls of [`Evaluation::run`]; the catalog, the episodes and the
//! sequence models stay loaded in the worker between tasks.

use super::*;
use herb_methods::evaluation::{self, EvalRun, EvalSettings, Row};
use herb_sim::boxed::Episode;
use herb_sim::eval::{EpisodeOutcome, EpisodeResult, EvalError};
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Mutex;

/// A set of episodes: BoxED's sessions (the first `limit`) or sampled ones.
#[derive(Debug, Clone, PartialEq, Eq, Hash, serde::Deserialize)]
#[serde(tag = "set", rename_all = "lowercase", deny_unknown_fields)]
enum EpisodeSet {
    /// BoxED's sessions in load order (the sessions that do not load are left out, as in
    /// `herb-sim eval`), the first `limit` of them.
    Boxed { limit: Option<usize> },
    /// `count` episodes of the training distribution (`herb_sim::sample_objects`): episode `i`
    /// drawn from `seed + i`.
    Sample {
        seed: u64,
        count: usize,
        #[serde(default = "min_objects")]
        min_objects: usize,
        #[serde(default = "max_objects")]
        max_objects: usize,
    },
}

fn min_objects() -> usize {
    *evaluation::SAMPLED_OBJECTS.start()
}

fn max_objects() -> usize {
    *evaluation::SAMPLED_OBJECTS.end()
}

/// Loaded episodes and what the report says about the set.
struct Loaded {
    episodes: Vec<Episode>,
    skipped: Vec<String>,
}

/// What a worker keeps between the rows it runs: the catalog, the episode sets and the
/// sequence models, each loaded once.
#[pyclass(module = "herb_sim._native", frozen)]
pub(crate) struct Evaluation {
    catalog: SharedCatalog,
    root: Option<PathBuf>,
    sets: Mutex<HashMap<EpisodeSet, Arc<Loaded>>>,
    models: Mutex<HashMap<PathBuf, Arc<SequenceModel>>>,
}

impl Evaluation {
    fn episodes(&self, set: &EpisodeSet) -> Result<Arc<Loaded>, String> {
        let mut sets = self.sets.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(l) = sets.get(set) {
            return Ok(l.clone());
        }
        let loaded = match *set {
            EpisodeSet::Boxed { limit } => {
                let root = self.root.as_deref().ok_or(
                    "BoxED data not found: pass boxed= or set HERB_BOXED (the set \"boxed\")",
                )?;
                let (sessions, bad) =
                    herb_sim::boxed::load_all(root, &self.catalog).map_err(|e| e.to_string())?;
                let mut episodes: Vec<Episode> =
                    sessions.iter().map(|s| s.episode(&self.catalog)).collect();
                if let Some(n) = limit {
                    episodes.truncate(n);
                }
                Loaded {
                    episodes,
                    skipped: bad.iter().map(ToString::to_string).collect(),
                }
            }
            EpisodeSet::Sample {
                seed,
                count,
                min_objects,
                max_objects,
            } => {
                if min_objects == 0 || min_objects > max_objects || max_objects > 64 {
                    return Err(format!(
                        "objects per sampled episode {min_objects}..={max_objects}: need 1 <= \
                         min <= max <= 64"
                    ));
                }
                let episodes = evaluation::sampled_episodes(
                    self.catalog.len(),
                    seed,
                    count,
                    min_objects..=max_objects,
                );
                Loaded {
                    episodes,
                    skipped: Vec::new(),
                }
            }
        };
        let l = Arc::new(loaded);
        sets.insert(set.clone(), l.clone());
        Ok(l)
    }

    fn model(&self, path: &Path) -> Result<Arc<SequenceModel>, String> {
        let mut models = self.models.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(m) = models.get(path) {
            return Ok(m.clone());
        }
        let m = Arc::new(SequenceModel::load(path, &self.catalog).map_err(|e| e.to_string())?);
        models.insert(path.to_owned(), m.clone());
        Ok(m)
    }
}

/// A row and its settings from their text, checked (`EvalSettings::validate`, `check_row`).
fn parse_row(row: &str, settings: &str, policy: Option<&str>) -> PyResult<(Row, EvalSettings)> {
    let mut row: Row = row.parse().map_err(value_err)?;
    row.policy = policy
        .map(|p| p.parse::<herb_decide::PolicySpec>())
        .transpose()
        .map_err(value_err)?;
    let settings: EvalSettings =
        serde_json::from_str(settings).map_err(|e| value_err(format!("settings: {e}")))?;
    settings.validate().map_err(value_err)?;
    settings.check_row(&row).map_err(value_err)?;
    Ok((row, settings))
}

/// One episode's outcome as the tasks send it: the result, or why it could not be run.
#[derive(serde::Serialize, serde::Deserialize)]
enum Outcome {
    Ok(EpisodeResult),
    Err(String),
}

fn to_json(o: &EpisodeOutcome) -> String {
    let wire = match o {
        Ok(r) => Outcome::Ok(r.clone()),
        Err(e) => Outcome::Err(e.to_string()),
    };
    serde_json::to_string(&wire).expect("an episode result serialises")
}

fn from_json(s: &str) -> PyResult<EpisodeOutcome> {
    match serde_json::from_str::<Outcome>(s) {
        Ok(Outcome::Ok(r)) => Ok(Ok(r)),
        Ok(Outcome::Err(e)) => Ok(Err(EvalError::Placer(e.into()))),
        Err(e) => Err(value_err(format!(
            "an episode outcome that does not read: {e}"
        ))),
    }
}

#[pymethods]
impl Evaluation {
    /// The catalog (meshes from `boxed`'s `meshes` folder unless `meshes=False`) and the
    /// BoxED folder (`boxed`; default `HERB_BOXED` or ../shared/boxed).
    #[new]
    #[pyo3(signature = (boxed=None, meshes=true))]
    fn new(boxed: Option<String>, meshes: bool) -> PyResult<Self> {
        let root = paths::boxed_root(boxed.as_deref().map(Path::new));
        let source = if meshes {
            paths::mesh_source(None, root.as_deref())
        } else {
            MeshSource::None("meshes=False".into())
        };
        let catalog = Arc::new(Catalog::builtin(&source).map_err(value_err)?);
        Ok(Self {
            catalog,
            root,
            sets: Mutex::new(HashMap::new()),
            models: Mutex::new(HashMap::new()),
        })
    }

    /// The BoxED folder this evaluation reads, made absolute (`None` when none was found): a
    /// sweep passes it to its workers, which may run elsewhere.
    #[getter]
    fn boxed_root(&self) -> Option<String> {
        let root = self.root.as_ref()?;
        Some(
            root.canonicalize()
                .or_else(|_| std::path::absolute(root))
                .unwrap_or_else(|_| root.clone())
                .display()
                .to_string(),
        )
    }

    /// The episodes of a set (JSON: `{"set": "boxed", "limit": N}` or `{"set": "sample",
    /// "seed": S, "count": N, "min_objects": 10, "max_objects": 25}`): `(names, objects,
    /// skipped)`, the sessions that did not load in `skipped`.
    fn episodes_of(
        &self,
        py: Python<'_>,
        set: &str,
    ) -> PyResult<(Vec<String>, Vec<usize>, Vec<String>)> {
        let set: EpisodeSet =
            serde_json::from_str(set).map_err(|e| value_err(format!("episode set: {e}")))?;
        let l = py.detach(|| self.episodes(&set)).map_err(value_err)?;
        Ok((
            l.episodes.iter().map(|e| e.name.clone()).collect(),
            l.episodes.iter().map(|e| e.objects.len()).collect(),
            l.skipped.clone(),
        ))
    }

    /// Checks one row as [`Evaluation::run`] would run it (the row, its policy, the settings)
    /// without running it: a `ValueError` says what is wrong.
    #[pyo3(signature = (row, settings, policy=None, models="models"))]
    fn check(&self, row: &str, settings: &str, policy: Option<&str>, models: &str) -> PyResult<()> {
        let (row, settings) = parse_row(row, settings, policy)?;
        let base = settings
            .method_settings(&settings.world().map_err(value_err)?)
            .map_err(value_err)?;
        if let Some(herb_decide::PolicySpec::Onnx(p)) =
            settings.row_settings(&row, &base, Path::new(models)).policy
            && !p.is_file()
        {
            return Err(value_err(format!("policy {}: no such file", p.display())));
        }
        Ok(())
    }

    /// Runs one row (`row`: `METHOD` or `METHOD@ORDER`; `policy`: herb's policy, a shipped
    /// name or an ONNX file; `models`: where shipped policies are) with the `herb-sim eval`
    /// settings `settings` (JSON, the flags' names: `search_rollouts`, `release_noise`...) over
    /// the episodes `indices` of the set `set` (JSON, see `episodes_of`), on `threads` threads,
    /// with the GIL released. Episode `i` is seeded `seed + i` whatever the batch. Returns
    /// `(name, sequence, label, outcomes)`: the CSV's method and sequence columns, the table's
    /// label, and each episode's outcome as JSON (for `report` and `csv_rows`).
    #[pyo3(signature = (row, settings, set, indices, policy=None, models="models", threads=1))]
    #[allow(clippy::too_many_arguments)]
    fn run(
        &self,
        py: Python<'_>,
        row: &str,
        settings: &str,
        set: &str,
        indices: Vec<usize>,
        policy: Option<&str>,
        models: &str,
        threads: usize,
    ) -> PyResult<(String, String, String, Vec<String>)> {
        let (row, settings) = parse_row(row, settings, policy)?;
        let set: EpisodeSet =
            serde_json::from_str(set).map_err(|e| value_err(format!("episode set: {e}")))?;
        if !(1..=64).contains(&threads) {
            return Err(value_err(format!("threads {threads}: need 1 to 64")));
        }
        py.detach(|| {
            let loaded = self.episodes(&set)?;
            let n = loaded.episodes.len();
            if let Some(&i) = indices.iter().find(|&&i| i >= n) {
                return Err(format!("episode {i}: the set has {n}"));
            }
            let model = if settings.needs_sequence_model(&row) {
                Some(self.model(&settings.sequence_model)?)
            } else {
                None
            };
            let cfg = settings.world().map_err(|e| e.to_string())?;
            let base = settings.method_settings(&cfg).map_err(|e| e.to_string())?;
            let row_settings = settings.row_settings(&row, &base, Path::new(models));
            let names = settings.row_names(&row, &row_settings);
            let order = settings.order_of(&row);
            // Runs of consecutive indices keep each episode's seed: `first` is its index in the set.
            let mut outcomes = Vec::with_capacity(indices.len());
            let mut k = 0;
            while k < indices.len() {
                let first = indices[k];
                let mut end = k + 1;
                while end < indices.len() && indices[end] == first + (end - k) {
                    end += 1;
                }
                let run = EvalRun {
                    catalog: &self.catalog,
                    cfg: &cfg,
                    episodes: &loaded.episodes[first..first + (end - k)],
                    first,
                    model: model.as_deref(),
                    seed: settings.seed,
                    threads,
                };
                let results = run
                    .method(row.method, order, &row_settings)
                    .map_err(|e| e.to_string())?;
                outcomes.extend(results.iter().map(to_json));
                k = end;
            }
            Ok((names.name, names.sequence, names.label, outcomes))
        })
        .map_err(value_err)
    }
}

/// The per-episode CSV lines (no header: `CSV_HEADER`) of one row's outcomes, as `herb-sim
/// eval` writes them.
#[pyfunction]
pub(crate) fn csv_rows(name: &str, sequence: &str, outcomes: Vec<String>) -> PyResult<String> {
    let results = outcomes
        .iter()
        .map(|s| from_json(s))
        .collect::<PyResult<Vec<_>>>()?;
    Ok(evaluation::csv_rows(name, sequence, &results))
}

/// The Markdown report of rows `[(label, outcomes)]`, as `herb-sim eval` writes it, with
/// `notes` (one line each); the target row is the objects of the distinct episodes that ran.
#[pyfunction]
pub(crate) fn report(rows: Vec<(String, Vec<String>)>, notes: Vec<String>) -> PyResult<String> {
    let mut parsed = Vec::with_capacity(rows.len());
    let mut objects = std::collections::BTreeMap::new();
    for (label, outcomes) in rows {
        let results = outcomes
            .iter()
            .map(|s| from_json(s))
            .collect::<PyResult<Vec<_>>>()?;
        for r in results.iter().filter_map(|r| r.as_ref().ok()) {
            objects.insert(r.name.clone(), r.objects);
        }
        parsed.push((label, results));
    }
    let target = herb_sim::eval::mean_std(objects.values().map(|&n| n as f64));
    Ok(evaluation::report(&parsed, target, objects.len(), &notes))
}

/// The note of a release noise (`MM`, `DEG`), as `herb-sim eval` writes it.
#[pyfunction]
pub(crate) fn release_noise_note(mm: f32, deg: f32) -> String {
    evaluation::release_noise_note((mm, deg))
}

/// The summary of one configuration's outcomes (`herb_sim::eval::summarize`, the numbers of
/// its row in the table) as a dict: `episodes`, `errors`, `successes`, `success_pct` with its
/// 95 % interval `success_lo_pct`, `success_hi_pct` (Wilson), `packed_mean`, `packed_std`,
/// `packed_ci` (the 95 % half-width of the mean, normal), `final_c_mean`, `stability_pct`,
/// `latency_mean_ms` and `latency_p50_ms`, `latency_p95_ms`, `latency_p99_ms` (`None` for
/// rows that make no decision), `failures` (`[(cause, count)]`).
#[pyfunction]
pub(crate) fn summary<'py>(py: Python<'py>, outcomes: Vec<String>) -> PyResult<Bound<'py, PyDict>> {
    let results = outcomes
        .iter()
        .map(|s| from_json(s))
        .collect::<PyResult<Vec<_>>>()?;
    let s = herb_sim::eval::summarize("", &results);
    let successes = s.successes;
    let (lo, hi) = herb_sim::eval::success_interval(successes, s.episodes);
    let d = PyDict::new(py);
    d.set_item("episodes", s.episodes)?;
    d.set_item("errors", s.errors)?;
    d.set_item("successes", successes)?;
    d.set_item("success_pct", s.success_pct)?;
    d.set_item("success_lo_pct", 100.0 * lo)?;
    d.set_item("success_hi_pct", 100.0 * hi)?;
    d.set_item("packed_mean", s.packed.0)?;
    d.set_item("packed_std", s.packed.1)?;
    d.set_item(
        "packed_ci",
        herb_sim::eval::Z95 * s.packed.1 / (s.episodes.max(1) as f64).sqrt(),
    )?;
    d.set_item("final_c_mean", s.final_compactness.0)?;
    d.set_item("stability_pct", s.stability_pct)?;
    d.set_item("latency_mean_ms", s.latency_ms.map(|l| l.0))?;
    let q = s.latency_quantiles_ms;
    d.set_item("latency_p50_ms", q.map(|q| q[0]))?;
    d.set_item("latency_p95_ms", q.map(|q| q[1]))?;
    d.set_item("latency_p99_ms", q.map(|q| q[2]))?;
    d.set_item("failures", s.failures)?;
    Ok(d)
}

/// Writes a chart of `rows` (`[(label, value, lo, hi)]`, top to bottom) to `path` (PNG): a
/// bar per row with its interval, on an axis from 0 to `x_max` named `x_label`.
#[pyfunction]
pub(crate) fn interval_chart(
    path: &str,
    title: &str,
    x_label: &str,
    x_max: f64,
    rows: Vec<(String, f64, f64, f64)>,
) -> PyResult<()> {
    let rows: Vec<herb_picture::IntervalRow> = rows
        .into_iter()
        .map(|(label, value, lo, hi)| herb_picture::IntervalRow {
            label,
            value,
            lo,
            hi,
        })
        .collect();
    herb_picture::write_interval_chart(Path::new(path), title, x_label, x_max, &rows)
        .map_err(|e| PyRuntimeError::new_err(e.to_string()))
}
