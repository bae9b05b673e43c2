//! From a depth image to a heightmap of the box interior, with no ROS or IPC types: deproject
//! each pixel with the pinhole intrinsics, move it into the box frame B with the calibrated
//! camera pose, keep the points over the interior, take the highest per heightmap cell,
//! threshold the floor, and fill the cells no pixel saw.
//!
//! **Unseen cells** (occluded behind a wall or a tall object, or without a valid depth) are
//! filled conservatively: with the highest seen cell within `fill_radius` cells, or, with none
//! that near, with the highest seen cell of the whole frame. A placement is never planned into a
//! hole the camera could not see; the count of filled cells is reported with every frame.

use herb_core::frames::{BOX_HALF_X, BOX_HALF_Y};
use herb_core::heightmap::{GridSpec, finish_camera_cells};
use nalgebra::{Isometry3, Point3};

/// What is unusable in a camera info or a depth image.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InputError {
    /// K does not have nine values.
    #[error("K has {0} values, expected 9")]
    KLength(usize),
    /// An image size of zero or more than 4096 pixels.
    #[error("image size {width} x {height}")]
    ImageSize {
        /// Width (pixels).
        width: u32,
        /// Height (pixels).
        height: u32,
    },
    /// Focal lengths not positive, or a value not finite.
    #[error("K: fx {fx} fy {fy} cx {cx} cy {cy} unusable")]
    UnusableK {
        /// Focal length along u.
        fx: f64,
        /// Focal length along v.
        fy: f64,
        /// Principal point u.
        cx: f64,
        /// Principal point v.
        cy: f64,
    },
    /// An encoding other than 16UC1 (or mono16) and 32FC1.
    #[error("encoding {0:?}: expected 16UC1 or 32FC1")]
    Encoding(String),
    /// Big-endian pixels.
    #[error("big-endian depth")]
    BigEndian,
    /// An image whose size is not the camera info's.
    #[error("image {width} x {height}, camera info {info_width} x {info_height}")]
    SizeMismatch {
        /// The image's width.
        width: u32,
        /// The image's height.
        height: u32,
        /// The camera info's width.
        info_width: u32,
        /// The camera info's height.
        info_height: u32,
    },
    /// A row step other than the width's pixels.
    #[error("row step {step}, expected {expected}")]
    RowStep {
        /// The image's row step (bytes).
        step: u32,
        /// Width times bytes per pixel.
        expected: usize,
    },
    /// Data of another length than the rows.
    #[error("{len} bytes of data, expected {expected}")]
    DataLength {
        /// The data's length.
        len: usize,
        /// Step times height.
        expected: usize,
    },
}

/// Pinhole intrinsics of the depth image (from `sensor_msgs/CameraInfo`'s K).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    /// Image width (pixels).
    pub width: u32,
    /// Image height (pixels).
    pub height: u32,
    /// Focal length along u (pixels).
    pub fx: f64,
    /// Focal length along v (pixels).
    pub fy: f64,
    /// Principal point u (pixels).
    pub cx: f64,
    /// Principal point v (pixels).
    pub cy: f64,
}

impl Intrinsics {
    /// From a CameraInfo's size and row-major K; `Err` names what is unusable.
    pub fn from_k(width: u32, height: u32, k: &[f64]) -> Result<Self, InputError> {
        if k.len() != 9 {
            return Err(InputError::KLength(k.len()));
        }
        let i = Self {
            width,
            height,
            fx: k[0],
            fy: k[4],
            cx: k[2],
            cy: k[5],
        };
        if width == 0 || height == 0 || width > 4096 || height > 4096 {
            return Err(InputError::ImageSize { width, height });
        }
        let usable =
            [i.fx, i.fy, i.cx, i.cy].iter().all(|v| v.is_finite()) && i.fx > 0.0 && i.fy > 0.0;
        if !usable {
            return Err(InputError::UnusableK {
                fx: i.fx,
                fy: i.fy,
                cx: i.cx,
                cy: i.cy,
            });
        }
        Ok(i)
    }
}

/// Depth pixels as they come in `sensor_msgs/Image`.
#[derive(Debug, Clone, Copy)]
pub enum Depth<'a> {
    /// `16UC1`: millimetres, 0 = no reading (little-endian bytes).
    Millimetres(&'a [u8]),
    /// `32FC1`: metres, NaN or 0 = no reading (little-endian bytes).
    Metres(&'a [u8]),
}

impl<'a> Depth<'a> {
    /// The image's pixels from its encoding, size, row step and data; `Err` names what is wrong
    /// (an encoding other than 16UC1 or 32FC1, big-endian data, a size other than the camera
    /// info's, or data shorter than the rows).
    pub fn from_image(
        encoding: &str,
        is_bigendian: u8,
        width: u32,
        height: u32,
        step: u32,
        data: &'a [u8],
        intr: &Intrinsics,
    ) -> Result<Self, InputError> {
        let bytes = match encoding {
            "16UC1" | "mono16" => 2,
            "32FC1" => 4,
            e => return Err(InputError::Encoding(e.to_owned())),
        };
        if is_bigendian != 0 {
            return Err(InputError::BigEndian);
        }
        if (width, height) != (intr.width, intr.height) {
            return Err(InputError::SizeMismatch {
                width,
                height,
                info_width: intr.width,
                info_height: intr.height,
            });
        }
        if step as usize != width as usize * bytes {
            return Err(InputError::RowStep {
                step,
                expected: width as usize * bytes,
            });
        }
        if data.len() != step as usize * height as usize {
            return Err(InputError::DataLength {
                len: data.len(),
                expected: step as usize * height as usize,
            });
        }
        Ok(if bytes == 2 {
            Self::Millimetres(data)
        } else {
            Self::Metres(data)
        })
    }

    /// Depth of pixel `i` (row-major; m); `None` without a reading.
    #[inline]
    pub fn depth_m(&self, i: usize) -> Option<f64> {
        let d = match self {
            Self::Millimetres(b) => u16::from_le_bytes([b[2 * i], b[2 * i + 1]]) as f64 * 1e-3,
            Self::Metres(b) => {
                f32::from_le_bytes([b[4 * i], b[4 * i + 1], b[4 * i + 2], b[4 * i + 3]]) as f64
            }
        };
        (d.is_finite() && d > 0.0).then_some(d)
    }
}

/// Settings of the projection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// Depth readings outside `[min_depth, max_depth]` are ignored (m).
    pub min_depth: f64,
    /// See `min_depth`.
    pub max_depth: f64,
    /// Heights below this are the floor: 0 (m).
    pub floor_threshold: f32,
    /// Unseen cells take the highest seen cell within this many cells.
    pub fill_radius: usize,
    /// Heights are clamped to `[0, max_height]` (m).
    pub max_height: f32,
}

/// What one frame's projection did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FrameStats {
    /// Pixels with a valid depth.
    pub valid_pixels: u32,
    /// Pixels whose point fell over the box interior.
    pub interior_points: u32,
    /// Cells filled from a neighbour (unseen).
    pub filled_near: u32,
    /// Cells filled with the frame's highest cell (nothing seen near them).
    pub filled_far: u32,
}

/// The projection's buffers, allocated once for a grid.
#[derive(Debug, Clone)]
pub struct Projector {
    spec: GridSpec,
    seen: Vec<bool>,
    scratch: Vec<f32>,
}

impl Projector {
    /// For heightmaps of grid `spec` (the box interior).
    pub fn new(spec: GridSpec) -> Self {
        Self {
            spec,
            seen: vec![false; spec.len()],
            scratch: vec![0.0; spec.len()],
        }
    }

    /// The grid.
    pub fn spec(&self) -> &GridSpec {
        &self.spec
    }

    /// Which cells the last projection saw (the others were filled).
    pub fn seen(&self) -> &[bool] {
        &self.seen
    }

    /// Writes the heightmap of `depth` (camera pose `b_from_c`: the optical frame, z along the
    /// view, in the box frame B) into `out` (`spec.len()` cells).
    pub fn project(
        &mut self,
        depth: &Depth<'_>,
        intr: &Intrinsics,
        b_from_c: &Isometry3<f64>,
        p: &Params,
        out: &mut [f32],
    ) -> FrameStats {
        let spec = self.spec;
        assert_eq!(out.len(), spec.len(), "heightmap buffer of the grid's size");
        out.fill(f32::NEG_INFINITY);
        self.seen.fill(false);
        let mut stats = FrameStats::default();
        let (w, h) = (intr.width as usize, intr.height as usize);
        for v in 0..h {
            for u in 0..w {
                let Some(d) = depth.depth_m(v * w + u) else {
                    continue;
                };
                if !(p.min_depth..=p.max_depth).contains(&d) {
                    continue;
                }
                stats.valid_pixels += 1;
                let c = Point3::new(
                    (u as f64 - intr.cx) / intr.fx * d,
                    (v as f64 - intr.cy) / intr.fy * d,
                    d,
                );
                let b = b_from_c * c;
                let (x, y) = (b.x as f32, b.y as f32);
                if x.abs() > BOX_HALF_X || y.abs() > BOX_HALF_Y {
                    continue;
                }
                let (cu, cv) = spec.to_pixel(x, y);
                let (col, row) = (cu.floor(), cv.floor());
                if col < 0.0 || row < 0.0 || col as usize >= spec.nx || row as usize >= spec.ny {
                    continue;
                }
                stats.interior_points += 1;
                let i = row as usize * spec.nx + col as usize;
                let z = b.z as f32;
                if z > out[i] {
                    out[i] = z;
                }
                self.seen[i] = true;
            }
        }
        // Floor, clamp and the conservative fill of unseen cells: the camera contract's one
        // implementation, shared with the evaluation's field camera.
        let fill = finish_camera_cells(
            &spec,
            out,
            &self.seen,
            (p.floor_threshold, p.max_height, p.fill_radius),
            &mut self.scratch,
        );
        stats.filled_near = fill.near;
        stats.filled_far = fill.far;
        stats
    }
}

/// Per-cell median of the last `n` heightmaps (`n` = 1: the latest as is).
#[derive(Debug, Clone)]
pub struct Median {
    frames: Vec<Vec<f32>>,
    next: usize,
    filled: usize,
    column: Vec<f32>,
}

impl Median {
    /// Over `n` frames (at least 1) of `cells` cells.
    pub fn new(n: usize, cells: usize) -> Self {
        Self {
            frames: vec![vec![0.0; cells]; n.max(1)],
            next: 0,
            filled: 0,
            column: Vec::with_capacity(n.max(1)),
        }
    }

    /// Adds `hm` and writes the median of the frames held (fewer than `n` at start) to `out`.
    pub fn push(&mut self, hm: &[f32], out: &mut [f32]) {
        let n = self.frames.len();
        self.frames[self.next].copy_from_slice(hm);
        self.next = (self.next + 1) % n;
        self.filled = (self.filled + 1).min(n);
        for (i, o) in out.iter_mut().enumerate() {
            self.column.clear();
            self.column
                .extend(self.frames[..self.filled].iter().map(|f| f[i]));
            self.column.sort_unstable_by(f32::total_cmp);
            *o = self.column[self.column.len() / 2];
        }
    }
}
