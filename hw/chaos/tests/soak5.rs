//! The chaos soak's five-minute version (CI; the hour-long one is `scripts/chaos.sh`): herbd
//! with its defaults, the loopback and a client packing random BoxED episodes, a fault from the
//! whole list every 15 to 25 s, and no invariant broken, every fault recovered without a person.

use std::process::Command;

#[test]
fn five_minutes_of_faults_break_no_invariant() {
    if herb_core::paths::boxed_root_for_tests().is_none() {
        eprintln!("skipped: no BoxED data (CI=true makes this a failure)");
        return;
    }
    let herbd = herb_testkit::exe("herbd", "herb-daemon");
    herb_testkit::exe("herbctl", "herbctl");
    herb_testkit::exe("herb-loopback", "herb-loopback");
    let bin = herbd.parent().expect("the binaries' folder");
    let out = herb_testkit::tmp("chaos5");
    let o = Command::new(env!("CARGO_BIN_EXE_herb-chaos"))
        .args([
            "--minutes",
            "5",
            "--every-min-s",
            "15",
            "--every-max-s",
            "25",
        ])
        .args(["--recover-s", "120", "--seed", "5"])
        .arg("--bin")
        .arg(bin)
        .arg("--out")
        .arg(&out)
        .current_dir(herb_testkit::repo())
        .output()
        .expect("herb-chaos runs");
    let said = String::from_utf8_lossy(&o.stdout).to_string() + &String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{said}\n(logs in {})", out.display());
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["violations"], serde_json::json!([]), "{said}");
    let faults = report["faults"].as_array().expect("faults");
    assert!(
        faults.len() >= 6,
        "only {} faults injected: {said}",
        faults.len()
    );
    assert!(
        report["invariants"]["commands_compared_with_the_arm"]
            .as_u64()
            .unwrap_or(0)
            > 10_000,
        "{said}"
    );
    assert!(report["objects_placed"].as_u64().unwrap_or(0) > 0, "{said}");
}
