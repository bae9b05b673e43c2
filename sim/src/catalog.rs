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
use crate::paths::MeshSource;
use rapier3d::math::{Rotation, Vector};
use rapier3d::prelude::SharedShape;
use serde::Deserialize;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The catalog shipped with the repository, compiled in so binaries run from anywhere.
pub const BUILTIN_CATALOG: &str = include_str!("../../models/objects.toml");

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
            (crate::mesh::support_points(&pts), ShapeSource::Mesh(path))
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
    ObjectShape::from_points(&points, source).map_err(|message| SimError::Mesh {
        path: path_for_err,
        message,
    })
}

impl ObjectShape {
    /// Convex hull of `points` (canonical frame) as a shape, with every face reduced to at
    /// most four vertices (see [`quad_faced_hull`]).
    pub fn from_points(
        points: &[Vector],
        source: ShapeSource,
    ) -> std::result::Result<Self, String> {
        if points.len() < 4 || points.iter().any(|p| !p.is_finite()) {
            return Err(format!(
                "{} points (need 4 or more, all finite)",
                points.len()
            ));
        }
        let (vertices, triangles, poly) = quad_faced_hull(points)?;
        let volume = hull_volume(&vertices, &triangles);
        if volume.is_nan() || volume <= 1e-9 {
            return Err(format!("degenerate hull (volume {volume:e} m^3)"));
        }
        let (aabb_min, aabb_max) = vertices.iter().fold(
            (Vector::splat(f32::MAX), Vector::splat(f32::MIN)),
            |(lo, hi), &v| (lo.min(v), hi.max(v)),
        );
        let collider = SharedShape::new(poly);
        Ok(Self {
            vertices,
            triangles,
            volume,
            aabb_min,
            aabb_max,
            collider,
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

/// Vertices, outward triangles and the parry polyhedron of a hull.
pub type QuadHull = (Vec<Vector>, Vec<[u32; 3]>, parry3d::shape::ConvexPolyhedron);

/// How far face vertices beyond the kept four are moved inwards (m).
pub const FACE_NUDGE_M: f32 = 0.0004;

/// The convex hull of `points` with no face of more than four vertices.
///
/// parry's contact generation for convex polyhedra uses at most the first four vertices of a
/// face (`ConvexPolyhedron::support_face`), so a can's 32-gon base would touch the floor on a
/// sliver and the can would topple. For each face with more vertices we keep the four that
/// span the largest quadrilateral and move the others [`FACE_NUDGE_M`] inwards along the face
/// normal, then rebuild the hull, until every face is a triangle or a quad. The object then
/// rests on that quad (as parry's own cylinders rest on an inscribed square).
pub fn quad_faced_hull(points: &[Vector]) -> std::result::Result<QuadHull, String> {
    let mut pts = points.to_vec();
    for _ in 0..12 {
        let (v, t) = parry3d::transformation::try_convex_hull(&pts)
            .map_err(|e| format!("convex hull failed: {e:?}"))?;
        let poly = parry3d::shape::ConvexPolyhedron::from_convex_mesh(v, &t)
            .ok_or_else(|| "parry rejected the hull as a convex mesh".to_string())?;
        let mut next = poly.points().to_vec();
        let mut moved = false;
        for face in poly.faces() {
            let n = face.num_vertices_or_edges as usize;
            if n <= 4 {
                continue;
            }
            let first = face.first_vertex_or_edge as usize;
            let ids = &poly.vertices_adj_to_face()[first..first + n];
            let ring: Vec<Vector> = ids.iter().map(|&i| poly.points()[i as usize]).collect();
            let keep = max_area_quad(&ring);
            for (k, &vid) in ids.iter().enumerate() {
                if !keep.contains(&k) {
                    next[vid as usize] -= face.normal * FACE_NUDGE_M;
                    moved = true;
                }
            }
        }
        if !moved {
            let v = poly.points().to_vec();
            let t = triangulate_faces(&poly);
            return Ok((v, t, poly));
        }
        pts = next;
    }
    Err("could not reduce the hull's faces to quads in 12 rounds".into())
}

/// Fan triangulation of every face of a polyhedron, outward winding. Face vertices are first
/// put in cyclic order around the face centre (parry does not promise an order).
fn triangulate_faces(poly: &parry3d::shape::ConvexPolyhedron) -> Vec<[u32; 3]> {
    let mut out = Vec::new();
    for face in poly.faces() {
        let first = face.first_vertex_or_edge as usize;
        let mut ids = poly.vertices_adj_to_face()
            [first..first + face.num_vertices_or_edges as usize]
            .to_vec();
        let p = |i: u32| poly.points()[i as usize];
        let centre = ids.iter().fold(Vector::ZERO, |a, &i| a + p(i)) / ids.len() as f32;
        let n = face.normal;
        let u = (p(ids[0]) - centre).normalize_or_zero();
        let v = n.cross(u);
        ids.sort_by(|&a, &b| {
            let (da, db) = (p(a) - centre, p(b) - centre);
            da.dot(v)
                .atan2(da.dot(u))
                .total_cmp(&db.dot(v).atan2(db.dot(u)))
        });
        for k in 1..ids.len().saturating_sub(1) {
            let tri = [ids[0], ids[k], ids[k + 1]];
            let [a, b, c] = tri.map(p);
            // Keep the winding outward.
            if (b - a).cross(c - a).dot(n) >= 0.0 {
                out.push(tri);
            } else {
                out.push([tri[0], tri[2], tri[1]]);
            }
        }
    }
    out
}

/// Indices of four vertices of a convex polygon spanning (nearly) the largest quadrilateral:
/// for each vertex a, its farthest vertex b, then the farthest vertex on each side of ab.
fn max_area_quad(ring: &[Vector]) -> [usize; 4] {
    let mut best = (f32::MIN, [0, 1, 2, 3]);
    for a in 0..ring.len() {
        let b = (0..ring.len())
            .max_by(|&i, &j| {
                ring[i]
                    .distance_squared(ring[a])
                    .total_cmp(&ring[j].distance_squared(ring[a]))
            })
            .unwrap_or(a);
        let ab = ring[b] - ring[a];
        // Signed distance to line ab within the polygon plane via the cross product's length.
        let side = |i: usize| {
            let c = ab.cross(ring[i] - ring[a]);
            (c.length(), c)
        };
        let reference = (0..ring.len())
            .map(|i| side(i).1)
            .find(|c| c.length() > 1e-9)
            .unwrap_or(Vector::Z);
        let (mut c_best, mut d_best) = ((f32::MIN, a), (f32::MIN, b));
        for i in 0..ring.len() {
            if i == a || i == b {
                continue;
            }
            let (len, c) = side(i);
            if c.dot(reference) >= 0.0 {
                if len > c_best.0 {
                    c_best = (len, i);
                }
            } else if len > d_best.0 {
                d_best = (len, i);
            }
        }
        let area = c_best.0.max(0.0) + d_best.0.max(0.0);
        let (c, d) = (c_best.1, d_best.1);
        if area > best.0 && c != d && c != a && d != b {
            best = (area, [a, b, c, d]);
        }
    }
    best.1
}

/// Volume enclosed by a closed, consistently oriented triangle mesh (divergence theorem).
pub fn hull_volume(vertices: &[Vector], triangles: &[[u32; 3]]) -> f32 {
    let six_v: f64 = triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| vertices[i as usize].as_dvec3());
            a.dot(b.cross(c))
        })
        .sum();
    (six_v / 6.0).abs() as f32
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

/// `n` near-uniform unit directions (Fibonacci sphere), deterministic.
pub fn sphere_directions(n: usize) -> Vec<Vector> {
    let golden = std::f32::consts::PI * (3.0 - 5.0f32.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let a = golden * i as f32;
            Vector::new(r * a.cos(), r * a.sin(), z)
        })
        .collect()
}

/// Shared handle to a catalog, as worlds hold it.
pub type SharedCatalog = Arc<Catalog>;

/// Canonical-frame parameters fitted from a mesh (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CanonicalFit {
    /// The resting up axis in mesh-file coordinates (see [`resting_up`]).
    pub up_mesh: [f32; 3],
    /// Turn about z after aligning up with z (rad).
    pub yaw_rad: f32,
    /// Canonical origin (AABB centre) in scaled mesh-file coordinates (m).
    pub origin_mesh_m: [f32; 3],
    /// Canonical extents (m).
    pub dims_m: [f32; 3],
}

/// Fits the canonical frame of a mesh: `scaled` are mesh vertices times `mesh_scale`; with
/// `refine_up`, the up axis is refined to the resting face ([`resting_up`]).
/// Searches the yaw in 0.25 degree steps for the smallest footprint rectangle, then turns by
/// 90 degrees if needed so the long side is along x.
pub fn fit_canonical(scaled: &[Vector], up_mesh: [f32; 3], refine_up: bool) -> CanonicalFit {
    let hint = Vector::from_array(up_mesh).normalize();
    let up = if refine_up {
        resting_up(scaled, hint)
    } else {
        hint
    };
    let hull = crate::mesh::support_points(scaled);
    let align = Rotation::from_rotation_arc(up, Vector::Z);
    let upright: Vec<Vector> = hull.iter().map(|&p| align * p).collect();
    let footprint = |yaw: f32| {
        let r = Rotation::from_rotation_z(yaw);
        let (lo, hi) = upright.iter().fold(
            (Vector::splat(f32::MAX), Vector::splat(f32::MIN)),
            |(lo, hi), &p| {
                let q = r * p;
                (lo.min(q), hi.max(q))
            },
        );
        hi - lo
    };
    let mut best = (f32::MAX, 0.0f32);
    for step in 0..360 {
        let yaw = (step as f32 * 0.25).to_radians();
        let e = footprint(yaw);
        // Prefer the first minimum; ties within 1e-9 m^2 keep the smaller yaw (deterministic).
        if e.x * e.y < best.0 - 1e-9 {
            best = (e.x * e.y, yaw);
        }
    }
    let mut yaw = best.1;
    let e = footprint(yaw);
    if e.y > e.x + 1e-6 {
        yaw += std::f32::consts::FRAC_PI_2;
    }
    let yaw = crate::frames::wrap_angle(yaw);
    let rot = Rotation::from_rotation_z(yaw) * align;
    // AABB of the full vertex set (not just the hull sample) in the rotated frame.
    let (lo, hi) = scaled.iter().fold(
        (Vector::splat(f32::MAX), Vector::splat(f32::MIN)),
        |(lo, hi), &p| {
            let q = rot * p;
            (lo.min(q), hi.max(q))
        },
    );
    let centre_rot = (lo + hi) * 0.5;
    let origin = rot.inverse() * centre_rot;
    CanonicalFit {
        up_mesh: up.to_array(),
        yaw_rad: yaw,
        origin_mesh_m: origin.to_array(),
        dims_m: (hi - lo).to_array(),
    }
}

/// Refines a nominal up axis to the normal of the face the object rests on: the area-weighted
/// mean outward normal of the convex hull's triangles within 20 degrees of `-hint`, iterated.
/// A box or can whose bottom is a few degrees off the mesh axis then stands straight; for round
/// objects the mean stays near the hint.
pub fn resting_up(scaled: &[Vector], hint: Vector) -> Vector {
    let Ok((v, tris)) = parry3d::transformation::try_convex_hull(scaled) else {
        return hint;
    };
    let mut up = hint;
    for _ in 0..4 {
        let mut acc = Vector::ZERO;
        for t in &tris {
            let [a, b, c] = t.map(|i| v[i as usize]);
            let n2 = (b - a).cross(c - a); // outward normal times twice the area
            let len = n2.length();
            if len > 0.0 && (n2 / len).dot(-up) > 20f32.to_radians().cos() {
                acc += n2;
            }
        }
        if acc.length() == 0.0 {
            break;
        }
        up = -acc.normalize();
    }
    up
}
