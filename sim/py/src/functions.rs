//! The module's functions: the box's half turn of feature rows, and the humans' demonstrations
//! of BoxED as lattice choices.

use super::*;

/// The box's half turn about z applied to candidate rows (`[..., CANDIDATE_LEN]`, float32):
/// a turned copy (see `herb_sim::features`).
#[pyfunction]
pub(crate) fn half_turn_candidates<'py>(
    py: Python<'py>,
    rows: PyReadonlyArrayDyn<'py, f32>,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    turned(py, rows, CANDIDATE_LEN, features::half_turn_candidates)
}

/// The box's half turn about z applied to context vectors (`[..., CONTEXT_LEN]`, float32): a
/// turned copy.
#[pyfunction]
pub(crate) fn half_turn_context<'py>(
    py: Python<'py>,
    contexts: PyReadonlyArrayDyn<'py, f32>,
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    turned(py, contexts, CONTEXT_LEN, features::half_turn_context)
}

pub(crate) fn turned<'py>(
    py: Python<'py>,
    a: PyReadonlyArrayDyn<'py, f32>,
    last: usize,
    f: fn(&mut [f32]),
) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let a = a.as_array();
    if a.shape().last() != Some(&last) {
        return Err(value_err(format!(
            "array of shape {:?}: the last axis must have {last} values",
            a.shape()
        )));
    }
    let mut out = a.as_standard_layout().into_owned();
    let data = out
        .as_slice_mut()
        .ok_or_else(|| value_err("array is not contiguous"))?;
    f(data);
    Ok(out.into_pyarray(py))
}

/// The humans' demonstrations, for the behaviour-cloning rows of Table I (BC-MSE, BC-MDN).
///
/// For each object of each BoxED session (`boxed`: the folder; default `HERB_BOXED` or
/// ../shared/boxed), in the human order: the observation of the humans' own scene just before
/// it (the earlier objects at their recorded poses, no physics: `herb_sim::eval::
/// recorded_heightmap`; the shared layout with the object's projection), average-pooled by
/// `pool` and stored as uint8 of `round(value * 255)`, and the human's planar placement as the
/// policy contract's action `(x / BOX_HALF_X, y / BOX_HALF_Y, theta / pi)`. Returns a dict:
/// `obs` `[N, 2, 224/pool, 224/pool]` uint8, `actions` `[N, 3]` float32, `episode` `[N]`
/// (index into `names`), `participant` `[N]` (the `p` number of the session), `names` (the
/// sessions used) and `skipped` (`[(session, reason)]`: sessions that do not load or hold a
/// missing or non-finite pose, left out whole).
#[pyfunction]
#[pyo3(signature = (boxed=None, pool=4))]
pub(crate) fn human_demonstrations<'py>(
    py: Python<'py>,
    boxed: Option<String>,
    pool: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let side = ObsLayout::SIZE;
    if pool == 0 || !side.is_multiple_of(pool) {
        return Err(value_err(format!("pool {pool}: must divide {side}")));
    }
    let root = paths::boxed_root(boxed.as_deref().map(Path::new))
        .ok_or_else(|| value_err("BoxED data not found: pass boxed= or set HERB_BOXED"))?;
    let catalog = Catalog::builtin(&paths::mesh_source(None, Some(&root))).map_err(value_err)?;
    let (sessions, bad) = herb_sim::boxed::load_all(&root, &catalog).map_err(value_err)?;
    let mut skipped: Vec<(String, String)> = bad
        .iter()
        .map(|e| match e {
            herb_sim::SimError::Session { session, message } => (session.clone(), message.clone()),
            other => (String::new(), other.to_string()),
        })
        .collect();
    let (m, ch) = (side / pool, ObsLayout::CHANNELS);
    let projections = herb_sim::observation::Projections::new(&catalog);
    let mut hm = herb_sim::Heightmap::new(ObsLayout::grid());
    let mut obs = vec![0.0f32; ObsLayout::LEN];
    let (mut pooled, mut actions, mut episode, mut participant, mut names) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for s in &sessions {
        let ep = s.episode(&catalog);
        let p_number = herb_sim::boxed::participant(&s.name).map_or(-1, |p| p as i32);
        let mut rows = Vec::new();
        let mut rows_actions = Vec::new();
        let made: Result<(), herb_sim::SimError> = (0..ep.objects.len()).try_for_each(|i| {
            herb_sim::eval::recorded_heightmap(&catalog, &ep, i, &mut hm)?;
            ObsLayout::write(&hm, Some(projections.get(ep.objects[i])), &mut obs)?;
            for c in 0..ch {
                for r in 0..m {
                    for q in 0..m {
                        let mut sum = 0.0f32;
                        for dr in 0..pool {
                            let row = &obs[c * side * side + (r * pool + dr) * side..];
                            sum += row[q * pool..q * pool + pool].iter().sum::<f32>();
                        }
                        let mean = sum / (pool * pool) as f32;
                        rows.push((mean * 255.0).round().clamp(0.0, 255.0) as u8);
                    }
                }
            }
            let h = &ep.human[i];
            rows_actions.extend(herb_sim::observation::placement_to_action(
                h.x, h.y, h.theta,
            ));
            Ok(())
        });
        if let Err(e) = made {
            skipped.push((s.name.clone(), e.to_string()));
            continue;
        }
        let k = names.len() as i32;
        episode.extend(std::iter::repeat_n(k, ep.objects.len()));
        participant.extend(std::iter::repeat_n(p_number, ep.objects.len()));
        pooled.extend(rows);
        actions.extend(rows_actions);
        names.push(s.name.clone());
    }
    let n = episode.len();
    let d = PyDict::new(py);
    let shape_err = |e: numpy::ndarray::ShapeError| PyRuntimeError::new_err(e.to_string());
    d.set_item(
        "obs",
        numpy::ndarray::Array4::from_shape_vec((n, ch, m, m), pooled)
            .map_err(shape_err)?
            .into_pyarray(py),
    )?;
    d.set_item(
        "actions",
        Array2::from_shape_vec((n, 3), actions)
            .map_err(shape_err)?
            .into_pyarray(py),
    )?;
    d.set_item("episode", Array1::from_vec(episode).into_pyarray(py))?;
    d.set_item(
        "participant",
        Array1::from_vec(participant).into_pyarray(py),
    )?;
    d.set_item("names", names)?;
    d.set_item("skipped", skipped)?;
    Ok(d)
}
