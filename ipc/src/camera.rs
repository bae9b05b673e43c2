//! The camera: heightmap frames of the box interior.

use crate::base::*;
use iceoryx2::prelude::*;

/// A heightmap of the box interior from the camera adapter (or the loopback): row-major, row 0
/// at +y, column 0 at -x, cells of `cell_m` centred on the box (`herb_sim::GridSpec`).
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v2::HeightmapFrame")]
pub struct HeightmapFrame {
    /// Header; the stamp is the capture time.
    pub header: Header,
    /// Columns (along B x).
    pub nx: u32,
    /// Rows (along B y).
    pub ny: u32,
    /// Cell side (m).
    pub cell_m: f32,
    /// Objects in the box when captured, if the source knows (the loopback), else 0.
    pub objects: u32,
    /// Heights above the inner floor (m); the first `nx * ny` values are used.
    pub data: [f32; HEIGHTMAP_MAX_CELLS],
}
payload!(HeightmapFrame);

impl HeightmapFrame {
    /// The used cells.
    pub fn cells(&self) -> &[f32] {
        &self.data[..(self.nx as usize * self.ny as usize).min(HEIGHTMAP_MAX_CELLS)]
    }

    /// Header, grid size and cell side only (cheap; for a loop that only tracks freshness).
    pub fn validate_meta(&self) -> Result<(), Invalid> {
        self.header.validate()?;
        let n = self.nx as u64 * self.ny as u64;
        if self.nx == 0 || self.ny == 0 || n > HEIGHTMAP_MAX_CELLS as u64 {
            return Err(Invalid::new("nx*ny", Reason::BadLength));
        }
        within(
            "cell_m",
            &[self.cell_m],
            CELL_M_RANGE.0 as f64,
            CELL_M_RANGE.1 as f64,
        )
    }

    /// [`Self::validate_meta`] plus every used cell finite and within [`HEIGHT_RANGE_M`].
    pub fn validate(&self) -> Result<(), Invalid> {
        self.validate_meta()?;
        let (lo, hi) = HEIGHT_RANGE_M;
        within("data", self.cells(), lo as f64, hi as f64)
    }
}
