//! The run's identity, written in every segment's header: this machine's CPU, the catalog's
//! digest, and the header of a run of a configuration.

use super::RecordError;
use super::format::RunHeader;
use crate::digest::Fnv;
use std::path::Path;

/// This machine's CPU: model name and a digest of its flags (tract picks kernels by them).
pub fn cpu_identity() -> String {
    let info = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let field = |name: &str| {
        info.lines()
            .find(|l| l.starts_with(name))
            .and_then(|l| l.split(':').nth(1))
            .map(|v| v.trim().to_string())
            .unwrap_or_default()
    };
    format!(
        "{}; flags {:016x}",
        field("model name"),
        crate::digest::of(field("flags").as_bytes())
    )
}

/// The digest of a catalog: every type's id and the extents of its shape.
pub fn catalog_digest(c: &herb_core::Catalog) -> u64 {
    let mut h = Fnv::new();
    for i in 0..c.len() {
        let t = herb_core::TypeIdx(i as u16);
        h.bytes(c.spec(t).id.as_bytes());
        let e = c.shape(t).extents();
        for v in [e.x, e.y, e.z] {
            h.u64(v.to_bits() as u64);
        }
    }
    h.finish()
}

/// The header of a run of `cfg` with `catalog`: the configuration with its model paths and the
/// BoxED folder made absolute (a replay from another folder finds them) and without a run log
/// of its own, and the digests of what it loads.
pub fn header_for(
    cfg: &crate::config::Config,
    catalog: &herb_core::Catalog,
) -> Result<RunHeader, RecordError> {
    use herb_decide::PolicySpec;
    let model = |p: &Path, source| RecordError::Model {
        path: p.to_path_buf(),
        source,
    };
    let abs = |p: &Path| std::fs::canonicalize(p).map_err(|e| model(p, e));
    let file = |p: &Path| {
        std::fs::read(p)
            .map(|b| crate::digest::of(&b))
            .map_err(|e| model(p, e))
    };
    let mut c = cfg.clone();
    c.record.dir = None;
    // The search's threads as they ran (0 says "the cores left", which differ by machine).
    c.decision.threads = cfg.decision.search_threads();
    c.models.sequence = abs(&cfg.models.sequence)?;
    let policy = match cfg.models.policy_file() {
        None => 0,
        Some(p) => {
            c.models.policy = PolicySpec::Onnx(abs(&p)?);
            file(&p)?
        }
    };
    c.models.boxed = herb_core::paths::boxed_root(cfg.models.boxed.as_deref())
        .map(|p| std::fs::canonicalize(&p).unwrap_or(p));
    let started_unix_s = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    Ok(RunHeader {
        herbd: format!(
            "herbd {} ({})",
            env!("CARGO_PKG_VERSION"),
            if cfg!(debug_assertions) {
                "debug"
            } else {
                "release"
            }
        ),
        cpu: cpu_identity(),
        started_unix_s,
        config_toml: toml::to_string(&c)?,
        catalog: catalog_digest(catalog),
        policy,
        sequence: file(&cfg.models.sequence)?,
        segment: 0,
    })
}
