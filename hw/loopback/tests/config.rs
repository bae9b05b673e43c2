//! The loopback and herbd read one configuration file: the shipped example and a test file give
//! both the same prefix, cell and limits, and the loopback refuses what herbd refuses in those
//! tables.

use herb_daemon::config::Config;
use herb_loopback::config::{ConfigFile, LoopbackConfig};
use std::path::Path;

#[test]
fn both_processes_read_the_same_cell_limits_and_prefix() {
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../systemd/herbd.toml");
    let text = std::fs::read_to_string(&shipped).unwrap();
    let custom = text.replace(
        "ipc_prefix = ",
        "ipc_prefix = \"other\"\n# was: ipc_prefix = ",
    );
    for t in [text.as_str(), custom.as_str(), ""] {
        let d = Config::from_toml(t, "test").unwrap();
        let l = LoopbackConfig::from_toml(t, "test").unwrap();
        assert_eq!(l.ipc_prefix, d.ipc_prefix);
        assert_eq!(l.cell, d.cell);
        assert_eq!(l.limits, d.limits);
        assert_eq!(l.models.boxed, d.models.boxed);
    }
}

#[test]
fn bad_cell_or_limits_are_refused_by_both() {
    for (bad, says) in [
        ("[cell]\ngrasp_depth = 0.5\n", "grasp_depth"),
        ("[cell]\nbox_yaw = nan\n", "finite"),
        ("[cell]\nunknown = 1\n", "unknown"),
        ("ipc_prefix = \"\"\n", "prefix"),
        (
            "[limits]\nlower = [0,0,0,0,0,0,0]\nupper = [0,0,0,0,0,0,0]\nvelocity = [1,1,1,1,1,1,1]\nacceleration = [1,1,1,1,1,1,1]\njerk = [1,1,1,1,1,1,1]\n",
            "limits",
        ),
    ] {
        let d = Config::from_toml(bad, "test").unwrap_err();
        let l = LoopbackConfig::from_toml(bad, "test").unwrap_err();
        assert!(l.to_string().contains(says), "{bad}: {l}");
        assert!(!d.to_string().is_empty());
    }
}
