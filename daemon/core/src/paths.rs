//! Where the BoxED data and meshes are read from. The data is never copied into the repository.
//!
//! Resolution order for the BoxED root: an explicit path (CLI flag), the `HERB_BOXED`
//! environment variable, `../shared/boxed` relative to the working directory,
//! `../shared/boxed` relative to the workspace root (so tests find it from any crate folder),
//! then [`INSTALLED_BOXED`] (where `systemd/install.sh --boxed` puts it on a robot PC).
//! Meshes: an explicit folder, `HERB_MESHES`, `<boxed root>/meshes` if it exists, else none
//! (objects fall back to primitives).

use std::path::{Path, PathBuf};

/// Environment variable naming the BoxED root folder.
pub const ENV_BOXED: &str = "HERB_BOXED";
/// Environment variable naming the mesh folder (or `none` to force primitives).
pub const ENV_MESHES: &str = "HERB_MESHES";

/// Where object shapes come from.
#[derive(Debug, Clone, PartialEq)]
pub enum MeshSource {
    /// Convex hulls of the meshes in this folder.
    Folder(PathBuf),
    /// Primitives, with the reason no mesh folder is used.
    None(String),
}

/// Where `systemd/install.sh --boxed DIR` installs the BoxED sessions and meshes.
pub const INSTALLED_BOXED: &str = "/opt/herb/boxed";

fn workspace_default() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/boxed")
}

/// The BoxED root: explicit, else `HERB_BOXED`, else the defaults; `None` if none exists.
pub fn boxed_root(explicit: Option<&Path>) -> Option<PathBuf> {
    if let Some(p) = explicit {
        return Some(p.to_owned());
    }
    if let Some(p) = std::env::var_os(ENV_BOXED) {
        return Some(PathBuf::from(p));
    }
    [
        PathBuf::from("../shared/boxed"),
        workspace_default(),
        PathBuf::from(INSTALLED_BOXED),
    ]
    .into_iter()
    .find(|p| p.is_dir())
}

/// The mesh source: explicit folder, else `HERB_MESHES` (`none` forces primitives), else
/// `<boxed root>/meshes` when it exists, else primitives.
pub fn mesh_source(explicit: Option<&Path>, boxed: Option<&Path>) -> MeshSource {
    if let Some(p) = explicit {
        return MeshSource::Folder(p.to_owned());
    }
    if let Some(p) = std::env::var_os(ENV_MESHES) {
        if p == "none" {
            return MeshSource::None(format!("{ENV_MESHES}=none"));
        }
        return MeshSource::Folder(PathBuf::from(p));
    }
    match boxed.map(|b| b.join("meshes")) {
        Some(m) if m.is_dir() => MeshSource::Folder(m),
        Some(m) => MeshSource::None(format!("no mesh folder at {}", m.display())),
        None => MeshSource::None("no BoxED folder found".into()),
    }
}

/// For tests that need the BoxED data: the root if present; if absent, `None` outside CI and a
/// panic (a loud test failure) when `CI=true`, where the data must be present.
pub fn boxed_root_for_tests() -> Option<PathBuf> {
    let root = boxed_root(None).filter(|p| p.join("sessions").is_dir());
    if root.is_none() && std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!(
            "CI=true but the BoxED data was not found (set {ENV_BOXED} or place it at ../shared/boxed)"
        );
    }
    if root.is_none() {
        eprintln!("BoxED data not found: skipping this data test (it fails under CI=true)");
    }
    root
}
