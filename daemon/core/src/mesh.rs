//! Mesh loading (OBJ through `tobj`).

use crate::error::{Result, SimError};
use parry3d::math::Vector;
use std::path::Path;

/// All vertex positions of an OBJ file (every object and group), in file units.
pub fn load_obj_vertices(path: &Path) -> Result<Vec<Vector>> {
    let err = |message: String| SimError::Mesh {
        path: path.to_owned(),
        message,
    };
    if !path.is_file() {
        return Err(err("file not found".into()));
    }
    let opts = tobj::LoadOptions {
        single_index: false,
        triangulate: false,
        ..Default::default()
    };
    let (models, _materials) =
        tobj::load_obj(path, &opts).map_err(|e| err(format!("does not parse: {e}")))?;
    let mut out = Vec::new();
    for m in &models {
        for p in m.mesh.positions.chunks_exact(3) {
            let v = Vector::new(p[0], p[1], p[2]);
            if !v.is_finite() {
                return Err(err(format!("non-finite vertex {v:?}")));
            }
            out.push(v);
        }
    }
    if out.len() < 4 {
        return Err(err(format!(
            "{} vertices; a solid needs at least 4",
            out.len()
        )));
    }
    Ok(out)
}
