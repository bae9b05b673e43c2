//! Hull geometry for the catalog: the quad-faced convex hull parry can rest on, its volume,
//! support points of a point cloud, and the canonical-frame fit of a mesh. Pure geometry: it
//! knows nothing of the catalog file or of meshes on disk ([`crate::mesh`] reads those,
//! [`crate::catalog`] uses both).

use parry3d::math::{Rotation, Vector};
use parry3d::transformation::ConvexHullError;

/// Why no usable hull could be made of a point cloud.
#[derive(Debug, PartialEq, thiserror::Error)]
pub enum HullError {
    /// Too few points, or a point that is not finite.
    #[error("{0} points (need 4 or more, all finite)")]
    TooFewPoints(usize),
    /// parry's convex hull failed.
    #[error("convex hull failed: {0:?}")]
    ConvexHull(#[source] ConvexHullError),
    /// parry did not take the hull as a convex mesh.
    #[error("parry rejected the hull as a convex mesh")]
    NotConvexMesh,
    /// Some face still had more than four vertices after the last round.
    #[error("could not reduce the hull's faces to quads in 12 rounds")]
    FacesNotReduced,
    /// The hull is flat (its volume, m^3, is zero, tiny or NaN).
    #[error("degenerate hull (volume {0:e} m^3)")]
    Degenerate(f32),
}

/// Number of sampling directions used to reduce a hull (plus the 26 axis and diagonal ones).
pub const SUPPORT_DIRECTIONS: usize = 160;

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
pub fn quad_faced_hull(points: &[Vector]) -> std::result::Result<QuadHull, HullError> {
    let mut pts = points.to_vec();
    for _ in 0..12 {
        let (v, t) =
            parry3d::transformation::try_convex_hull(&pts).map_err(HullError::ConvexHull)?;
        let poly = parry3d::shape::ConvexPolyhedron::from_convex_mesh(v, &t)
            .ok_or(HullError::NotConvexMesh)?;
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
    Err(HullError::FacesNotReduced)
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
            // In f64: a . (b x c).
            let [a, b, c] = t.map(|i| {
                let v = vertices[i as usize];
                [v.x as f64, v.y as f64, v.z as f64]
            });
            let cross = [
                b[1] * c[2] - b[2] * c[1],
                b[2] * c[0] - b[0] * c[2],
                b[0] * c[1] - b[1] * c[0],
            ];
            a[0] * cross[0] + a[1] * cross[1] + a[2] * cross[2]
        })
        .sum();
    (six_v / 6.0).abs() as f32
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

/// The support points of `points` in a fixed set of directions: the vertices of an inner
/// approximation of the convex hull with at most `SUPPORT_DIRECTIONS + 26` vertices. Keeps the
/// axis-aligned extremes exactly (so extents are preserved) and is deterministic.
pub fn support_points(points: &[Vector]) -> Vec<Vector> {
    let mut dirs = sphere_directions(SUPPORT_DIRECTIONS);
    for i in -1i32..=1 {
        for j in -1i32..=1 {
            for k in -1i32..=1 {
                if (i, j, k) != (0, 0, 0) {
                    dirs.push(Vector::new(i as f32, j as f32, k as f32).normalize());
                }
            }
        }
    }
    let mut idx: Vec<usize> = dirs
        .iter()
        .map(|d| {
            let mut best = 0;
            let mut best_v = f32::MIN;
            for (i, p) in points.iter().enumerate() {
                let v = p.dot(*d);
                if v > best_v {
                    best_v = v;
                    best = i;
                }
            }
            best
        })
        .collect();
    idx.sort_unstable();
    idx.dedup();
    idx.into_iter().map(|i| points[i]).collect()
}

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
    let hull = support_points(scaled);
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
