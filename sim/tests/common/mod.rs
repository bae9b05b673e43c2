//! Shared helpers for the integration tests.
#![allow(dead_code)]

use herb_sim::paths::{self, MeshSource};
use herb_sim::{Catalog, PackingWorld, SharedCatalog, WorldConfig};
use std::sync::{Arc, OnceLock};

/// The catalog with primitive shapes (no data needed).
pub fn primitives() -> SharedCatalog {
    static C: OnceLock<SharedCatalog> = OnceLock::new();
    C.get_or_init(|| {
        Arc::new(Catalog::builtin(&MeshSource::None("test".into())).expect("built-in catalog"))
    })
    .clone()
}

/// The catalog with mesh hulls, if the BoxED meshes are present (a loud failure under CI=true).
pub fn meshes() -> Option<SharedCatalog> {
    static C: OnceLock<Option<SharedCatalog>> = OnceLock::new();
    C.get_or_init(|| {
        let root = paths::boxed_root_for_tests()?;
        let m = MeshSource::Folder(root.join("meshes"));
        Some(Arc::new(Catalog::builtin(&m).expect("catalog with meshes")))
    })
    .clone()
}

/// A world with default settings.
pub fn world(c: &SharedCatalog) -> PackingWorld {
    PackingWorld::new(c.clone(), WorldConfig::default()).expect("world")
}

/// **Fixture**: a world with the objects `ids` placed in turn at fixed, scattered positions.
pub fn pile(c: &SharedCatalog, ids: &[&str]) -> PackingWorld {
    let mut w = world(c);
    for (i, id) in ids.iter().enumerate() {
        let f = i as f32;
        w.place(
            c.by_id(id).expect("catalog id"),
            0.1 * (f * 1.7).sin(),
            0.06 * (f * 2.3).cos(),
            0.4 * f,
        )
        .expect("place");
    }
    w
}
