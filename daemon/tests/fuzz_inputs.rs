//! Fuzzed input files (proptest): herbd's TOML configuration, the object catalog, the sequence
//! model and ONNX policies, each read from the shipped file with a few arbitrary byte edits
//! (overwritten, inserted, deleted; cut short) and from arbitrary bytes. Nothing may panic: a
//! bad file is an error naming what was wrong, and a file that loads passes its own checks.
//!
//! Budget: `PROPTEST_CASES` cases per property (256 by default, what CI runs; the ONNX
//! property runs a quarter of them, each case builds a model); `scripts/fuzz.sh` runs them with
//! a larger budget.

use herb_core::Catalog;
use herb_core::paths::MeshSource;
use herb_daemon::config::{Config, ConfigFile};
use herb_decide::{PolicySpec, SequenceModel, load_policy};
use proptest::prelude::*;
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn shipped(rel: &str) -> Vec<u8> {
    std::fs::read(repo().join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// An edit of a file: overwrite, insert or delete one byte at a position (modulo the length).
#[derive(Debug, Clone)]
enum Edit {
    Set(usize, u8),
    Insert(usize, u8),
    Delete(usize),
}

/// `base` with up to 8 edits, then possibly cut short; or arbitrary bytes.
fn mutated(base: Vec<u8>) -> impl Strategy<Value = Vec<u8>> {
    let edit = prop_oneof![
        (any::<usize>(), any::<u8>()).prop_map(|(i, b)| Edit::Set(i, b)),
        (any::<usize>(), any::<u8>()).prop_map(|(i, b)| Edit::Insert(i, b)),
        any::<usize>().prop_map(Edit::Delete),
    ];
    prop_oneof![
        4 => (proptest::collection::vec(edit, 1..8), proptest::option::of(any::<usize>())).prop_map(
            move |(edits, cut)| {
                let mut b = base.clone();
                for e in edits {
                    let n = b.len().max(1);
                    match e {
                        Edit::Set(i, v) if !b.is_empty() => b[i % n] = v,
                        Edit::Insert(i, v) => b.insert(i % (b.len() + 1), v),
                        Edit::Delete(i) if !b.is_empty() => {
                            b.remove(i % n);
                        }
                        _ => {}
                    }
                }
                if let Some(c) = cut {
                    b.truncate(c % (b.len() + 1));
                }
                b
            }
        ),
        1 => proptest::collection::vec(any::<u8>(), 0..512),
    ]
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// The catalog (primitives), built once for every case.
fn catalog() -> &'static Catalog {
    static CATALOG: std::sync::OnceLock<Catalog> = std::sync::OnceLock::new();
    CATALOG.get_or_init(|| Catalog::builtin(&MeshSource::None("fuzz: primitives".into())).unwrap())
}

proptest! {
    #[test]
    fn herbd_config(b in mutated(shipped("systemd/herbd.toml"))) {
        if let Ok(c) = Config::from_toml(&text(&b), "fuzzed herbd.toml") {
            prop_assert!(c.validate().is_ok());
        }
    }

    #[test]
    fn object_catalog(b in mutated(shipped("models/objects.toml"))) {
        let none = MeshSource::None("fuzz: primitives".into());
        if let Ok(c) = Catalog::from_toml(&text(&b), "fuzzed objects.toml", &none) {
            prop_assert!(!c.is_empty());
        }
    }

    #[test]
    fn sequence_model(b in mutated(shipped("models/sequence.json"))) {
        let _ = SequenceModel::from_json(&text(&b), "fuzzed sequence.json", catalog());
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(
        (ProptestConfig::default().cases / 4).max(1)
    ))]

    #[test]
    fn onnx_policy(
        b in prop_oneof![
            mutated(shipped("models/fixtures/tiny_policy.onnx")),
            mutated(shipped("models/fixtures/bad_input_shape.onnx")),
        ],
        tag in any::<u64>(),
    ) {
        let path = std::env::temp_dir().join(format!("herb-fuzz-{}-{tag}.onnx", std::process::id()));
        std::fs::write(&path, &b).unwrap();
        let r = load_policy(&PolicySpec::Onnx(path.clone()), catalog());
        let _ = std::fs::remove_file(&path);
        if let Err(e) = r {
            // The error names the file.
            prop_assert!(e.to_string().contains("herb-fuzz-"), "{e}");
        }
    }
}
