//! `herb-sim eval` as a user runs it: one herb row per `--policy`, and clear errors for a herb
//! method without a policy or a policy without the herb method.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn herb_sim(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_herb-sim"))
        .args(args)
        .current_dir(repo())
        .output()
        .expect("run herb-sim")
}

/// `herb-sim eval` on the BoxED episodes at `root` with `args`, its table, CSV and plots written
/// into `dir`; fails the test if it fails. Returns the table (Markdown) and the CSV.
fn eval_into(root: &Path, dir: &Path, args: &[&str]) -> (String, String) {
    let s = |p: &Path| p.to_str().unwrap().to_owned();
    let (md, csv) = (dir.join("t.md"), dir.join("t.csv"));
    let mut all = vec!["eval".to_owned(), "--boxed".to_owned(), s(root)];
    all.extend(args.iter().map(|a| a.to_string()));
    for (flag, path) in [
        ("--out", &md),
        ("--csv", &csv),
        ("--plots", &dir.to_path_buf()),
    ] {
        all.push(flag.to_owned());
        all.push(s(path));
    }
    all.push("--quiet".to_owned());
    let out = herb_sim(&all.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    (
        std::fs::read_to_string(&md).unwrap(),
        std::fs::read_to_string(&csv).unwrap(),
    )
}

#[test]
fn herb_needs_a_policy_and_a_policy_needs_herb() {
    let out = herb_sim(&["eval", "--method", "herb"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("herb needs --policy"), "{err}");

    let out = herb_sim(&[
        "eval",
        "--method",
        "blbf",
        "--policy",
        "models/fixtures/tiny_policy.onnx",
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--policy is used by --method herb only"),
        "{err}"
    );
}

#[test]
fn one_herb_row_per_policy() {
    let Some(root) = herb_sim::paths::boxed_root_for_tests() else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("herb-eval-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // Two copies of one fixture network under different names: the rows are told apart by the
    // file stem, and identical weights must give identical rows.
    let src = repo().join("models/fixtures/tiny_policy.onnx");
    let (a, b) = (dir.join("first.onnx"), dir.join("second.onnx"));
    std::fs::copy(&src, &a).unwrap();
    std::fs::copy(&src, &b).unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_owned();
    let (table, rows) = eval_into(
        &root,
        &dir,
        &[
            "--method",
            "herb",
            "--policy",
            &s(&a),
            "--policy",
            &s(&b),
            "--limit",
            "2",
        ],
    );
    let row = |name: &str| {
        table
            .lines()
            .find(|l| l.starts_with(&format!("| herb {name} (beam3) (ours) |")))
            .unwrap_or_else(|| panic!("no row for {name} in\n{table}"))
            .split('|')
            .skip(2)
            .take(2)
            .map(|c| c.trim().to_owned())
            .collect::<Vec<_>>()
    };
    // Success and objects packed match (latency is measured, so it is not compared).
    assert_eq!(row("first"), row("second"));
    assert_eq!(
        rows.lines()
            .filter(|l| l.starts_with("herb first,"))
            .count(),
        2
    );
    assert_eq!(
        rows.lines()
            .filter(|l| l.starts_with("herb second,"))
            .count(),
        2
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn the_lookahead_horizon_names_its_row_and_refuses_zero() {
    let out = herb_sim(&["eval", "--method", "lookahead", "--lookahead-horizon", "0"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--lookahead-horizon"), "{err}");

    let Some(root) = herb_sim::paths::boxed_root_for_tests() else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("herb-eval-horizon-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (table, _) = eval_into(
        &root,
        &dir,
        &[
            "--method",
            "lookahead",
            "--lookahead-k",
            "2",
            "--lookahead-horizon",
            "1",
            "--limit",
            "1",
        ],
    );
    assert!(
        table
            .lines()
            .any(|l| l.starts_with("| lookahead (teacher, k = 2, horizon 1) (beam3) (ours) |")),
        "{table}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn release_noise_is_said_in_the_table_and_bad_noise_is_refused() {
    for bad in ["5", "5,-1", "x,3", "5,3,1", "100,3"] {
        let out = herb_sim(&["eval", "--method", "blbf", "--release-noise", bad]);
        assert!(!out.status.success(), "{bad} was accepted");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("release"), "{bad}: {err}");
    }
    let Some(root) = herb_sim::paths::boxed_root_for_tests() else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("herb-eval-noise-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (table, _) = eval_into(
        &root,
        &dir,
        &["--method", "blbf", "--release-noise", "5,3", "--limit", "1"],
    );
    assert!(
        table.contains("release noise (every row)") && table.contains("sd 5 mm"),
        "{table}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_support_share_outside_0_to_1_is_refused() {
    for bad in ["-0.1", "1.5", "nan", "x"] {
        let arg = format!("--search-min-support={bad}");
        let out = herb_sim(&["eval", "--method", "search", &arg]);
        assert!(!out.status.success(), "{bad} was accepted");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("--search-min-support"), "{bad}: {err}");
    }
}
