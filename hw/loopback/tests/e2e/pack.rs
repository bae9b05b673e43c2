//! Packing an episode: with the SAC policy, a candidate policy, the README's demo script and
//! herbd's default search (replayed bit for bit).

use super::*;

/// With the shipped SAC policy (CS0.6, `[decision] method = "policy"`): herbd loads it and
/// decides every placement with it; the other tests decide by herbd's default, the search.
#[test]
fn packs_a_boxed_episode_end_to_end_with_real_processes() {
    pack_shortest_episode_with("episode", &repo().join("models/policy-cs06.onnx"));
}

/// The README's main command, `scripts/demo.sh`, as a newcomer runs it (on the shortest
/// session, with the binaries this test run built): it packs the episode, prints the verdict
/// and writes its picture and logs into its run folder.
#[test]
fn the_readme_demo_script_packs_an_episode() {
    let Some(root) = herb_sim::paths::boxed_root_for_tests() else {
        return;
    };
    let (session, n) = shortest_session(&root);
    let bin = loopback_exe().parent().unwrap().to_owned();
    herb_testkit::exe("herbd", "herb-daemon");
    herb_testkit::exe("herbctl", "herbctl");
    let out = tmp("demo-script");
    let run = std::process::Command::new("bash")
        .arg(repo().join("scripts/demo.sh"))
        .arg(&session)
        .env("DEMO_BIN", &bin)
        .env("DEMO_OUT", &out)
        .env("HERB_BOXED", &root)
        .output()
        .expect("bash runs");
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(
        stdout.contains(&format!("verdict: SUCCESS: {n}/{n} placed")),
        "{stdout}"
    );
    assert!(out.join("pack.png").is_file(), "{}", out.display());
    assert!(
        stdout.contains("herbd:") && stdout.contains("loopback:"),
        "{stdout}"
    );
}

/// With a policy of the candidate contract (the export fixture `candidates-smoke.onnx`, a
/// fixture, not a trained policy): herbd loads it through the same factory, gives it the rest
/// of the job, and decides every placement of the episode with it.
#[test]
fn packs_a_boxed_episode_with_a_candidate_policy() {
    pack_shortest_episode_with(
        "candidates",
        &repo().join("models/fixtures/candidates-smoke.onnx"),
    );
}

/// Packs the shortest BoxED episode with herbd placing by `policy`, and checks the job, the
/// loop's and the loopback's reports.
fn pack_shortest_episode_with(tag: &str, policy: &Path) {
    let Some(root) = herb_sim::paths::boxed_root_for_tests() else {
        return;
    };
    let (session, n) = shortest_session(&root);
    let (dir, prefix, cfg) = setup_with(tag, policy.to_str().unwrap());
    // The policy decides, not the default search.
    let mut text = std::fs::read_to_string(&cfg).unwrap();
    text.push_str("\n[decision]\nmethod = \"policy\"\n");
    std::fs::write(&cfg, text).unwrap();
    let claims = herb_testkit::claims::Claims::watch(&prefix);
    let cfg_s = cfg.to_str().unwrap();
    let boxed = root.to_str().unwrap();
    let mut lb = spawn(
        &loopback_exe(),
        &["--config", cfg_s, "--boxed", boxed],
        &dir.join("loopback.log"),
    );
    let mut hd = spawn(
        &exe("herbd"),
        &["--config", cfg_s, "--boxed", boxed],
        &dir.join("herbd.log"),
    );
    let picture = dir.join("pack.png");
    let mut ctl = spawn(
        &exe("herbctl"),
        &[
            "--prefix",
            &prefix,
            "--boxed",
            boxed,
            "pack",
            "--session",
            &session,
            "--json",
            "--timeout",
            "600",
            "--picture",
            picture.to_str().unwrap(),
        ],
        &dir.join("herbctl.log"),
    );
    let ctl_lines = lines(&mut ctl);
    let st = ctl.wait_for(Duration::from_secs(660));
    let summary = {
        let mut v = None;
        while let Ok(l) = ctl_lines.try_recv() {
            if let Ok(j) = serde_json::from_str::<serde_json::Value>(&l) {
                v = Some(j);
            }
        }
        v.expect("herbctl printed its JSON summary")
    };
    assert!(st.success(), "herbctl failed: {summary}");
    assert_eq!(summary["ok"], true, "{summary}");
    assert_eq!(
        summary["placed"], n as u64,
        "every placement made: {summary}"
    );
    assert_eq!(summary["decisions"], n as u64);
    assert!(summary["deadline_misses"].is_u64(), "{summary}");
    assert!(picture.exists(), "picture of the final pack");

    let (hd_lines, lb_lines) = (lines(&mut hd), lines(&mut lb));
    hd.signal(libc::SIGTERM);
    assert!(
        hd.wait_for(Duration::from_secs(10)).success(),
        "herbd exits 0 on SIGTERM"
    );
    let stats = last_json(&hd_lines, "herbd_final");
    assert!(stats["cycles"].as_u64().unwrap() > 1000, "{stats}");
    assert!(
        stats["deadline_misses"].is_u64(),
        "the loop reports its deadline misses: {stats}"
    );
    assert_eq!(stats["decision_us"]["n"], n as u64);
    let log = std::fs::read_to_string(dir.join("herbd.log")).unwrap();
    let file = policy.file_name().unwrap().to_string_lossy();
    assert!(log.contains(&*file), "herbd ran {file}:\n{log}");
    lb.signal(libc::SIGTERM);
    assert!(lb.wait_for(Duration::from_secs(10)).success());
    let sim = last_json(&lb_lines, "loopback_final");
    assert!(sim["commands"].as_u64().unwrap() > 1000, "{sim}");
    assert_eq!(
        sim["commands_rejected"], 0,
        "every command within limits: {sim}"
    );
    assert_eq!(sim["max_limit_excess_rad"], 0.0, "{sim}");
    assert_eq!(sim["releases"], n as u64, "{sim}");
    assert_eq!(sim["world_error"], serde_json::Value::Null);
    eprintln!("episode {session} ({n} objects): {summary}\nherbd: {stats}\nloopback: {sim}");
    claims.check();
}

/// With the search deciding in the job's twin (herbd's default method and twin, a short
/// budget, its rollouts on two threads): the episode is packed with every decision made while
/// the arm picks, the run log replays bit for bit (each search re-run with the rollouts its
/// budget allowed, the job's twin rebuilt from the recorded decisions and heightmaps), and
/// `herbd explain` lists the candidates the search tried and the threads they ran on.
#[test]
fn packs_an_episode_with_the_search_and_replays_it_bit_for_bit() {
    let Some(root) = herb_sim::paths::boxed_root_for_tests() else {
        return;
    };
    let (session, n) = shortest_session(&root);
    let (dir, prefix, cfg) = setup("search");
    let mut text = std::fs::read_to_string(&cfg).unwrap();
    // The rollouts on two threads: what the budget allowed replays alike whatever the timing.
    text.push_str("\n[decision]\nmethod = \"search\"\nbudget_s = 0.3\nk = 4\nthreads = 2\n");
    std::fs::write(&cfg, text).unwrap();
    let (cfg_s, boxed) = (cfg.to_str().unwrap(), root.to_str().unwrap());
    let runs = dir.join("runs");
    let _lb = spawn(
        &loopback_exe(),
        &["--config", cfg_s, "--boxed", boxed],
        &dir.join("loopback.log"),
    );
    let mut hd = spawn(
        &exe("herbd"),
        &[
            "--config",
            cfg_s,
            "--boxed",
            boxed,
            "--record",
            runs.to_str().unwrap(),
        ],
        &dir.join("herbd.log"),
    );
    let (st, out) = herbctl_output(
        &prefix,
        &[
            "--boxed",
            boxed,
            "pack",
            "--session",
            &session,
            "--json",
            "--timeout",
            "600",
        ],
    );
    let summary: serde_json::Value = out
        .lines()
        .rev()
        .find_map(|l| serde_json::from_str(l).ok())
        .unwrap_or_else(|| panic!("a JSON summary: {out}"));
    assert!(st.success(), "{summary}");
    assert_eq!(summary["ok"], true, "{summary}");
    assert_eq!(summary["placed"], n as u64, "{summary}");
    assert_eq!(summary["decisions"], n as u64, "{summary}");
    assert!(
        summary["decision_wait_s"].as_f64().unwrap() >= 0.0,
        "{summary}"
    );
    hd.signal(libc::SIGTERM);
    assert!(hd.wait_for(Duration::from_secs(10)).success());
    let mut logs: Vec<PathBuf> = std::fs::read_dir(&runs)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    logs.sort();
    let log = logs[0].to_str().unwrap();
    let (st, out) = herbd_output(&["--boxed", boxed, "replay", log]);
    assert!(st.success(), "{out}");
    assert!(out.contains("reproduced bit for bit"), "{out}");
    assert!(out.contains(&format!("{n} decisions")), "{out}");
    let pictures = dir.join("explain");
    let (st, out) = herbd_output(&[
        "--boxed",
        boxed,
        "explain",
        log,
        "--object",
        "1",
        "--out",
        pictures.to_str().unwrap(),
    ]);
    assert!(st.success(), "{out}");
    for want in [
        "method: search",
        "feasible candidates",
        "rollout",
        "on 2 threads",
        "placement",
    ] {
        assert!(out.contains(want), "{want}: {out}");
    }
}
