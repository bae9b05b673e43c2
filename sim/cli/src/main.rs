//! `herb-sim`: the packing world's command line (evaluation, one-episode packing, catalog).

use clap::builder::{PossibleValuesParser, TypedValueParser};
use clap::{Args, Parser, Subcommand};
use herb_sim::boxed::{self, Episode};
use herb_sim::catalog::Catalog;
use herb_sim::eval::{self, Replay, ReplayPlacer};
use herb_sim::hull::fit_canonical;
use herb_sim::paths::{self, MeshSource};
use herb_sim::{PackingEnv, RewardMode, SharedCatalog, WorldConfig};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Instant;

mod plot;

use herb_decide::{Order, PolicySpec, SequenceModel};
use herb_methods::evaluation;
use herb_methods::{EvalRun, EvalSettings, Method, MethodSettings, Row};
use herb_picture::{PictureObject, write_pack_picture};
use herb_search::TwinKind;

/// The replays `herb-sim pack` shows.
const REPLAYS: [Method; 3] = [Method::Human, Method::HumanPose, Method::Random];

/// A clap parser accepting the names of `methods` (listed in `--help` and in errors).
fn method_parser(
    methods: &[Method],
) -> impl clap::builder::TypedValueParser<Value = Method> + use<> {
    PossibleValuesParser::new(methods.iter().map(|m| m.name()))
        .map(|s| s.parse::<Method>().expect("a listed name"))
}

/// A clap parser accepting the names of [`Order::ALL`] and the aliases [`Order::ALIASES`].
fn order_parser() -> impl clap::builder::TypedValueParser<Value = Order> {
    let names = Order::ALL
        .map(|o| o.name())
        .into_iter()
        .chain(Order::ALIASES.map(|(alias, _)| alias));
    PossibleValuesParser::new(names).map(|s| s.parse::<Order>().expect("a listed name"))
}

#[derive(Parser)]
#[command(
    name = "herb-sim",
    version,
    about = "The HERB packing world: evaluation and tools"
)]
struct Cli {
    #[command(flatten)]
    data: DataArgs,
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Args)]
struct DataArgs {
    /// BoxED root folder (default: $HERB_BOXED, else ../shared/boxed).
    #[arg(long, global = true)]
    boxed: Option<PathBuf>,
    /// Mesh folder (default: $HERB_MESHES, else <boxed>/meshes if present).
    #[arg(long, global = true)]
    meshes: Option<PathBuf>,
    /// Use primitive shapes even if meshes are available.
    #[arg(long, global = true)]
    no_meshes: bool,
    /// Object catalog file (default: the built-in models/objects.toml).
    #[arg(long, global = true)]
    catalog: Option<PathBuf>,
    /// Do not print which shape source each object used.
    #[arg(long, global = true)]
    quiet: bool,
}

#[derive(Subcommand)]
enum Cmd {
    /// Run methods over all BoxED episodes and write the Table I metrics (Markdown, CSV, plots).
    Eval(Box<EvalArgs>),
    /// Pack one BoxED episode, print each placement, and write a picture of the final pack.
    Pack(PackArgs),
    /// Count the human object-type transitions of all BoxED episodes and write the sequence
    /// model (`models/sequence.json`, used by Beam-3).
    Sequence(SequenceArgs),
    /// Print each object's shape source; with --fit, fit canonical frames from the meshes.
    Catalog(CatalogArgs),
}

/// Arguments of `herb-sim eval`.
#[derive(Args)]
struct EvalArgs {
    /// Method, optionally with its row's object order as `METHOD@ORDER` (e.g. `blbf@beam3`);
    /// repeat for several rows. Methods: herb, blbf, human, human-pose, random,
    /// human-recorded, packit-so3, bc-mse, bc-mdn, lattice-blbf, lookahead, lattice-reserve,
    /// geo-lookahead.
    #[arg(long)]
    method: Vec<Row>,
    /// Object order of the rows without `@ORDER` (defaults: HERB's, `beam3`, for herb and the
    /// lookahead rules, largest for the BLBF rules); the replays use the human order. The old
    /// flag name `--sequence` is an alias for one release.
    #[arg(long, alias = "sequence", value_parser = order_parser())]
    order: Option<Order>,
    /// The placement policy for herb: a shipped policy's name (cs06, cs09: `models/`) or an
    /// ONNX file (repeat for one herb row per policy, labelled by file stem).
    #[arg(long)]
    policy: Vec<PolicySpec>,
    /// The folder of the behaviour-cloning models for bc-mse and bc-mdn
    /// (`bc-<kind>-heldout-{even,odd}.onnx`, written by `training/bc.py`).
    #[arg(long, default_value = "models")]
    bc_models: PathBuf,
    /// The sequence model for Beam-3.
    #[arg(long, default_value = "models/sequence.json")]
    sequence_model: PathBuf,
    /// Candidates the lookahead teacher simulates per decision.
    #[arg(long, default_value_t = 8)]
    lookahead_k: usize,
    /// Reward whose return the lookahead teacher maximises (simple, c, cs<alpha>).
    #[arg(long, default_value = "cs0.6")]
    lookahead_reward: String,
    /// Objects the lookahead teacher simulates per rollout, the candidate's included (to the
    /// episode's end when absent): horizon 1 is the candidate's own settling, what a student
    /// that sees only the next object could at best learn.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    lookahead_horizon: Option<u64>,
    /// Rollouts the search may run per decision (its budget as a count: rows reproduce).
    #[arg(long, default_value_t = herb_search::DEFAULT_K)]
    search_rollouts: usize,
    /// The search's budget as a time per decision (s) instead of a count of rollouts.
    #[arg(long)]
    search_time_s: Option<f64>,
    /// Candidates the search considers at most, in lattice BLBF's order.
    #[arg(long, default_value_t = herb_search::DEFAULT_K)]
    search_k: usize,
    /// Threads each search decision's rollouts run on (episodes already run in parallel on
    /// `--threads`): the rows are the same whatever the count with a budget of rollouts.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=64))]
    search_threads: u64,
    /// Objects per search rollout, the candidate's included (to the job's end when absent).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    search_horizon: Option<u64>,
    /// The world the search's rollouts run in: `heightmap` (the twin built from the heightmap;
    /// `twin` is its old name), `job` (the job's own twin: the search's decisions replayed and
    /// fitted to the heightmaps, the heightmap twin where they disagree) or `exact` (a clone of
    /// the evaluation's world: the twins' fidelity bound). Default `job`, herbd's.
    #[arg(long, default_value = "job", value_parser = TwinKind::parse)]
    search_world: TwinKind,
    /// The search's rollouts on a live pile (every object they wake simulated) instead of a
    /// rigid one (each object settles alone against the objects before it): for measurements.
    #[arg(long)]
    search_live_pile: bool,
    /// The search's clearance for a gripper that does not release exactly: its candidates
    /// (and its rollouts' placements) back off from the neighbour or wall they were pushed
    /// against by up to this many cells of 6.25 mm, as far as there is room; 0: tight.
    #[arg(long, default_value_t = herb_search::DEFAULT_GAP as u64,
          value_parser = clap::value_parser!(u64).range(0..=herb_sim::lattice::MAX_PUSH_GAP as u64))]
    search_gap: u64,
    /// The search's clearance from the walls for objects that stand above the rim, where the
    /// wall no longer holds one released off its placement: candidates within this many cells
    /// of 6.25 mm of a wall move away from it, as far as there is room; 0: none.
    #[arg(long, default_value_t = 0,
          value_parser = clap::value_parser!(u64).range(0..=herb_sim::lattice::MAX_PUSH_GAP as u64))]
    search_wall_gap: u64,
    /// The robust search: rollouts per candidate, every object of each released off its
    /// placement by `--search-noise` (the same draws for every candidate); 0: one rollout,
    /// exact releases.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u64).range(0..=64))]
    search_samples: u64,
    /// The release error the robust search assumes: MM,DEG (sd of x and y, of yaw); also the
    /// corners `--search-check` tries.
    #[arg(long, default_value = "5,3", value_parser = parse_noise)]
    search_noise: (f32, f32),
    /// The search's release check (on, as herbd's; `--search-check false`: off): each of its
    /// best candidates is first released on the live pile off its placement by the four
    /// corners of `--search-noise`, and passed over when one of those leaves it outside.
    #[arg(long, default_value_t = herb_search::SearchSettings::default().release_check.is_some(),
          num_args = 0..=1, default_missing_value = "true", action = clap::ArgAction::Set)]
    search_check: bool,
    /// The search's support rule (0 to 1; 0: off): a candidate standing above the rim on less
    /// than this share of its footprint, which a release a few millimetres off can slide off
    /// the pile, is ranked as a failed rollout.
    #[arg(long, default_value_t = herb_search::SearchSettings::default().min_support.unwrap_or(0.0),
          value_parser = parse_share)]
    search_min_support: f32,
    /// The search finds its candidates on the camera's heightmap filtered by a 3 x 3 median
    /// (on, as herbd's; `--search-median false`: off), so that the
    /// camera's depth noise no longer decides between positions of the same top.
    #[arg(long, default_value_t = herb_search::SearchSettings::default().median,
          num_args = 0..=1, default_missing_value = "true", action = clap::ArgAction::Set)]
    search_median: bool,
    /// The evaluation's world: `ideal` (every object released where it was decided), `field`
    /// (the shipped field model, models/field.toml: a real cell's release error, seeded per
    /// episode, told to no twin or method) or a field model file.
    #[arg(long, default_value = "ideal")]
    world: String,
    /// Release noise of the evaluation's world, `MM,DEG`: each object is released off the pose
    /// its method decided by normal noise of these standard deviations in x and y (mm) and in
    /// yaw (degrees), as a real gripper does; seeded by the episode's seed. The search's twin is
    /// not told: with noise the world is no longer the model it rolls out in.
    #[arg(long, value_parser = parse_noise)]
    release_noise: Option<(f32, f32)>,
    /// Physics settings of the world (the evaluation's and the search's twins), as
    /// `KEY=VALUE[,KEY=VALUE...]`, e.g. `solver_iterations=4,dt=0.0333`; repeatable. Keys: dt,
    /// settle_cap_s, time_until_sleep_s, sleep_speed_mps, rest_speed_mps, friction, max_corrective_speed_mps,
    /// solver_iterations, prediction_distance_m, length_unit_m, contact_recycle_m, clearance_m, early_out_m, out_past_walls, out_check_steps,
    /// inside_tolerance_m.
    #[arg(long)]
    world_set: Vec<String>,
    /// Base seed (episode i uses seed + i).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Worker threads (episodes run in parallel). The old flag name `--jobs` is an alias for
    /// one release.
    #[arg(long, alias = "jobs", default_value_t = 2)]
    threads: usize,
    /// Only the first N episodes.
    #[arg(long)]
    limit: Option<usize>,
    /// Write a picture of this episode (session name) for every row, as a PNG ...: the final
    /// heightmap of the humans' replays; for the other methods the pack where the episode ended
    /// (top and side views, an object outside in red), run again with the row's method, order,
    /// seed and world.
    #[arg(long)]
    png_episode: Option<String>,
    /// ... to this path.
    #[arg(long, default_value = "results/final-heightmap.png")]
    png: PathBuf,
    /// Write the table (Markdown) here.
    #[arg(long, default_value = "results/table1.md")]
    out: PathBuf,
    /// Write per-episode results (CSV) here; by default beside `--out`, with its name and the
    /// extension `.csv` (results/table1.csv for the default table).
    #[arg(long)]
    csv: Option<PathBuf>,
    /// Write the plots (compactness per step, objects packed) into this folder; by default the
    /// folder of `--out`, so that a table written elsewhere leaves the checkout's results alone.
    #[arg(long)]
    plots: Option<PathBuf>,
}

/// Arguments of `herb-sim pack`.
#[derive(Args)]
struct PackArgs {
    /// Session name (e.g. p1_s1).
    #[arg(long, default_value = "p1_s1")]
    session: String,
    /// Placement method.
    #[arg(long, default_value = "human", value_parser = method_parser(&REPLAYS))]
    method: Method,
    /// Seed for the random method.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output picture.
    #[arg(long, default_value = "results/pack.png")]
    png: PathBuf,
}

/// Arguments of `herb-sim sequence`.
#[derive(Args)]
struct SequenceArgs {
    /// Output file.
    #[arg(long, default_value = "models/sequence.json")]
    out: PathBuf,
}

/// Arguments of `herb-sim catalog`.
#[derive(Args)]
struct CatalogArgs {
    /// Print fitted `yaw_rad`, `origin_mesh_m`, `dims_m` for objects with a mesh.
    #[arg(long)]
    fit: bool,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("herb-sim: error: {e}");
            ExitCode::FAILURE
        }
    }
}

type AnyResult<T> = Result<T, Box<dyn std::error::Error + Send + Sync>>;

fn load_catalog(d: &DataArgs) -> AnyResult<(SharedCatalog, Option<PathBuf>)> {
    let root = paths::boxed_root(d.boxed.as_deref());
    let meshes = if d.no_meshes {
        MeshSource::None("--no-meshes".into())
    } else {
        paths::mesh_source(d.meshes.as_deref(), root.as_deref())
    };
    let t = Instant::now();
    let catalog = match &d.catalog {
        Some(p) => Catalog::load(p, &meshes)?,
        None => Catalog::builtin(&meshes)?,
    };
    if !d.quiet {
        eprintln!(
            "catalog: {} objects in {:.2} s",
            catalog.len(),
            t.elapsed().as_secs_f64()
        );
        for line in catalog.source_report() {
            eprintln!("  {line}");
        }
    }
    Ok((Arc::new(catalog), root))
}

fn need_root(root: Option<PathBuf>) -> AnyResult<PathBuf> {
    root.ok_or_else(|| {
        format!(
            "BoxED data not found: pass --boxed or set {}",
            paths::ENV_BOXED
        )
        .into()
    })
}

fn run(cli: Cli) -> AnyResult<()> {
    match cli.cmd {
        Cmd::Sequence(a) => sequence_cmd(&cli.data, a),
        Cmd::Catalog(a) => catalog_cmd(&cli.data, a),
        Cmd::Pack(a) => pack_cmd(&cli.data, a),
        Cmd::Eval(a) => eval_cmd(&cli.data, *a),
    }
}

/// `herb-sim sequence`: fits the Beam-3 sequence model to the BoxED sessions.
fn sequence_cmd(data: &DataArgs, a: SequenceArgs) -> AnyResult<()> {
    let SequenceArgs { out } = a;
    let (catalog, root) = load_catalog(data)?;
    let root = need_root(root)?;
    let (sessions, bad) = boxed::load_all(&root, &catalog)?;
    if !bad.is_empty() {
        let list: Vec<String> = bad.iter().map(|e| e.to_string()).collect();
        return Err(format!("bad sessions: {}", list.join("; ")).into());
    }
    let episodes: Vec<Episode> = sessions.iter().map(|s| s.episode(&catalog)).collect();
    let model = herb_decide::SequenceModel::fit(
        &catalog,
        episodes.iter().map(|e| &e.objects[..]),
        "BoxED sessions/*/PickPlace_dataset.json: each instance at its first placement, \
             in the human order (herb_sim::boxed::Session::episode)",
    );
    write_file(&out, &model.to_json())?;
    eprintln!(
        "wrote {} ({} episodes, {} transitions)",
        out.display(),
        model.provenance().episodes,
        model.provenance().transitions
    );
    Ok(())
}

/// `herb-sim catalog`: shape sources, and with `--fit` the canonical frames of the meshes.
fn catalog_cmd(data: &DataArgs, a: CatalogArgs) -> AnyResult<()> {
    let CatalogArgs { fit } = a;
    let (catalog, root) = load_catalog(data)?;
    if fit {
        let meshes = paths::mesh_source(data.meshes.as_deref(), root.as_deref());
        let MeshSource::Folder(dir) = meshes else {
            return Err("--fit needs a mesh folder".into());
        };
        for s in catalog.specs() {
            let Some(file) = &s.mesh else { continue };
            let raw = herb_sim::mesh::load_obj_vertices(&dir.join(file))?;
            let scaled: Vec<_> = raw.iter().map(|&v| v * s.mesh_scale).collect();
            // Round objects have no resting face: keep their nominal up axis.
            let refine = s.primitive != herb_sim::catalog::Primitive::Ellipsoid;
            let f = fit_canonical(&scaled, s.up_mesh, refine);
            println!(
                "{}  up_mesh = [{:.5}, {:.5}, {:.5}]\n     yaw_rad = {:.4}\n     origin_mesh_m = [{:.5}, {:.5}, {:.5}]\n     dims_m = [{:.4}, {:.4}, {:.4}]",
                s.id,
                f.up_mesh[0],
                f.up_mesh[1],
                f.up_mesh[2],
                f.yaw_rad,
                f.origin_mesh_m[0],
                f.origin_mesh_m[1],
                f.origin_mesh_m[2],
                f.dims_m[0],
                f.dims_m[1],
                f.dims_m[2]
            );
        }
    }
    Ok(())
}

/// `herb-sim pack`: one BoxED episode, printed, and a picture of the final pack.
fn pack_cmd(data: &DataArgs, a: PackArgs) -> AnyResult<()> {
    let PackArgs {
        session,
        method,
        seed,
        png,
    } = a;
    let (catalog, root) = load_catalog(data)?;
    let root = need_root(root)?;
    let s = boxed::load_session(&root, &session, &catalog)?;
    let ep = s.episode(&catalog);
    let replay = method.replay().expect("the parser accepts replays only");
    pack_one(&catalog, &ep, replay, seed, &png)
}

/// `herb-sim eval`: methods over the BoxED episodes, the Table I metrics (Markdown, CSV, plots).
fn eval_cmd(data: &DataArgs, a: EvalArgs) -> AnyResult<()> {
    check_eval_args(&a)?;
    let settings = a.settings();
    settings.validate()?;
    // One run per (row, policy): herb once per policy, the others once.
    let rows: Vec<Row> = a
        .method
        .iter()
        .flat_map(|r| match r.method {
            Method::Herb => a
                .policy
                .iter()
                .map(|p| Row {
                    policy: Some(p.clone()),
                    ..r.clone()
                })
                .collect(),
            _ => vec![r.clone()],
        })
        .collect();
    for r in &rows {
        settings.check_row(r)?;
    }
    let (catalog, root) = load_catalog(data)?;
    let root = need_root(root)?;
    let (sessions, bad) = boxed::load_all(&root, &catalog)?;
    for e in &bad {
        eprintln!("skipping bad session: {e}");
    }
    let mut episodes: Vec<Episode> = sessions.iter().map(|s| s.episode(&catalog)).collect();
    if let Some(n) = a.limit {
        episodes.truncate(n);
    }
    // The sequence model, when any row orders its objects by Beam-3.
    let model = if rows.iter().any(|r| settings.needs_sequence_model(r)) {
        Some(SequenceModel::load(&settings.sequence_model, &catalog)?)
    } else {
        None
    };
    let target = eval::mean_std(episodes.iter().map(|e| e.objects.len() as f64));
    let cfg = settings.world()?;
    let base = settings.method_settings(&cfg)?;
    let mut all_results = Vec::new();
    let mut csv_text = String::from(evaluation::CSV_HEADER);
    let run = EvalRun {
        catalog: &catalog,
        cfg: &cfg,
        episodes: &episodes,
        first: 0,
        model: model.as_ref(),
        seed: settings.seed,
        threads: a.threads,
    };
    let models_dir = Path::new(PolicySpec::DEFAULT_MODELS_DIR);
    for row in rows {
        let m = row.method;
        let t = Instant::now();
        let row_settings = settings.row_settings(&row, &base, models_dir);
        if let Some(PolicySpec::Onnx(p)) = &row_settings.policy {
            let bytes = std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
            eprintln!("policy {}: {:.2} MB", p.display(), bytes as f64 / 1e6);
        }
        let names = settings.row_names(&row, &row_settings);
        let order = settings.order_of(&row);
        let results = run.method(m, order, &row_settings)?;
        let secs = t.elapsed().as_secs_f64();
        let placements: usize = results
            .iter()
            .filter_map(|r| r.as_ref().ok())
            .map(|r| r.placements)
            .sum();
        eprintln!(
            "{}: {} episodes, {} placements in {:.1} s ({:.0} placements/s on {} threads)",
            names.label,
            results.len(),
            placements,
            secs,
            placements as f64 / secs,
            a.threads
        );
        for e in results.iter().filter_map(|r| r.as_ref().err()) {
            eprintln!("episode failed: {e}");
        }
        csv_text.push_str(&evaluation::csv_rows(
            &names.name,
            &names.sequence,
            &results,
        ));
        if let Some(ep_name) = a
            .png_episode
            .as_ref()
            .filter(|_| m != Method::HumanRecorded)
        {
            let i = episodes
                .iter()
                .position(|e| &e.name == ep_name)
                .ok_or_else(|| format!("no episode {ep_name:?}"))?;
            let path = a.png.with_file_name(format!(
                "{}-{}-{}.png",
                a.png
                    .file_stem()
                    .and_then(|s| s.to_str())
                    .unwrap_or("final"),
                names.name.replace(' ', "-"),
                ep_name
            ));
            match m.replay() {
                Some(sm) => pack_quiet(&catalog, &episodes[i], sm, settings.seed, &path)?,
                None => picture(&run, m, order, &row_settings, i, &names.label, &path)?,
            }
            eprintln!("wrote {}", path.display());
        }
        all_results.push((names.label, results));
    }
    let mut notes = Vec::new();
    if let Some(m) = settings.field_model()? {
        notes.push(evaluation::field_note(&m, &settings.world));
    }
    if let Some(noise) = settings.release_noise {
        notes.push(evaluation::release_noise_note(noise));
    }
    if !bad.is_empty() {
        notes.push(format!(
            "sessions skipped at load (every row): {}: {}",
            bad.len(),
            bad.iter()
                .map(|e| e.to_string())
                .collect::<Vec<_>>()
                .join("; ")
        ));
    }
    let table = evaluation::report(&all_results, target, episodes.len(), &notes);
    println!("{table}");
    let (csv, plots) = (a.csv_path(), a.plots_dir());
    write_file(&a.out, &table)?;
    write_file(&csv, &csv_text)?;
    eprintln!("wrote {} and {}", a.out.display(), csv.display());
    match plot::write_plots(&plots, &all_results) {
        Ok(files) => {
            for f in files {
                eprintln!("wrote {}", f.display());
            }
        }
        // The table and CSV are already written: report and keep them.
        Err(e) => eprintln!("herb-sim: plots not written: {e}"),
    }
    Ok(())
}

impl EvalArgs {
    /// Where the per-episode CSV goes: `--csv`, or `--out` with the extension `.csv`.
    fn csv_path(&self) -> PathBuf {
        self.csv
            .clone()
            .unwrap_or_else(|| self.out.with_extension("csv"))
    }

    /// Where the plots go: `--plots`, or the folder `--out` is written in.
    fn plots_dir(&self) -> PathBuf {
        let beside = || {
            let dir = self.out.parent().filter(|d| !d.as_os_str().is_empty());
            dir.unwrap_or(Path::new(".")).to_path_buf()
        };
        self.plots.clone().unwrap_or_else(beside)
    }

    /// The settings every row shares, as the library names them (one conversion; a sweep's
    /// configuration gives the same settings by the same names).
    fn settings(&self) -> EvalSettings {
        EvalSettings {
            order: self.order,
            bc_models: self.bc_models.clone(),
            sequence_model: self.sequence_model.clone(),
            lookahead_k: self.lookahead_k,
            lookahead_reward: self.lookahead_reward.clone(),
            lookahead_horizon: self.lookahead_horizon.map(|h| h as usize),
            search_rollouts: self.search_rollouts,
            search_time_s: self.search_time_s,
            search_k: self.search_k,
            search_threads: self.search_threads as usize,
            search_horizon: self.search_horizon.map(|h| h as usize),
            search_world: self.search_world.name().into(),
            search_live_pile: self.search_live_pile,
            search_gap: self.search_gap as usize,
            search_wall_gap: self.search_wall_gap as usize,
            search_samples: self.search_samples as usize,
            search_noise: self.search_noise,
            search_check: self.search_check,
            search_min_support: self.search_min_support,
            search_median: self.search_median,
            world: self.world.clone(),
            release_noise: self.release_noise,
            world_set: self.world_set.clone(),
            seed: self.seed,
        }
    }
}

/// The argument checks of `herb-sim eval` that need no data.
fn check_eval_args(a: &EvalArgs) -> AnyResult<()> {
    if a.method.is_empty() {
        return Err("give at least one --method (see herb-sim eval --help)".into());
    }
    let has = |m: Method| a.method.iter().any(|r| r.method == m);
    if has(Method::Herb) && a.policy.is_empty() {
        return Err("herb needs --policy <model.onnx> (e.g. models/policy-cs06.onnx)".into());
    }
    if !a.policy.is_empty() && !has(Method::Herb) {
        return Err("--policy is used by --method herb only".into());
    }
    Ok(())
}

/// Runs episode `i` once more with method `m` as [`EvalRun::method`] runs it (same order, seed
/// and world) and writes the pack where it ended to `path` (top and side views).
fn picture(
    run: &EvalRun<'_>,
    m: Method,
    order: Option<Order>,
    settings: &MethodSettings,
    i: usize,
    label: &str,
    path: &Path,
) -> AnyResult<()> {
    let ep = &run.episodes[i];
    let s = run.episode_seed(i);
    let objects = match order {
        Some(o) => o.order(run.catalog, run.model, &ep.objects, s)?,
        None => ep.objects.clone(),
    };
    let mut env = PackingEnv::new(run.catalog.clone(), run.cfg.clone(), RewardMode::Simple)?;
    let mut placer = m.placer(run.catalog, settings)?;
    let r =
        eval::run_episode(&mut env, ep, &objects, placer.as_mut(), s).map_err(|e| e.to_string())?;
    let objects: Vec<PictureObject> = env
        .world_mut()
        .report()
        .iter()
        .enumerate()
        .map(|(k, o)| PictureObject {
            label: format!("{} {}", k + 1, run.catalog.spec(o.ty).id),
            lo: o.lo,
            hi: o.hi,
            outside: o.violation.map(|(b, by)| (b.to_string(), by)),
        })
        .collect();
    let verdict = format!(
        "{}: {label}, {} ({} of {} packed)",
        ep.name,
        if r.success { "success" } else { "FAILED" },
        r.packed,
        r.objects
    );
    write_pack_picture(path, &verdict, env.world().heightmap(), &objects)?;
    Ok(())
}

fn write_file(p: &Path, text: &str) -> AnyResult<()> {
    if let Some(d) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d)?;
    }
    std::fs::write(p, text).map_err(|e| format!("cannot write {}: {e}", p.display()).into())
}

fn pack_quiet(
    catalog: &SharedCatalog,
    ep: &Episode,
    m: Replay,
    seed: u64,
    png: &Path,
) -> AnyResult<()> {
    let mut env = PackingEnv::new(catalog.clone(), WorldConfig::default(), RewardMode::Simple)?;
    let mut placer = ReplayPlacer::new(m)?;
    eval::run_episode(&mut env, ep, &ep.objects, &mut placer, seed)?;
    herb_sim::image::write_heightmap_png(png, env.world().heightmap(), 0.30, 3)?;
    Ok(())
}

fn pack_one(
    catalog: &SharedCatalog,
    ep: &Episode,
    m: Replay,
    seed: u64,
    png: &Path,
) -> AnyResult<()> {
    let mut env = PackingEnv::new(
        catalog.clone(),
        WorldConfig::default(),
        RewardMode::cs(0.6)?,
    )?;
    env.reset(&ep.objects, seed)?;
    let mut placer = ReplayPlacer::new(m)?;
    eval::Placer::begin_episode(&mut placer, ep, seed).map_err(|e| e.to_string())?;
    println!(
        "episode {} ({} objects), method {}",
        ep.name,
        ep.objects.len(),
        m.name()
    );
    let t = Instant::now();
    for (i, &ty) in ep.objects.iter().enumerate() {
        let decided = eval::Placer::decide(&mut placer, &mut env).map_err(|e| e.to_string())?;
        let Some(d) = decided else { break };
        let step = eval::apply(&mut env, d)?;
        let o = step.info.outcome;
        let (x, y, th) = step.info.placement;
        println!(
            "{:>3} {} {:<18} x {:+.3} y {:+.3} theta {:+6.1} deg z {:.3}  {}  tilt {:5.1} deg  C {:.3}  reward {:+.3}{}",
            i + 1,
            catalog.spec(ty).id,
            catalog.spec(ty).name,
            x,
            y,
            th.to_degrees(),
            o.z,
            if o.inside { "inside " } else { "OUTSIDE" },
            o.tilt_rad.to_degrees(),
            o.compactness,
            step.reward,
            match (o.first_outside, o.violation) {
                (Some(i), Some((what, by))) => format!(
                    "  (object {} crosses the {what} by {:.1} cm)",
                    i + 1,
                    by * 100.0
                ),
                _ => String::new(),
            }
        );
        if step.terminated {
            println!(
                "{} after {} of {} objects ({:.2} s)",
                if step.info.success {
                    "success"
                } else {
                    "failed"
                },
                step.info.packed,
                ep.objects.len(),
                t.elapsed().as_secs_f64()
            );
            break;
        }
    }
    herb_sim::image::write_heightmap_png(png, env.world().heightmap(), 0.30, 3)?;
    println!("wrote {}", png.display());
    Ok(())
}

/// `MM,DEG` of `--release-noise`: two finite, non-negative numbers.
fn parse_noise(s: &str) -> Result<(f32, f32), String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let [mm, deg] = parts[..] else {
        return Err(format!("{s:?}: expected MM,DEG (e.g. 5,3)"));
    };
    let num = |v: &str, what: &str| -> Result<f32, String> {
        match v.parse::<f32>() {
            Ok(x) if x.is_finite() && x >= 0.0 => Ok(x),
            _ => Err(format!("{what} {v:?}: expected a number >= 0")),
        }
    };
    Ok((num(mm, "MM")?, num(deg, "DEG")?))
}

/// A share from 0 to 1 (`--search-min-support`).
fn parse_share(s: &str) -> Result<f32, String> {
    let x = s
        .trim()
        .parse::<f32>()
        .map_err(|_| format!("{s:?}: expected a share from 0 to 1 (e.g. 0.3)"))?;
    herb_search::support_rule(x).map(|_| x)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `herb-sim eval`'s flags default to what a sweep's configuration defaults to: the
    /// library's `EvalSettings::default()`.
    #[test]
    fn the_flags_default_to_the_library_settings() {
        let cli = Cli::try_parse_from(["herb-sim", "eval", "--method", "blbf"]).unwrap();
        let Cmd::Eval(a) = cli.cmd else {
            panic!("not eval")
        };
        assert_eq!(a.settings(), EvalSettings::default());
    }

    fn eval_args(args: &[&str]) -> EvalArgs {
        let cli = Cli::try_parse_from(["herb-sim", "eval"].iter().chain(args)).unwrap();
        let Cmd::Eval(a) = cli.cmd else {
            panic!("not eval")
        };
        *a
    }

    /// The CSV and the plots go beside the table: a table written elsewhere does not overwrite
    /// the checkout's results/table1.csv or its plots; the defaults stay results/.
    #[test]
    fn the_csv_and_plots_follow_the_table() {
        let a = eval_args(&[]);
        assert_eq!(a.csv_path(), PathBuf::from("results/table1.csv"));
        assert_eq!(a.plots_dir(), PathBuf::from("results"));
        let a = eval_args(&["--out", "/tmp/run/s.md"]);
        assert_eq!(a.csv_path(), PathBuf::from("/tmp/run/s.csv"));
        assert_eq!(a.plots_dir(), PathBuf::from("/tmp/run"));
        let a = eval_args(&["--out", "s.md"]);
        assert_eq!(a.plots_dir(), PathBuf::from("."));
        let a = eval_args(&["--out", "s.md", "--csv", "x/e.csv", "--plots", "p"]);
        assert_eq!(a.csv_path(), PathBuf::from("x/e.csv"));
        assert_eq!(a.plots_dir(), PathBuf::from("p"));
    }
}
