//! The BoxED human sessions: object lists, human order and placements, in the box frame B.
//!
//! Reads `<root>/sessions/<name>/PickPlace_dataset.json` (formats in `../shared/boxed/README.md`).
//! Each record becomes a [`PlacementRecord`] with the object's mesh-frame pose converted to B by
//! [`crate::frames::unity_place_to_box`]. An [`Episode`] is what the evaluation runs: the
//! placed instances in the order of their **first** placement, and for each the human's planar
//! placement `(x, y, theta)` of the object's canonical origin, taken from that first record
//! (what the human did at that step; 84 later re-grasp records move an already placed object
//! and are kept in the session but not replayed), plus its tilt from upright.
//!
//! Counts: 263 sessions, 4660 records, 4576 placed instances (tested). The HERB and BoxED
//! papers state 4644 placements. The difference is the 16 re-grasps that move an already placed
//! object by less than 2 cm: of the 84 re-grasps, those 16 move its pivot 5.3 to 14.2 mm, and
//! the next smallest moves it 20.6 mm, so a count that takes short re-grasps as adjustments of the
//! same placement, not new placements, gives exactly 4660 - 16 = 4644
//! ([`Session::regrasp_moves`], [`ADJUSTMENT_MAX_M`]; tested). The papers do not state this
//! rule; it is the one we found that reproduces their figure from the data's structure (no
//! record is malformed or repeats a pose; consecutive repeats of one id number 61 and
//! records whose pivot lies outside the normalised box 131, neither giving 16). We replay
//! first placements only and keep all 4660 records.

use crate::catalog::{Catalog, TypeIdx};
use crate::error::{Result, SimError};
use crate::frames::{MeshPoseB, tilt_of, unity_place_to_box, yaw_of};
use parry3d::math::{Rotation, Vector};
use serde::Deserialize;
use std::path::Path;

/// One `PickPlace_dataset.json` record in B.
#[derive(Debug, Clone, PartialEq)]
pub struct PlacementRecord {
    /// The instance id as stored (`"004 sugar box(Clone)-8620"`).
    pub instance: String,
    /// Its object type.
    pub ty: TypeIdx,
    /// Pose of the object's mesh-file frame in B.
    pub pose: MeshPoseB,
}

/// A human placement reduced to the planar action space.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HumanPlacement {
    /// B x of the canonical origin (m).
    pub x: f32,
    /// B y of the canonical origin (m).
    pub y: f32,
    /// B z of the canonical origin as recorded (m).
    pub z: f32,
    /// Turn about z of the canonical frame (rad).
    pub theta: f32,
    /// The human's tilt from upright (rad): how far from planar this placement was.
    pub tilt_rad: f32,
    /// The human's full orientation of the canonical frame in B.
    pub rotation: Rotation,
}

/// One BoxED session.
#[derive(Debug, Clone)]
pub struct Session {
    /// Folder name, e.g. `p12_s3`.
    pub name: String,
    /// Every record, in the stored order.
    pub records: Vec<PlacementRecord>,
}

/// Re-grasps that move an object by less than this (m) are adjustments of its placement: with
/// this threshold the data gives the papers' 4644 placements (see the module docs).
pub const ADJUSTMENT_MAX_M: f32 = 0.02;

impl Session {
    /// For each re-grasp (a record of an instance placed before), the index of the record and
    /// how far it moved the object's pivot from its previous placement (m).
    pub fn regrasp_moves(&self) -> Vec<(usize, f32)> {
        let mut out = Vec::new();
        for (k, r) in self.records.iter().enumerate() {
            if let Some(prev) = self.records[..k]
                .iter()
                .rev()
                .find(|p| p.instance == r.instance)
            {
                out.push((k, prev.pose.translation.distance(r.pose.translation)));
            }
        }
        out
    }

    /// Placements counted as the papers count them: records minus the re-grasps that move the
    /// object by less than [`ADJUSTMENT_MAX_M`].
    pub fn paper_placement_count(&self) -> usize {
        self.records.len()
            - self
                .regrasp_moves()
                .iter()
                .filter(|(_, d)| *d < ADJUSTMENT_MAX_M)
                .count()
    }
}

/// An evaluation episode derived from a session.
#[derive(Debug, Clone, PartialEq)]
pub struct Episode {
    /// Session name.
    pub name: String,
    /// Object types in the human order (first placement of each instance).
    pub objects: Vec<TypeIdx>,
    /// The human's placement of each object, same order.
    pub human: Vec<HumanPlacement>,
}

#[derive(Deserialize)]
struct RawRecord {
    id: String,
    #[serde(rename = "placeRotation")]
    place_rotation: [[f32; 3]; 3],
    #[serde(rename = "placeTranslation")]
    place_translation: [f32; 3],
}

/// The participant number of a session folder name (`p12_s3` -> 12), `None` if the name is
/// not of that form. The BC rows of Table I hold participants out by its parity.
pub fn participant(session: &str) -> Option<u32> {
    session.strip_prefix('p')?.split('_').next()?.parse().ok()
}

/// Session folder names under `<root>/sessions`, in natural order (p2 before p10).
pub fn list_sessions(root: &Path) -> Result<Vec<String>> {
    let dir = root.join("sessions");
    let rd = std::fs::read_dir(&dir).map_err(|source| SimError::Io {
        path: dir.clone(),
        source,
    })?;
    let mut names: Vec<String> = rd
        .filter_map(|e| e.ok())
        .filter(|e| e.path().is_dir())
        .filter_map(|e| e.file_name().into_string().ok())
        .collect();
    names.sort_by_key(|n| natural_key(n));
    Ok(names)
}

fn natural_key(name: &str) -> Vec<(u64, String)> {
    // Split into digit runs and text runs: "p10_s2" -> [(0,"p"),(10,""),(0,"_s"),(2,"")].
    let mut out = Vec::new();
    let mut chars = name.chars().peekable();
    while let Some(&c) = chars.peek() {
        if c.is_ascii_digit() {
            let mut n = 0u64;
            while let Some(&d) = chars.peek().filter(|d| d.is_ascii_digit()) {
                n = n.saturating_mul(10).saturating_add(d as u64 - '0' as u64);
                chars.next();
            }
            out.push((n, String::new()));
        } else {
            let mut s = String::new();
            while let Some(&d) = chars.peek().filter(|d| !d.is_ascii_digit()) {
                s.push(d);
                chars.next();
            }
            out.push((u64::MAX, s));
        }
    }
    out
}

/// Loads one session; the error names the session and what is wrong.
pub fn load_session(root: &Path, name: &str, catalog: &Catalog) -> Result<Session> {
    let err = |message: String| SimError::Session {
        session: name.to_owned(),
        message,
    };
    let path = root
        .join("sessions")
        .join(name)
        .join("PickPlace_dataset.json");
    let text = std::fs::read_to_string(&path)
        .map_err(|e| err(format!("cannot read {}: {e}", path.display())))?;
    let raw: Vec<RawRecord> = serde_json::from_str(&text)
        .map_err(|e| err(format!("{} is malformed: {e}", path.display())))?;
    if raw.is_empty() {
        return Err(err("no placement records".into()));
    }
    let mut records = Vec::with_capacity(raw.len());
    for (i, r) in raw.into_iter().enumerate() {
        let type_name = r.id.split("(Clone)").next().unwrap_or("").trim_end();
        let ty = catalog.by_dataset_type(type_name).map_err(|_| {
            err(format!(
                "record {i}: unknown object type {type_name:?} in id {:?}",
                r.id
            ))
        })?;
        let pose = unity_place_to_box(r.place_rotation, r.place_translation).ok_or_else(|| {
            err(format!(
                "record {i} ({}): not a finite proper rotation/translation",
                r.id
            ))
        })?;
        records.push(PlacementRecord {
            instance: r.id,
            ty,
            pose,
        });
    }
    Ok(Session {
        name: name.to_owned(),
        records,
    })
}

impl Session {
    /// The evaluation episode: instances in first-placement order with their human placements.
    pub fn episode(&self, catalog: &Catalog) -> Episode {
        let mut seen: Vec<&str> = Vec::new();
        let mut objects = Vec::new();
        let mut human = Vec::new();
        for r in &self.records {
            if seen.contains(&r.instance.as_str()) {
                continue;
            }
            seen.push(&r.instance);
            objects.push(r.ty);
            human.push(human_placement(catalog, r));
        }
        Episode {
            name: self.name.clone(),
            objects,
            human,
        }
    }
}

/// The body pose of a record's object in its canonical frame, reduced to `(x, y, theta)` and tilt.
///
/// With `v_c = R_c (s v - o)`, the canonical body pose is `R = R_B R_c^-1`, `t = p_B + R_B o`.
pub fn human_placement(catalog: &Catalog, r: &PlacementRecord) -> HumanPlacement {
    let spec = catalog.spec(r.ty);
    let rc: Rotation = spec.canonical_rotation();
    let rot = r.pose.rotation * rc.inverse();
    let t = r.pose.translation + r.pose.rotation * Vector::from_array(spec.origin_mesh_m);
    HumanPlacement {
        x: t.x,
        y: t.y,
        z: t.z,
        theta: yaw_of(rot),
        tilt_rad: tilt_of(rot),
        rotation: rot,
    }
}

/// Loads every session under `root`: the good ones, and each bad one with its error.
pub fn load_all(root: &Path, catalog: &Catalog) -> Result<(Vec<Session>, Vec<SimError>)> {
    let mut ok = Vec::new();
    let mut bad = Vec::new();
    for name in list_sessions(root)? {
        match load_session(root, &name, catalog) {
            Ok(s) => ok.push(s),
            Err(e) => bad.push(e),
        }
    }
    Ok((ok, bad))
}

#[cfg(test)]
mod tests {
    use super::natural_key;

    #[test]
    fn participant_numbers() {
        assert_eq!(super::participant("p12_s3"), Some(12));
        assert_eq!(super::participant("p1_s1"), Some(1));
        assert_eq!(super::participant("q1_s1"), None);
        assert_eq!(super::participant("p_s1"), None);
    }

    #[test]
    fn natural_order() {
        let mut v = vec!["p10_s1", "p2_s10", "p2_s2", "p1_s1"];
        v.sort_by_key(|n| natural_key(n));
        assert_eq!(v, ["p1_s1", "p2_s2", "p2_s10", "p10_s1"]);
    }
}
