//! The observation layout and the action mapping: the contract shared by training, evaluation
//! and the daemon. Defined here once; everything else imports it.
//!
//! # Observation
//!
//! `f32` tensor of shape `[CHANNELS, SIZE, SIZE]` = `[2, 224, 224]`, channel-major, row-major
//! (the ONNX input adds a batch dimension: `[1, 2, 224, 224]`). Pixels are square with side
//! [`ObsLayout::CELL_M`] = 0.35 m / 224 = 1.5625 mm, the same scale in both channels. Image
//! rows run from +y (row 0) to -y, columns from -x to +x (B frame seen from above).
//!
//! - **Channel 0, box heightmap**: the box interior centred in the image; value = height above
//!   the inner floor / [`ObsLayout::HEIGHT_SCALE_M`], clamped to `[0, 1]`. Pixels outside the
//!   interior (the padding) are 1.0: "blocked", as high as the scale allows.
//! - **Channel 1, next object**: the top-down projection of the next object to place, upright
//!   in its canonical orientation (theta = 0), its origin at the image centre; value = height of
//!   its top surface above its lowest point / `HEIGHT_SCALE_M`, clamped to `[0, 1]`; 0 where
//!   there is no object. All zero when there is no next object (terminal observation).
//!
//! The paper appends the object's projection to the heightmap and pads to 224 x 224; here the
//! two images are stacked as channels at the same scale, which keeps the full box resolution
//! (222 x 146 cells) inside 224 x 224.
//!
//! # Action
//!
//! `a` in `[-1, 1]^3` maps linearly: `x = a0 * BOX_HALF_X`, `y = a1 * BOX_HALF_Y` (the canonical
//! origin of the object, over the box interior), `theta = a2 * pi` (turn about z). Finite
//! actions outside the range are clamped; non-finite ones are rejected.
//!
//! # Policy model I/O contract (ONNX)
//!
//! A placement policy model has exactly one input and one output:
//!
//! - input [`ObsLayout::INPUT_NAME`] = `"obs"`, `float32`, shape [`ObsLayout::INPUT_SHAPE`] =
//!   `[1, 2, 224, 224]`: the observation above, values in `[0, 1]`, no other normalisation;
//! - output [`ObsLayout::OUTPUT_NAME`] = `"action"`, `float32`, shape `[1, 3]`: the
//!   deterministic action `(x, y, theta)` in `[-1, 1]` (SAC: `tanh` of the actor's mean), mapped
//!   as in "Action" above.
//!
//! Networks that work at a lower resolution downsample inside the model, so the contract stays
//! the same. `herb-daemon` checks all of this when it loads a model and refuses one that
//! differs, naming what differs.

use crate::catalog::{Catalog, ObjectShape, TypeIdx};
use crate::error::{Result, SimError};
use crate::frames::{BOX_HALF_X, BOX_HALF_Y};
use crate::heightmap::{DepthTest, GridSpec, Heightmap, Window, raster_hull};
use parry3d::math::Vector;

/// The observation layout (see the module docs). A namespace of constants and functions.
#[derive(Debug, Clone, Copy)]
pub struct ObsLayout;

impl ObsLayout {
    /// Image side (pixels).
    pub const SIZE: usize = 224;
    /// Channels: 0 box heightmap, 1 next object.
    pub const CHANNELS: usize = 2;
    /// Values per observation.
    pub const LEN: usize = Self::CHANNELS * Self::SIZE * Self::SIZE;
    /// Pixel side (m): 0.35 m over 224 pixels.
    pub const CELL_M: f32 = 0.35 / 224.0;
    /// Height that maps to 1.0 (m): the success volume's top (rim 0.1639 + 0.13) rounded up.
    pub const HEIGHT_SCALE_M: f32 = 0.30;
    /// Value of padding pixels in channel 0.
    pub const PAD_VALUE: f32 = 1.0;
    /// ONNX input shape (batch 1).
    pub const INPUT_SHAPE: [usize; 4] = [1, Self::CHANNELS, Self::SIZE, Self::SIZE];
    /// ONNX input name.
    pub const INPUT_NAME: &'static str = "obs";
    /// ONNX output name.
    pub const OUTPUT_NAME: &'static str = "action";
    /// ONNX output shape (batch 1, x y theta).
    pub const OUTPUT_SHAPE: [usize; 2] = [1, 3];

    /// The heightmap grid at observation scale (222 x 146 cells).
    pub fn grid() -> GridSpec {
        GridSpec::for_box(Self::CELL_M).expect("CELL_M is a valid cell size")
    }

    /// B (x, y) of the centre of observation pixel (col, row).
    pub fn pixel_centre(col: usize, row: usize) -> (f32, f32) {
        let half = Self::SIZE as f32 * 0.5;
        (
            (col as f32 + 0.5 - half) * Self::CELL_M,
            (half - (row as f32 + 0.5)) * Self::CELL_M,
        )
    }

    /// Writes the observation for heightmap `hm` and the next object's projection (`None` at
    /// the end of an episode) into `out` (length [`Self::LEN`]). Does not allocate.
    pub fn write(hm: &Heightmap, next: Option<&ObjectProjection>, out: &mut [f32]) -> Result<()> {
        if out.len() != Self::LEN {
            return Err(SimError::Heightmap(format!(
                "observation buffer of {} values, expected {}",
                out.len(),
                Self::LEN
            )));
        }
        let (ch0, ch1) = out.split_at_mut(Self::SIZE * Self::SIZE);
        let s = 1.0 / Self::HEIGHT_SCALE_M;
        let spec = hm.spec();
        if *spec == Self::grid() {
            // Fast path: same scale, the grid sits at a whole-pixel offset.
            let c_off = (Self::SIZE - spec.nx) / 2;
            let r_off = (Self::SIZE - spec.ny) / 2;
            ch0.fill(Self::PAD_VALUE);
            for r in 0..spec.ny {
                let src = &hm.data()[r * spec.nx..(r + 1) * spec.nx];
                let dst = &mut ch0[(r + r_off) * Self::SIZE + c_off..][..spec.nx];
                for (d, &v) in dst.iter_mut().zip(src) {
                    *d = (v * s).clamp(0.0, 1.0);
                }
            }
        } else {
            for r in 0..Self::SIZE {
                for c in 0..Self::SIZE {
                    let (x, y) = Self::pixel_centre(c, r);
                    ch0[r * Self::SIZE + c] = if x.abs() <= BOX_HALF_X && y.abs() <= BOX_HALF_Y {
                        (hm.sample(x, y) * s).clamp(0.0, 1.0)
                    } else {
                        Self::PAD_VALUE
                    };
                }
            }
        }
        match next {
            Some(p) => ch1.copy_from_slice(&p.data),
            None => ch1.fill(0.0),
        }
        Ok(())
    }
}

/// Maps an action in `[-1, 1]^3` to a placement `(x, y, theta)` (see the module docs).
pub fn action_to_placement(a: [f32; 3]) -> Result<(f32, f32, f32)> {
    if a.iter().any(|v| !v.is_finite()) {
        return Err(SimError::InvalidAction(a));
    }
    let c = a.map(|v| v.clamp(-1.0, 1.0));
    Ok((
        c[0] * BOX_HALF_X,
        c[1] * BOX_HALF_Y,
        c[2] * std::f32::consts::PI,
    ))
}

/// Inverse of [`action_to_placement`] (theta wrapped to (-pi, pi]); values may exceed 1 for
/// placements beyond the walls.
pub fn placement_to_action(x: f32, y: f32, theta: f32) -> [f32; 3] {
    [
        x / BOX_HALF_X,
        y / BOX_HALF_Y,
        crate::frames::wrap_angle(theta) / std::f32::consts::PI,
    ]
}

/// Channel 1 of the observation for one object type, rendered once.
#[derive(Debug, Clone)]
pub struct ObjectProjection {
    data: Vec<f32>,
}

impl ObjectProjection {
    /// Renders the top-down projection of `shape` (see the module docs).
    pub fn render(shape: &ObjectShape) -> Self {
        let n = ObsLayout::SIZE;
        // A grid of exactly 224 x 224 observation pixels centred on the object's origin.
        let spec = GridSpec {
            nx: n,
            ny: n,
            cell: ObsLayout::CELL_M,
        };
        let lowest = shape.aabb_min.z;
        let mut verts: Vec<Vector> = shape
            .vertices
            .iter()
            .map(|&v| Vector::new(v.x, v.y, v.z - lowest))
            .collect();
        let mut data = vec![0.0f32; n * n];
        raster_hull(
            &spec,
            &mut data,
            Window {
                col0: 0,
                row0: 0,
                w: n,
                h: n,
            },
            &mut verts,
            &shape.triangles,
            DepthTest::Max,
        );
        for d in &mut data {
            *d = (*d / ObsLayout::HEIGHT_SCALE_M).clamp(0.0, 1.0);
        }
        Self { data }
    }

    /// Row-major values (224 x 224).
    pub fn data(&self) -> &[f32] {
        &self.data
    }
}

/// Projections of every catalog type, indexed by [`TypeIdx`].
#[derive(Debug, Clone)]
pub struct Projections(Vec<ObjectProjection>);

impl Projections {
    /// Renders all types of `catalog`.
    pub fn new(catalog: &Catalog) -> Self {
        Self(
            catalog
                .types()
                .map(|t| ObjectProjection::render(catalog.shape(t)))
                .collect(),
        )
    }

    /// The projection of type `t`.
    pub fn get(&self, t: TypeIdx) -> &ObjectProjection {
        &self.0[t.0 as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_constants_are_consistent() {
        let g = ObsLayout::grid();
        assert_eq!((g.nx, g.ny), (222, 146));
        assert!(g.nx <= ObsLayout::SIZE && g.ny <= ObsLayout::SIZE);
        assert_eq!((ObsLayout::SIZE - g.nx) % 2, 0);
        assert_eq!((ObsLayout::SIZE - g.ny) % 2, 0);
        assert_eq!(ObsLayout::LEN, 2 * 224 * 224);
    }

    #[test]
    fn fast_and_general_paths_agree() {
        let g = ObsLayout::grid();
        let data: Vec<f32> = (0..g.len()).map(|i| (i % 97) as f32 * 0.003).collect();
        let hm = Heightmap::from_data(g, data).unwrap();
        let mut fast = vec![0.0; ObsLayout::LEN];
        ObsLayout::write(&hm, None, &mut fast).unwrap();
        // The general path samples by position: compare it on the same data via a resampled grid.
        for r in 0..ObsLayout::SIZE {
            for c in 0..ObsLayout::SIZE {
                let (x, y) = ObsLayout::pixel_centre(c, r);
                let expect = if x.abs() <= BOX_HALF_X && y.abs() <= BOX_HALF_Y {
                    (hm.sample(x, y) * (1.0 / ObsLayout::HEIGHT_SCALE_M)).clamp(0.0, 1.0)
                } else {
                    1.0
                };
                let got = fast[r * ObsLayout::SIZE + c];
                // Pixels of the grid's overhang beyond the walls are padding in one, data in the other.
                if x.abs() < BOX_HALF_X - 0.001 && y.abs() < BOX_HALF_Y - 0.001 {
                    assert_eq!(got, expect, "pixel ({c}, {r})");
                }
            }
        }
    }

    #[test]
    fn actions_map_and_reject_nan() {
        let (x, y, t) = action_to_placement([1.0, -1.0, 0.5]).unwrap();
        assert_eq!((x, y), (BOX_HALF_X, -BOX_HALF_Y));
        assert!((t - std::f32::consts::FRAC_PI_2).abs() < 1e-6);
        assert_eq!(action_to_placement([3.0, 0.0, 0.0]).unwrap().0, BOX_HALF_X);
        assert!(action_to_placement([f32::NAN, 0.0, 0.0]).is_err());
        assert!(action_to_placement([0.0, f32::INFINITY, 0.0]).is_err());
        let a = placement_to_action(x, y, t);
        assert!((a[0] - 1.0).abs() < 1e-6 && (a[2] - 0.5).abs() < 1e-6);
    }
}
