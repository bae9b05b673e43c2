//! The object catalog (`models/objects.toml`) and each object's collision shape.
//!
//! Every object has a **canonical frame**: upright (its resting "up" axis along +z), turned
//! about z so its footprint's bounding rectangle is smallest with the long side along x, and
//! its origin at the centre of its axis-aligned bounding box. A placement `(x, y, theta)` puts
//! that origin at `(x, y)` and turns the canonical frame by `theta` about z.
//!
//! The map from mesh-file coordinates to the canonical frame is
//! `v_c = R_c (s v_mesh - o)` with `R_c = Rz(yaw) * shortest_arc(up_mesh -> z)`, where `s`,
//! `up_mesh`, `yaw` and `o` are catalog fields (fitted once from the meshes by
//! `herb-sim catalog --fit`), so primitives and mesh hulls share one frame.
//!
//! Shapes are convex polyhedra either way: the convex hull of the mesh (reduced to its support
//! points in a fixed set of directions, for speed) when a mesh folder is configured, or the hull
//! of a primitive (cuboid, elliptic cylinder, ellipsoid, capsule) with the real dimensions.

use crate::error::{Result, SimError};
use crate::hull::{HullError, hull_volume, quad_faced_hull, sphere_directions};
use crate::paths::MeshSource;
use parry3d::mass_properties::MassProperties;
use parry3d::math::{Rotation, Vector};
use parry3d::shape::SharedShape;
use serde::Deserialize;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The catalog shipped with the repository, compiled in so binaries run from anywhere.
pub const BUILTIN_CATALOG: &str = include_str!("../../../models/objects.toml");

/// Index of an object type in the catalog (dense, 0-based, in file order).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TypeIdx(pub u16);

/// Primitive approximation used when no mesh is available.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Primitive {
    /// A box with the canonical extents.
    Cuboid,
    /// An (elliptic) cylinder with axis z: diameters `dims.x`, `dims.y`, height `dims.z`.
    Cylinder,
    /// An ellipsoid with diameters `dims`.
    Ellipsoid,
    /// A capsule along x: length `dims.x`, diameter `dims.y` (`dims.z` should equal `dims.y`).
    Capsule,
}

/// One object type as written in `models/objects.toml`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectSpec {
    /// BoxED id, e.g. `"002"`.
    pub id: String,
    /// Human-readable name.
    pub name: String,
    /// Type name as it appears in BoxED `PickPlace_dataset.json` ids (before `(Clone)`).
    pub dataset_type: String,
    /// Mass (kg).
    pub mass_kg: f32,
    /// Where the mass comes from (e.g. the YCB table, or "estimated").
    pub mass_source: String,
    /// Real extents in the canonical frame (m): footprint long side x, short side y, height z.
    pub dims_m: [f32; 3],
    /// Primitive approximation used without a mesh.
    pub primitive: Primitive,
    /// Mesh file name inside the mesh folder, if the object has one.
    #[serde(default)]
    pub mesh: Option<String>,
    /// Scale applied to mesh-file coordinates (`scale_in_dataset`).
    pub mesh_scale: f32,
    /// The mesh-file axis that points up when the object rests canonically.
    pub up_mesh: [f32; 3],
    /// Turn about z after aligning `up_mesh` with z (rad).
    pub yaw_rad: f32,
    /// Canonical origin in scaled mesh-file coordinates (m).
    pub origin_mesh_m: [f32; 3],
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CatalogFile {
    format: u32,
    object: Vec<ObjectSpec>,
}

/// Where an object's collision shape came from.
#[derive(Debug, Clone, PartialEq)]
pub enum ShapeSource {
    /// Convex hull of this mesh file.
    Mesh(PathBuf),
    /// The primitive, and why no mesh was used.
    Primitive(String),
}

/// A convex collision shape in the canonical frame, with what rendering and metrics need.
#[derive(Debug, Clone)]
pub struct ObjectShape {
    /// Hull vertices in the canonical frame (m).
    pub vertices: Vec<Vector>,
    /// Hull triangles (outward, counter-clockwise), indices into `vertices`.
    pub triangles: Vec<[u32; 3]>,
    /// Volume of the hull (m^3).
    pub volume: f32,
    /// Axis-aligned bounds of the hull in the canonical frame: min corner.
    pub aabb_min: Vector,
    /// Axis-aligned bounds of the hull in the canonical frame: max corner.
    pub aabb_max: Vector,
    /// The rapier/parry collision shape (shared, cheap to clone).
    pub collider: SharedShape,
    /// The collision shape's mass properties at a density of 1 kg/m^3, computed once (a
    /// world scales them to the object's mass for every body it inserts).
    pub unit_mass: MassProperties,
    /// Where it came from.
    pub source: ShapeSource,
}

/// The loaded catalog: specs plus one shape per object type.
#[derive(Debug, Clone)]
pub struct Catalog {
    specs: Vec<ObjectSpec>,
    shapes: Vec<ObjectShape>,
}

impl ObjectSpec {
    /// Rotation from scaled mesh-file coordinates to the canonical frame.
    pub fn canonical_rotation(&self) -> Rotation {
        let up = Vector::from_array(self.up_mesh).normalize();
        Rotation::from_rotation_z(self.yaw_rad) * Rotation::from_rotation_arc(up, Vector::Z)
    }

    /// Maps a mesh-file vertex to the canonical frame.
    pub fn mesh_to_canonical(&self, v_mesh: Vector) -> Vector {
        self.canonical_rotation()
            * (self.mesh_scale * v_mesh - Vector::from_array(self.origin_mesh_m))
    }
}

impl Catalog {
    /// Type `t`'s catalog id and name for people (`003 cracker box`), `-` for a code that names
    /// no type (e.g. `NO_OBJECT` in a status).
    pub fn label(&self, t: u32) -> String {
        if (t as usize) < self.len() {
            let s = self.spec(TypeIdx(t as u16));
            format!("{} {}", s.id, s.name)
        } else {
            "-".into()
        }
    }

    /// Loads the built-in catalog with shapes from `meshes`.
    pub fn builtin(meshes: &MeshSource) -> Result<Self> {
        Self::from_toml(BUILTIN_CATALOG, "built-in models/objects.toml", meshes)
    }

    /// Loads a catalog file with shapes from `meshes`.
    pub fn load(path: &Path, meshes: &MeshSource) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|source| SimError::Io {
            path: path.to_owned(),
            source,
        })?;
        Self::from_toml(&text, &path.display().to_string(), meshes)
    }

    /// Parses and validates catalog text, then builds every shape.
    pub fn from_toml(text: &str, origin: &str, meshes: &MeshSource) -> Result<Self> {
        let err = |message: String| SimError::Catalog {
            origin: origin.to_owned(),
            message,
        };
        let file: CatalogFile = toml::from_str(text).map_err(|e| err(e.to_string()))?;
        if file.format != 1 {
            return Err(err(format!(
                "format {} is not supported (expected 1)",
                file.format
            )));
        }
        if file.object.is_empty() || file.object.len() > u16::MAX as usize {
            return Err(err(format!(
                "{} objects; expected 1..=65535",
                file.object.len()
            )));
        }
        for (i, s) in file.object.iter().enumerate() {
            let name = format!("object {} ({:?})", i, s.id);
            if file.object[..i].iter().any(|o| o.id == s.id) {
                return Err(err(format!("{name}: duplicate id")));
            }
            let finite = s
                .dims_m
                .iter()
                .chain(&s.up_mesh)
                .chain(&s.origin_mesh_m)
                .all(|v| v.is_finite())
                && s.yaw_rad.is_finite();
            if !finite {
                return Err(err(format!("{name}: non-finite number")));
            }
            if s.dims_m.iter().any(|&d| !(0.001..=1.0).contains(&d)) {
                return Err(err(format!(
                    "{name}: 'dims_m' {:?} outside 1 mm..1 m",
                    s.dims_m
                )));
            }
            if !(s.mass_kg > 0.0 && s.mass_kg < 50.0) {
                return Err(err(format!(
                    "{name}: 'mass_kg' {} outside (0, 50)",
                    s.mass_kg
                )));
            }
            if !(s.mesh_scale > 0.0 && s.mesh_scale.is_finite()) {
                return Err(err(format!("{name}: 'mesh_scale' must be positive")));
            }
            if Vector::from_array(s.up_mesh).length() < 0.5 {
                return Err(err(format!("{name}: 'up_mesh' must be a unit vector")));
            }
        }
        let shapes = file
            .object
            .iter()
            .map(|spec| build_shape(spec, meshes))
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            specs: file.object,
            shapes,
        })
    }

    /// Number of object types.
    pub fn len(&self) -> usize {
        self.specs.len()
    }

    /// True if the catalog has no object (never, once loaded).
    pub fn is_empty(&self) -> bool {
        self.specs.is_empty()
    }

    /// All specs, in catalog order.
    pub fn specs(&self) -> &[ObjectSpec] {
        &self.specs
    }

    /// The spec of a type.
    pub fn spec(&self, t: TypeIdx) -> &ObjectSpec {
        &self.specs[t.0 as usize]
    }

    /// The shape of a type.
    pub fn shape(&self, t: TypeIdx) -> &ObjectShape {
        &self.shapes[t.0 as usize]
    }

    /// All type indices.
    pub fn types(&self) -> impl Iterator<Item = TypeIdx> + '_ {
        (0..self.specs.len()).map(|i| TypeIdx(i as u16))
    }

    /// Looks an id up (`"002"`), or the error naming it.
    pub fn by_id(&self, id: &str) -> Result<TypeIdx> {
        self.specs
            .iter()
            .position(|s| s.id == id)
            .map(|i| TypeIdx(i as u16))
            .ok_or_else(|| SimError::UnknownObject(id.to_owned()))
    }

    /// Looks a BoxED dataset type name up (`"004 sugar box"`).
    pub fn by_dataset_type(&self, name: &str) -> Result<TypeIdx> {
        self.specs
            .iter()
            .position(|s| s.dataset_type == name)
            .map(|i| TypeIdx(i as u16))
            .ok_or_else(|| SimError::UnknownObject(name.to_owned()))
    }

    /// One line per object saying which shape source it used (for logs).
    pub fn source_report(&self) -> Vec<String> {
        self.specs
            .iter()
            .zip(&self.shapes)
            .map(|(s, sh)| match &sh.source {
                ShapeSource::Mesh(p) => format!(
                    "{} {:<18} mesh hull {} ({} vertices)",
                    s.id,
                    s.name,
                    p.display(),
                    sh.vertices.len()
                ),
                ShapeSource::Primitive(why) => {
                    format!(
                        "{} {:<18} primitive {:?} ({why})",
                        s.id, s.name, s.primitive
                    )
                }
            })
            .collect()
    }
}

/// Builds an object's shape from its mesh when one is configured and present, else its primitive.
fn build_shape(spec: &ObjectSpec, meshes: &MeshSource) -> Result<ObjectShape> {
    let (points, source) = match (meshes, &spec.mesh) {
        (MeshSource::Folder(dir), Some(file)) => {
            let path = dir.join(file);
            let raw = crate::mesh::load_obj_vertices(&path)?;
            let pts: Vec<Vector> = raw.iter().map(|&v| spec.mesh_to_canonical(v)).collect();
            (crate::hull::support_points(&pts), ShapeSource::Mesh(path))
        }
        (MeshSource::Folder(_), None) => (
            primitive_points(spec.primitive, spec.dims_m),
            ShapeSource::Primitive("no mesh in the catalog".into()),
        ),
        (MeshSource::None(why), _) => (
            primitive_points(spec.primitive, spec.dims_m),
            ShapeSource::Primitive(why.clone()),
        ),
    };
    let path_for_err = match &source {
        ShapeSource::Mesh(p) => p.clone(),
        ShapeSource::Primitive(_) => PathBuf::from(format!("<primitive of {}>", spec.id)),
    };
    ObjectShape::from_points(&points, source).map_err(|e| SimError::Mesh {
        path: path_for_err,
        message: e.to_string(),
    })
}

impl ObjectShape {
    /// Convex hull of `points` (canonical frame) as a shape, with every face reduced to at
    /// most four vertices (see [`crate::hull::quad_faced_hull`]).
    pub fn from_points(
        points: &[Vector],
        source: ShapeSource,
    ) -> std::result::Result<Self, HullError> {
        if points.len() < 4 || points.iter().any(|p| !p.is_finite()) {
            return Err(HullError::TooFewPoints(points.len()));
        }
        let (vertices, triangles, poly) = quad_faced_hull(points)?;
        let volume = hull_volume(&vertices, &triangles);
        if volume.is_nan() || volume <= 1e-9 {
            return Err(HullError::Degenerate(volume));
        }
        let (aabb_min, aabb_max) = vertices.iter().fold(
            (Vector::splat(f32::MAX), Vector::splat(f32::MIN)),
            |(lo, hi), &v| (lo.min(v), hi.max(v)),
        );
        let collider = SharedShape::new(poly);
        let unit_mass = collider.mass_properties(1.0);
        Ok(Self {
            vertices,
            triangles,
            volume,
            aabb_min,
            aabb_max,
            collider,
            unit_mass,
            source,
        })
    }

    /// Canonical extents (max - min) of the hull.
    pub fn extents(&self) -> Vector {
        self.aabb_max - self.aabb_min
    }

    /// Axis-aligned bounds (min, max) of the hull turned by `rot`, around its origin.
    pub fn rotated_bounds(&self, rot: Rotation) -> (Vector, Vector) {
        self.vertices.iter().fold(
            (Vector::splat(f32::MAX), Vector::splat(f32::MIN)),
            |(lo, hi), &v| {
                let r = rot * v;
                (lo.min(r), hi.max(r))
            },
        )
    }
}

/// Sample points of a primitive with extents `dims` centred at the origin.
pub fn primitive_points(kind: Primitive, dims: [f32; 3]) -> Vec<Vector> {
    let h = Vector::from_array(dims) * 0.5;
    let mut pts = Vec::new();
    const SEG: usize = 32;
    match kind {
        Primitive::Cuboid => {
            for i in 0..8 {
                let s = |bit: usize| if i & bit == 0 { -1.0 } else { 1.0 };
                pts.push(Vector::new(s(1) * h.x, s(2) * h.y, s(4) * h.z));
            }
        }
        Primitive::Cylinder => {
            for k in 0..SEG {
                let a = k as f32 / SEG as f32 * std::f32::consts::TAU;
                for z in [-h.z, h.z] {
                    pts.push(Vector::new(h.x * a.cos(), h.y * a.sin(), z));
                }
            }
        }
        Primitive::Ellipsoid => {
            for d in sphere_directions(192) {
                pts.push(d * h);
            }
            for axis in [Vector::X, Vector::Y, Vector::Z] {
                pts.push(axis * h);
                pts.push(-axis * h);
            }
        }
        Primitive::Capsule => {
            let r_y = h.y;
            let r_z = h.z;
            let half_len = (h.x - r_y).max(0.0);
            for d in sphere_directions(192) {
                let c = if d.x >= 0.0 { half_len } else { -half_len };
                pts.push(Vector::new(c + d.x * r_y, d.y * r_y, d.z * r_z));
            }
            for s in [-1.0, 1.0] {
                pts.push(Vector::new(s * h.x, 0.0, 0.0));
                pts.push(Vector::new(s * half_len, 0.0, s * r_z));
                pts.push(Vector::new(s * half_len, 0.0, -s * r_z));
            }
        }
    }
    pts
}

/// Shared handle to a catalog, as worlds hold it.
pub type SharedCatalog = Arc<Catalog>;
