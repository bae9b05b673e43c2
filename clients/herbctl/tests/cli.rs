//! herbctl as a user runs it, without herbd: bad input gets a clear error and exit 2 (never a
//! panic), and `catalog` prints the catalog. Having a test here also makes `cargo test
//! --workspace` build herbctl's binary, which the end-to-end tests of other packages run.

use std::process::Command;

fn herbctl(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_herbctl"))
        .args(args)
        // No BoxED folder here: the catalog's primitive shapes.
        .current_dir(std::env::temp_dir())
        .output()
        .expect("herbctl runs")
}

#[test]
fn bad_input_is_refused_by_name_before_herbd_is_asked() {
    for (args, named) in [
        (&["pack", "--objects", "003,9x9"][..], "9x9"),
        (
            &["pack", "--objects", "003", "--timeout", "-1"][..],
            "--timeout",
        ),
        (
            &["pack", "--objects", "003", "--reconnect", "nan"][..],
            "--reconnect",
        ),
    ] {
        let o = herbctl(args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(
            err.contains("herbctl: error:") && err.contains(named),
            "{args:?}: {err}"
        );
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
}

#[test]
fn catalog_prints_the_box_and_every_object_as_one_json_document() {
    let o = herbctl(&["catalog"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON document");
    assert_eq!(doc["format"], 1);
    let height = doc["box"]["height"].as_f64().unwrap();
    assert!((height - f64::from(herb_core::frames::BOX_HEIGHT)).abs() < 1e-6);
    let objects = doc["objects"].as_array().unwrap();
    assert!(!objects.is_empty());
    assert!(objects.iter().all(|ob| {
        ob["vertices"].as_array().is_some_and(|v| v.len() >= 4)
            && ob["id"].as_str().is_some_and(|s| !s.is_empty())
    }));
}
