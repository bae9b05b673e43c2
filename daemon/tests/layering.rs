//! The workspace's dependency rules, checked on the graph cargo resolves.
//!
//! Dependencies point one way: the simulation, the decision core, the CLI and the bindings never
//! reach IPC, real-time motion or the daemon; the robot side (loopback, adapters, robot crate)
//! never reaches the learned policies; the wire types reach no other HERB crate. Only normal and
//! build dependencies count (a test may link whatever it checks against).
//!
//! A library or binary built without its unit-test harness (`test = false`, to spare the test
//! build a second compile of it) must hold no unit test, since one added there would never run.
//!
//! `PENDING` lists the violations the restructuring has not removed yet. Each entry must still be
//! a violation: once a step removes one, this test fails until the entry is deleted, so the list
//! only shrinks.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;

/// (package, crates it must never reach, directly or transitively).
const RULES: &[(&str, &[&str])] = &[
    // The domain core: no physics engine, no pictures, no learned policies, no IPC.
    (
        "herb-core",
        &[
            "rapier3d",
            "plotters",
            "tract-onnx",
            "iceoryx2",
            "ruckig",
            "herb-sim",
            "herb-ipc",
            "herb-robot",
            "herb-adapter",
            "herb-decide",
            "herb-daemon",
        ],
    ),
    (
        "herb-sim",
        &[
            "plotters",
            "iceoryx2",
            "ruckig",
            "tract-onnx",
            "herb-ipc",
            "herb-robot",
            "herb-adapter",
            "herb-decide",
            "herb-methods",
            "herb-daemon",
        ],
    ),
    // The packing world (physics): no policies, no search, no evaluation, no IPC.
    (
        "herb-world",
        &[
            "tract-onnx",
            "plotters",
            "iceoryx2",
            "ruckig",
            "herb-decide",
            "herb-search",
            "herb-sim",
            "herb-ipc",
            "herb-robot",
            "herb-daemon",
        ],
    ),
    // The search herbd ships: the world and the decision core, without the RL environment, the
    // evaluation or the teachers (herb-sim), the registry, IPC or motion.
    (
        "herb-search",
        &[
            "herb-sim",
            "herb-methods",
            "plotters",
            "iceoryx2",
            "ruckig",
            "herb-ipc",
            "herb-robot",
            "herb-adapter",
            "herb-daemon",
        ],
    ),
    // The decision core herbd ships: the policies, the order and the Decider, on the domain
    // core alone (no physics engine, no pictures).
    (
        "herb-decide",
        &[
            "rapier3d",
            "plotters",
            "herb-sim",
            "herb-search",
            "herb-methods",
            "iceoryx2",
            "ruckig",
            "herb-ipc",
            "herb-robot",
            "herb-adapter",
            "herb-daemon",
        ],
    ),
    ("herb-methods", SIM_SIDE_NEVER),
    ("herb-sim-cli", SIM_SIDE_NEVER),
    ("herb-sim-py", SIM_SIDE_NEVER),
    (
        "herb-ipc",
        &[
            "herb-sim",
            "herb-decide",
            "herb-methods",
            "herb-robot",
            "herb-adapter",
            "herb-daemon",
        ],
    ),
    // herbd: no pictures (herbctl, its own crate, draws them), not the RL environment, the
    // evaluation or the teachers (herb-sim), not the evaluation's registry; the physics engine
    // only through the search (see ONLY_THROUGH).
    (
        "herb-daemon",
        &["plotters", "herb-sim", "herb-methods", "herb-picture"],
    ),
    // The Rust client library: the wire and iceoryx2 only; no physics engine, policies'
    // runtime or pictures, and none of the crates that bring them.
    (
        "herb-client",
        &[
            "rapier3d",
            "tract-onnx",
            "plotters",
            "herb-core",
            "herb-sim",
            "herb-picture",
            "herb-decide",
            "herb-methods",
            "herb-robot",
            "herb-daemon",
        ],
    ),
    // herbctl, a thin client: the client library, the wire, the core and the pictures; never
    // herbd (its replay, explain and cell calibration are `herbd` tools), the physics engine,
    // the policies' runtime or real-time motion.
    (
        "herbctl",
        &[
            "rapier3d",
            "tract-onnx",
            "ruckig",
            "herb-daemon",
            "herb-sim",
            "herb-decide",
            "herb-methods",
            "herb-robot",
        ],
    ),
    ("herb-robot", ROBOT_SIDE_NEVER),
    (
        "herb-adapter",
        &[
            "tract-onnx",
            "herb-decide",
            "herb-daemon",
            "herb-robot",
            "ruckig",
        ],
    ),
    // The loopback simulates the cell with the world alone: not the evaluation.
    (
        "herb-loopback",
        &[
            "tract-onnx",
            "herb-decide",
            "herb-daemon",
            "herb-testkit",
            "herb-sim",
        ],
    ),
    // The real cell's adapters link neither the physics engine, the learned policies' runtime
    // nor the pictures.
    (
        "herb-baxter",
        &[
            "rapier3d",
            "plotters",
            "tract-onnx",
            "herb-decide",
            "herb-daemon",
            "herb-sim",
            "herb-loopback",
            "herb-testkit",
        ],
    ),
    // The camera adapter needs no arm: no kinematics, no Ruckig.
    (
        "herb-camera",
        &[
            "rapier3d",
            "plotters",
            "herb-sim",
            "tract-onnx",
            "herb-decide",
            "herb-daemon",
            "herb-loopback",
            "herb-testkit",
            "herb-robot",
            "ruckig",
        ],
    ),
    // The chaos soak drives the cell from outside, as an operator and the bus see it: never
    // herbd's insides, the evaluation or the policies.
    (
        "herb-chaos",
        &[
            "tract-onnx",
            "herb-decide",
            "herb-daemon",
            "herb-sim",
            "herb-search",
            "rapier3d",
        ],
    ),
    // Process plumbing (configuration files, real-time timing): apart from the arm's
    // kinematics and motion.
    (
        "herb-process",
        &[
            "ruckig",
            "nalgebra",
            "rapier3d",
            "tract-onnx",
            "herb-robot",
            "herb-core",
            "herb-daemon",
        ],
    ),
    // The ROS side knows ROS only: no HERB crate, no IPC, no motion.
    (
        "herb-ros1",
        &[
            "iceoryx2",
            "ruckig",
            "tract-onnx",
            "herb-ipc",
            "herb-robot",
            "herb-adapter",
            "herb-sim",
            "herb-decide",
            "herb-daemon",
        ],
    ),
];

/// (package, crate, the one crate through which the package may reach it): with that crate
/// taken out of the graph, the package reaches the crate no more.
const ONLY_THROUGH: &[(&str, &str, &str)] = &[
    // herbd decides through the decision core (policies, no physics); the decision worker's
    // search (`herb-search`, its twins in `herb-world`) is its one way to the physics engine.
    ("herb-daemon", "rapier3d", "herb-search"),
];

/// What the simulation-side crates (decision core, CLI, bindings) never reach.
const SIM_SIDE_NEVER: &[&str] = &[
    "iceoryx2",
    "ruckig",
    "herb-ipc",
    "herb-robot",
    "herb-adapter",
    "herb-daemon",
];

/// What the robot-side crates (robot, adapters, loopback) never reach (the test helpers are
/// for tests only).
const ROBOT_SIDE_NEVER: &[&str] = &["tract-onnx", "herb-decide", "herb-daemon", "herb-testkit"];

/// Violations still to be removed by the restructuring (package, forbidden crate reached);
/// empty since the loopback left herb-daemon.
const PENDING: &[(&str, &str)] = &[];

/// `cargo metadata` of the workspace, with `args`, as JSON.
fn cargo_metadata(args: &[&str]) -> Value {
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/..");
    let out = Command::new(env!("CARGO"))
        .args(["metadata", "--format-version", "1"])
        .args(args)
        .current_dir(root)
        .output()
        .expect("cargo metadata runs");
    assert!(
        out.status.success(),
        "cargo metadata failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("cargo metadata prints JSON")
}

/// Package name -> names of its normal and build dependencies, as cargo resolves them. Not
/// `--offline`: `cargo metadata` reads the manifests of every platform's packages (Windows-only
/// ones included), which a Linux build never downloads, so a fresh cargo home must fetch them.
fn resolved_graph() -> BTreeMap<String, BTreeSet<String>> {
    let meta = cargo_metadata(&[]);
    let names: BTreeMap<&str, &str> = meta["packages"]
        .as_array()
        .expect("packages")
        .iter()
        .map(|p| (p["id"].as_str().unwrap(), p["name"].as_str().unwrap()))
        .collect();
    let mut graph = BTreeMap::new();
    for node in meta["resolve"]["nodes"].as_array().expect("resolve.nodes") {
        let name = names[node["id"].as_str().unwrap()].to_owned();
        let deps = node["deps"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|d| {
                d["dep_kinds"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .any(|k| k["kind"].is_null() || k["kind"] == "build")
            })
            .map(|d| names[d["pkg"].as_str().unwrap()].to_owned());
        graph.entry(name).or_insert_with(BTreeSet::new).extend(deps);
    }
    graph
}

/// Every crate `from` reaches through normal and build dependencies.
fn reach(graph: &BTreeMap<String, BTreeSet<String>>, from: &str) -> BTreeSet<String> {
    reach_avoiding(graph, from, None)
}

/// Every crate `from` reaches without passing through `avoid`.
fn reach_avoiding(
    graph: &BTreeMap<String, BTreeSet<String>>,
    from: &str,
    avoid: Option<&str>,
) -> BTreeSet<String> {
    let mut seen = BTreeSet::new();
    let mut stack = vec![from.to_owned()];
    while let Some(p) = stack.pop() {
        for d in graph.get(&p).into_iter().flatten() {
            if Some(d.as_str()) != avoid && seen.insert(d.clone()) {
                stack.push(d.clone());
            }
        }
    }
    seen
}

#[test]
fn some_crates_are_reached_through_one_crate_only() {
    let graph = resolved_graph();
    for (package, target, via) in ONLY_THROUGH {
        let direct = reach(&graph, package);
        assert!(
            direct.contains(*via),
            "{package} no longer reaches {via}: update the rule"
        );
        let around = reach_avoiding(&graph, package, Some(via));
        assert!(
            !around.contains(*target),
            "{package} reaches {target} other than through {via}"
        );
    }
}

#[test]
fn dependencies_point_one_way() {
    let graph = resolved_graph();
    assert!(
        graph.contains_key("herb-daemon") && graph.contains_key("herb-sim"),
        "the workspace graph was not read"
    );
    let mut violations = BTreeSet::new();
    for (package, never) in RULES {
        if !graph.contains_key(*package) {
            continue;
        }
        let reached = reach(&graph, package);
        for crate_name in *never {
            if reached.contains(*crate_name) {
                violations.insert((package.to_string(), crate_name.to_string()));
            }
        }
    }
    let pending: BTreeSet<(String, String)> = PENDING
        .iter()
        .map(|(p, c)| (p.to_string(), c.to_string()))
        .collect();
    let new: Vec<_> = violations.difference(&pending).collect();
    let fixed: Vec<_> = pending.difference(&violations).collect();
    assert!(
        new.is_empty(),
        "dependency rules broken (package, crate): {new:?}"
    );
    assert!(
        fixed.is_empty(),
        "no longer violated, delete from PENDING: {fixed:?}"
    );
}

#[test]
fn the_rules_name_real_workspace_packages() {
    let graph = resolved_graph();
    let missing: Vec<&str> = RULES
        .iter()
        .map(|(p, _)| *p)
        .chain(ONLY_THROUGH.iter().flat_map(|(p, _, via)| [*p, *via]))
        .filter(|p| !graph.contains_key(*p))
        .collect();
    assert!(
        missing.is_empty(),
        "rules name packages the workspace does not have: {missing:?}"
    );
}

/// The `.rs` files under `dir`, recursively.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("a source folder reads") {
        let path = entry.expect("a source folder entry").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

#[test]
fn targets_built_without_a_test_harness_hold_no_unit_tests() {
    let meta = cargo_metadata(&["--no-deps", "--offline"]);
    let (mut skipped, mut tests) = (Vec::new(), Vec::new());
    for target in meta["packages"]
        .as_array()
        .expect("packages")
        .iter()
        .flat_map(|p| p["targets"].as_array().expect("targets"))
    {
        let kinds = target["kind"].as_array().expect("kind");
        let lib_or_bin = kinds.iter().any(|k| k == "lib" || k == "bin");
        if !lib_or_bin || target["test"] != Value::Bool(false) {
            continue;
        }
        skipped.push(target["name"].as_str().unwrap().to_owned());
        // The target's folder: a library's src/ (with its modules), a binary's own folder.
        let src = Path::new(target["src_path"].as_str().expect("src_path"));
        let mut files = Vec::new();
        rust_files(src.parent().unwrap(), &mut files);
        for file in files {
            let text = std::fs::read_to_string(&file).unwrap();
            if text.contains("#[test]") || text.contains("#[cfg(test)]") {
                tests.push(file);
            }
        }
    }
    // The manifests mark some (herbd, the loopback, herb-sim, ...): the check checks something.
    assert!(skipped.iter().any(|t| t == "herbd"), "{skipped:?}");
    assert!(
        tests.is_empty(),
        "unit tests in targets built without a test harness ({skipped:?}), which never run: \
         {tests:?}; remove `test = false` from their manifest"
    );
}
