//! PNG pictures of heightmaps (8-bit grayscale, white = high).

use crate::error::{Result, SimError};
use crate::heightmap::Heightmap;
use std::path::Path;

/// Writes `hm` as a grayscale PNG, `upscale` pixels per cell, black = floor, white = `max_m`
/// or higher. Row 0 (+y) is the image top, x runs to the right.
pub fn write_heightmap_png(path: &Path, hm: &Heightmap, max_m: f32, upscale: usize) -> Result<()> {
    let err = |message: String| SimError::Output {
        path: path.to_owned(),
        message,
    };
    if max_m.is_nan() || max_m <= 0.0 || upscale == 0 || upscale > 16 {
        return Err(err(format!("bad scale (max_m {max_m}, upscale {upscale})")));
    }
    let spec = hm.spec();
    let (w, h) = (spec.nx * upscale, spec.ny * upscale);
    let mut pixels = vec![0u8; w * h];
    for (i, px) in pixels.iter_mut().enumerate() {
        let (x, y) = (i % w / upscale, i / w / upscale);
        let v = hm.data()[y * spec.nx + x] / max_m;
        *px = (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| err(e.to_string()))?;
    }
    let file = std::fs::File::create(path).map_err(|e| err(e.to_string()))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), w as u32, h as u32);
    enc.set_color(png::ColorType::Grayscale);
    enc.set_depth(png::BitDepth::Eight);
    let mut writer = enc.write_header().map_err(|e| err(e.to_string()))?;
    writer
        .write_image_data(&pixels)
        .map_err(|e| err(e.to_string()))?;
    writer.finish().map_err(|e| err(e.to_string()))
}
