//! The heightmap twin's pile as static colliders ([`pile_colliders`]).
//!
//! The pile is what a camera sees: a height per cell. Its collider must never be below the
//! heightmap (objects land on the pile, not in it) and should touch an object with as few
//! shapes as it can, since every shape under an object is one more contact manifold for the
//! solver, each step of each settle of each rollout.
//!
//! - **Pieces** (`pile_fit_m > 0`, the default): the cells are grown into rectangles, each one
//!   convex piece (the convex hull of its cells' tops and its floor corners), as long as the
//!   piece's top stays within `pile_fit_m` of every cell's own height. A flat or tilted top
//!   (a box lying on its side, a can) becomes one piece where columns made dozens; a step
//!   (an object's edge) ends a piece, since a hull across it would fill the step.
//! - **Row runs** (`pile_fit_m = 0`, the collider before pieces, kept for the benches' ratios):
//!   heights rounded up to `pile_step_m`, each row's runs of one height one cuboid.

use rapier3d::math::Vector;
use rapier3d::prelude::{ColliderBuilder, SharedShape};

/// Cells lower than this (m) are the floor, not the pile.
pub(crate) const PILE_FLOOR_M: f32 = 0.002;

/// The widest and longest piece, in cells: bounds the hulls' size, so building a twin stays
/// cheap (a piece of 16 x 16 cells is 293 points).
const MAX_PIECE_CELLS: usize = 16;

/// A grid of pooled pile heights: `h[row * nx + col]` (m), rows from B's +y side, columns from
/// -x; column `col` spans B x `xs[col]..xs[col + 1]`, row `row` B y `ys[row + 1]..ys[row]`.
pub(crate) struct PileGrid<'a> {
    /// Heights, row-major.
    pub h: &'a [f32],
    /// Columns.
    pub nx: usize,
    /// Rows.
    pub ny: usize,
    /// The columns' edges in B x, increasing (`nx + 1`).
    pub xs: Vec<f32>,
    /// The rows' edges in B y, decreasing (`ny + 1`).
    pub ys: Vec<f32>,
}

impl PileGrid<'_> {
    fn at(&self, row: usize, col: usize) -> f32 {
        self.h[row * self.nx + col]
    }

    fn x(&self, col: usize) -> f32 {
        self.xs[col]
    }

    fn y(&self, row: usize) -> f32 {
        self.ys[row]
    }

    /// The centre of cell (`row`, `col`) in B x and y.
    fn centre(&self, row: usize, col: usize) -> (f32, f32) {
        (
            0.5 * (self.xs[col] + self.xs[col + 1]),
            0.5 * (self.ys[row] + self.ys[row + 1]),
        )
    }

    /// The cuboid from the floor up to `h` over columns `c0..c1` and rows `r0..r1`.
    fn cuboid(&self, r0: usize, r1: usize, c0: usize, c1: usize, h: f32) -> ColliderBuilder {
        let (x0, x1, y0, y1) = (self.x(c0), self.x(c1), self.y(r0), self.y(r1));
        ColliderBuilder::cuboid(0.5 * (x1 - x0), 0.5 * (y0 - y1), 0.5 * h).translation(Vector::new(
            0.5 * (x0 + x1),
            0.5 * (y0 + y1),
            0.5 * h,
        ))
    }
}

/// The pile's colliders (friction and restitution are the caller's), by pieces when `fit_m > 0`,
/// else by row runs of heights rounded up to `step_m` (see the module's documentation).
pub(crate) fn pile_colliders(g: &PileGrid<'_>, fit_m: f32, step_m: f32) -> Vec<ColliderBuilder> {
    if fit_m > 0.0 {
        pieces(g, fit_m)
    } else {
        row_runs(g, step_m)
    }
}

fn row_runs(g: &PileGrid<'_>, step_m: f32) -> Vec<ColliderBuilder> {
    let up = |h: f32| (h / step_m).ceil() * step_m;
    let mut out = Vec::new();
    for row in 0..g.ny {
        let mut col = 0;
        while col < g.nx {
            let h = up(g.at(row, col));
            let mut end = col + 1;
            while end < g.nx && up(g.at(row, end)) == h {
                end += 1;
            }
            if h > PILE_FLOOR_M {
                out.push(g.cuboid(row, row + 1, col, end, h));
            }
            col = end;
        }
    }
    out
}

fn pieces(g: &PileGrid<'_>, fit_m: f32) -> Vec<ColliderBuilder> {
    let mut taken = vec![false; g.nx * g.ny];
    let mut points = Vec::new();
    let mut out = Vec::new();
    let free = |taken: &[bool], row: usize, col: usize| {
        !taken[row * g.nx + col] && g.at(row, col) > PILE_FLOOR_M
    };
    for r0 in 0..g.ny {
        for c0 in 0..g.nx {
            if !free(&taken, r0, c0) {
                continue;
            }
            // Grow a column to the right and a row down in turn, each while the piece still
            // fits, until neither does: pieces as square as the pile lets them be.
            let (mut c1, mut r1, mut hull) = (c0 + 1, r0 + 1, None);
            let (mut right, mut down) = (true, true);
            while right || down {
                right = right
                    && c1 < g.nx
                    && c1 - c0 < MAX_PIECE_CELLS
                    && (r0..r1).all(|r| free(&taken, r, c1));
                if right {
                    match fit(g, &mut points, r0, r1, c0, c1 + 1, fit_m) {
                        Some(h) => {
                            hull = Some(h);
                            c1 += 1;
                        }
                        None => right = false,
                    }
                }
                down = down
                    && r1 < g.ny
                    && r1 - r0 < MAX_PIECE_CELLS
                    && (c0..c1).all(|c| free(&taken, r1, c));
                if down {
                    match fit(g, &mut points, r0, r1 + 1, c0, c1, fit_m) {
                        Some(h) => {
                            hull = Some(h);
                            r1 += 1;
                        }
                        None => down = false,
                    }
                }
            }
            for row in r0..r1 {
                taken[row * g.nx + c0..row * g.nx + c1].fill(true);
            }
            // parry touches a face through at most four of its vertices (see
            // `herb_core::hull::quad_faced_hull`): a flat top of many collinear edge points
            // would hold an object on a sliver, so the piece's faces are made quads.
            let piece = hull.and_then(|v| {
                let (_, _, poly) = herb_core::hull::quad_faced_hull(&v).ok()?;
                Some(ColliderBuilder::new(SharedShape::new(poly)))
            });
            out.push(piece.unwrap_or_else(|| {
                // One cell (or a hull that could not be made quad-faced): one cuboid up to the
                // rectangle's highest cell.
                let top = (r0..r1)
                    .flat_map(|r| (c0..c1).map(move |c| (r, c)))
                    .map(|(r, c)| g.at(r, c))
                    .fold(0.0f32, f32::max);
                g.cuboid(r0, r1, c0, c1, top)
            }));
        }
    }
    out
}

/// The vertices of the convex hull of the cells `r0..r1` x `c0..c1` (their tops: each grid vertex at the
/// highest of its cells in the rectangle, and the rectangle's floor corners), if its top is
/// within `fit_m` of every cell's own height at the cell's centre. It is never below a cell:
/// the top of a convex body is a concave function, so over each cell it is at least the least
/// of the cell's corners, each at least the cell's height.
fn fit(
    g: &PileGrid<'_>,
    points: &mut Vec<Vector>,
    r0: usize,
    r1: usize,
    c0: usize,
    c1: usize,
    fit_m: f32,
) -> Option<Vec<Vector>> {
    points.clear();
    for vr in r0..=r1 {
        for vc in c0..=c1 {
            let mut top = 0.0f32;
            for row in vr.saturating_sub(1).max(r0)..vr.min(r1 - 1) + 1 {
                for col in vc.saturating_sub(1).max(c0)..vc.min(c1 - 1) + 1 {
                    top = top.max(g.at(row, col));
                }
            }
            points.push(Vector::new(g.x(vc), g.y(vr), top));
        }
    }
    for (vr, vc) in [(r0, c0), (r0, c1), (r1, c0), (r1, c1)] {
        points.push(Vector::new(g.x(vc), g.y(vr), 0.0));
    }
    let (v, t) = rapier3d::parry::transformation::try_convex_hull(points).ok()?;
    if t.is_empty() {
        return None;
    }
    // The top over (x, y) is the least of the outward up-facing faces' planes there.
    let centroid = v.iter().copied().sum::<Vector>() / v.len() as f32;
    let planes: Vec<(Vector, Vector)> = t
        .iter()
        .filter_map(|&[a, b, c]| {
            let (a, b, c) = (v[a as usize], v[b as usize], v[c as usize]);
            let mut n = (b - a).cross(c - a);
            if n.dot(a - centroid) < 0.0 {
                n = -n;
            }
            (n.z > 1e-6 * n.length()).then_some((a, n))
        })
        .collect();
    for row in r0..r1 {
        for col in c0..c1 {
            let (x, y) = g.centre(row, col);
            let top = planes
                .iter()
                .map(|(a, n)| a.z - (n.x * (x - a.x) + n.y * (y - a.y)) / n.z)
                .fold(f32::INFINITY, f32::min);
            if top - g.at(row, col) > fit_m {
                return None;
            }
        }
    }
    Some(v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rapier3d::prelude::*;

    fn grid(h: &[f32], nx: usize) -> PileGrid<'_> {
        let ny = h.len() / nx;
        PileGrid {
            h,
            nx,
            ny,
            xs: (0..=nx).map(|c| -0.1 + 0.0125 * c as f32).collect(),
            ys: (0..=ny).map(|r| 0.1 - 0.0125 * r as f32).collect(),
        }
    }

    /// The top of the colliders over each cell's centre (a ray cast down), or 0 with none.
    fn tops(g: &PileGrid<'_>, colliders: Vec<ColliderBuilder>) -> Vec<f32> {
        let mut bodies = RigidBodySet::new();
        let mut set = ColliderSet::new();
        let body = bodies.insert(RigidBodyBuilder::fixed());
        for c in colliders {
            set.insert_with_parent(c, body, &mut bodies);
        }
        let mut out = Vec::new();
        for row in 0..g.ny {
            for col in 0..g.nx {
                let (x, y) = g.centre(row, col);
                let ray = rapier3d::parry::query::Ray::new(
                    Vector::new(x, y, 1.0),
                    Vector::new(0.0, 0.0, -1.0),
                );
                let hit = set
                    .iter()
                    .filter_map(|(_, c)| c.shape().cast_ray(c.position(), &ray, 2.0, true))
                    .fold(f32::INFINITY, f32::min);
                out.push(if hit.is_finite() { 1.0 - hit } else { 0.0 });
            }
        }
        out
    }

    /// A pile of a flat block, a tilted slab and a cylinder lying on its side, on a floor.
    fn scene() -> (Vec<f32>, usize) {
        let (nx, ny) = (16, 16);
        let mut h = vec![0.0f32; nx * ny];
        for row in 0..ny {
            for col in 0..nx {
                let v = &mut h[row * nx + col];
                if row < 6 && col < 6 {
                    *v = 0.05; // a block
                } else if row < 6 && col >= 8 {
                    *v = 0.02 + 0.004 * (col - 8) as f32; // a slab tilted about y
                } else if row >= 9 {
                    let d = (col as f32 - 7.5) * 0.0125; // a can of radius 4 cm along x
                    if d.abs() < 0.04 {
                        *v = 0.04 + (0.04f32 * 0.04 - d * d).sqrt();
                    }
                }
            }
        }
        (h, nx)
    }

    #[test]
    fn pieces_are_never_below_a_cell_nor_above_it_by_more_than_the_fit_and_are_few() {
        let (h, nx) = scene();
        let g = grid(&h, nx);
        let fit_m = 0.006;
        let pieces = pile_colliders(&g, fit_m, 0.002);
        let runs = pile_colliders(&g, 0.0, 0.002);
        let n = (pieces.len(), runs.len());
        let t = tops(&g, pieces);
        for (i, (&top, &cell)) in t.iter().zip(&h).enumerate() {
            if cell > PILE_FLOOR_M {
                assert!(top >= cell - 1e-4, "cell {i}: top {top} below {cell}");
                assert!(
                    top <= cell + fit_m + 1e-4,
                    "cell {i}: top {top} over {cell}"
                );
            } else {
                assert_eq!(top, 0.0, "cell {i} is floor, yet under a piece");
            }
        }
        // The block and the slab one piece each; the can a few; row runs many more.
        assert!(n.0 * 3 < n.1, "{} pieces against {} row runs", n.0, n.1);
    }

    #[test]
    fn row_runs_round_heights_up_and_cover_every_pile_cell() {
        let (h, nx) = scene();
        let g = grid(&h, nx);
        let t = tops(&g, pile_colliders(&g, 0.0, 0.002));
        for (&top, &cell) in t.iter().zip(&h) {
            if cell > PILE_FLOOR_M {
                assert!(
                    top >= cell - 1e-4 && top <= cell + 0.002 + 1e-4,
                    "{top} {cell}"
                );
            }
        }
    }
}
