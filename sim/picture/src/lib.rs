//! Pictures for people: the final pack of a job as a top view (heightmap in colour with a
//! height scale, the box, each object's bounds and name, objects outside the success volume
//! marked in red) above a side view (x-z: the objects' bounds, the box walls, the top of the
//! success volume).
//!
//! Text needs a TrueType font, read at run time from `$HERB_FONT` or the DejaVu Sans path of
//! Debian/Ubuntu (`fonts-dejavu-core`): [`register_font`], shared with the Table I plots.

#![warn(missing_docs)]

pub mod chart;

pub use chart::{IntervalRow, write_interval_chart};

use herb_core::frames::{BOX_HALF_X, BOX_HALF_Y, BOX_HEIGHT, SUCCESS_TOP_Z};
use herb_core::heightmap::Heightmap;
use plotters::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The font read when `$HERB_FONT` is not set.
pub const DEFAULT_FONT: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

/// What kept a picture, or the font it needs, from being made.
#[derive(Debug, Clone, thiserror::Error)]
pub enum PictureError {
    /// The font file could not be read.
    #[error(
        "font {}: {source} (set HERB_FONT to a .ttf file, or install fonts-dejavu-core)",
        .path.display()
    )]
    FontUnreadable {
        /// The font file (`$HERB_FONT` or [`DEFAULT_FONT`]).
        path: PathBuf,
        /// The I/O error.
        source: Arc<std::io::Error>,
    },
    /// The font file is not a TrueType font plotters can use.
    #[error("font {}: not a usable TrueType font", .path.display())]
    FontUnusable {
        /// The font file.
        path: PathBuf,
    },
    /// The picture's folder could not be made.
    #[error("{}: {source}", .dir.display())]
    Folder {
        /// The folder.
        dir: PathBuf,
        /// The I/O error.
        source: Arc<std::io::Error>,
    },
    /// Drawing or writing the picture failed.
    #[error("{}: {message}", .path.display())]
    Draw {
        /// The picture file.
        path: PathBuf,
        /// What plotters reported.
        message: String,
    },
}

/// Registers the font plotters draws text with (once per process; later calls do nothing and
/// return the first call's result).
pub fn register_font() -> Result<(), PictureError> {
    static DONE: std::sync::OnceLock<Result<(), PictureError>> = std::sync::OnceLock::new();
    DONE.get_or_init(|| {
        let path =
            PathBuf::from(std::env::var("HERB_FONT").unwrap_or_else(|_| DEFAULT_FONT.into()));
        let bytes = std::fs::read(&path).map_err(|e| PictureError::FontUnreadable {
            path: path.clone(),
            source: Arc::new(e),
        })?;
        // plotters keeps the font for the life of the process.
        let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
        plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
            .map_err(|_| PictureError::FontUnusable { path })
    })
    .clone()
}

/// One object of the pack as the picture shows it (frame B, metres).
#[derive(Debug, Clone, PartialEq)]
pub struct PictureObject {
    /// Short label (placement number and catalog id, e.g. `3 011`).
    pub label: String,
    /// Lowest corner of its bounds.
    pub lo: [f32; 3],
    /// Highest corner of its bounds.
    pub hi: [f32; 3],
    /// `Some((bound, metres))` when it is outside the success volume.
    pub outside: Option<(String, f32)>,
}

/// A colour for `t` in `0..=1`: dark blue through teal and green to yellow (viridis-like,
/// readable in grey and by most colour-blind readers).
pub fn height_colour(t: f32) -> RGBColor {
    const STOPS: [(f32, [f32; 3]); 5] = [
        (0.00, [68.0, 1.0, 84.0]),
        (0.25, [59.0, 82.0, 139.0]),
        (0.50, [33.0, 145.0, 140.0]),
        (0.75, [94.0, 201.0, 98.0]),
        (1.00, [253.0, 231.0, 37.0]),
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let k = STOPS.iter().rposition(|s| s.0 <= t).unwrap_or(0).min(3);
    let (a, b) = (STOPS[k], STOPS[k + 1]);
    let u = (t - a.0) / (b.0 - a.0);
    let c: [u8; 3] = std::array::from_fn(|i| (a.1[i] + u * (b.1[i] - a.1[i])).round() as u8);
    RGBColor(c[0], c[1], c[2])
}

type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// Writes the final-pack picture of `hm` and `objects` to `path` (PNG), with `title` on top.
/// Heights are coloured from the floor to the top of the success volume.
pub fn write_pack_picture(
    path: &Path,
    title: &str,
    hm: &Heightmap,
    objects: &[PictureObject],
) -> Result<(), PictureError> {
    write_with(path, |path| draw(path, title, hm, objects))
}

/// Registers the font, makes `path`'s folder and draws the picture with `draw`, its errors
/// named with the path: how every picture of this crate is written.
fn write_with(path: &Path, draw: impl FnOnce(&Path) -> DrawResult) -> Result<(), PictureError> {
    register_font()?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| PictureError::Folder {
            dir: dir.to_owned(),
            source: Arc::new(e),
        })?;
    }
    draw(path).map_err(|e| PictureError::Draw {
        path: path.to_owned(),
        message: e.to_string(),
    })
}

fn draw(path: &Path, title: &str, hm: &Heightmap, objects: &[PictureObject]) -> DrawResult {
    let root = BitMapBackend::new(path, (1000, 1040)).into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(title, ("sans-serif", 22))?;
    let (top, side) = root.split_vertically(640);
    let (top_map, scale) = top.split_horizontally(860);
    let max_m = SUCCESS_TOP_Z;
    let (mx, my) = (BOX_HALF_X + 0.06, BOX_HALF_Y + 0.05);

    // Top view.
    let mut chart = ChartBuilder::on(&top_map)
        .caption("top view (heightmap)", ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(55)
        .build_cartesian_2d(-mx..mx, -my..my)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("x (m)")
        .y_desc("y (m)")
        .label_style(("sans-serif", 14))
        .draw()?;
    let spec = *hm.spec();
    let half = spec.cell / 2.0;
    chart.draw_series((0..spec.ny).flat_map(|row| {
        (0..spec.nx).map(move |col| {
            let (x, y) = spec.cell_centre(col, row);
            let v = hm.data()[row * spec.nx + col];
            Rectangle::new(
                [(x - half, y - half), (x + half, y + half)],
                height_colour(v / max_m).filled(),
            )
        })
    }))?;
    chart.draw_series(std::iter::once(Rectangle::new(
        [(-BOX_HALF_X, -BOX_HALF_Y), (BOX_HALF_X, BOX_HALF_Y)],
        BLACK.stroke_width(3),
    )))?;
    for o in objects {
        let colour = if o.outside.is_some() { RED } else { WHITE };
        chart.draw_series(std::iter::once(Rectangle::new(
            [(o.lo[0], o.lo[1]), (o.hi[0], o.hi[1])],
            colour.stroke_width(if o.outside.is_some() { 3 } else { 1 }),
        )))?;
        let (cx, cy) = ((o.lo[0] + o.hi[0]) / 2.0, (o.lo[1] + o.hi[1]) / 2.0);
        let text = match &o.outside {
            Some((bound, m)) => format!("{} OUT {bound} {:.0} mm", o.label, m * 1000.0),
            None => o.label.clone(),
        };
        chart.draw_series(std::iter::once(Text::new(
            text,
            (cx - 0.01, cy),
            ("sans-serif", 14).into_font().color(&colour),
        )))?;
    }

    // Height scale.
    let mut bar = ChartBuilder::on(&scale)
        .margin_top(40)
        .margin_bottom(50)
        .margin_right(10)
        .y_label_area_size(75)
        .build_cartesian_2d(0f32..1f32, 0f32..max_m)?;
    bar.configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_desc("height (m)")
        .y_label_style(("sans-serif", 14))
        .axis_desc_style(("sans-serif", 14))
        .draw()?;
    let steps = 100;
    bar.draw_series((0..steps).map(|i| {
        let (a, b) = (
            i as f32 / steps as f32 * max_m,
            (i + 1) as f32 / steps as f32 * max_m,
        );
        Rectangle::new(
            [(0.0, a), (1.0, b)],
            height_colour((a + b) / 2.0 / max_m).filled(),
        )
    }))?;

    // Side view.
    let mut chart = ChartBuilder::on(&side)
        .caption(
            "side view (x-z; dashed: top of the success volume)",
            ("sans-serif", 18),
        )
        .margin(10)
        .margin_right(130)
        .x_label_area_size(40)
        .y_label_area_size(55)
        .build_cartesian_2d(-mx..mx, -0.02f32..SUCCESS_TOP_Z + 0.05)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("x (m)")
        .y_desc("z (m)")
        .label_style(("sans-serif", 14))
        .draw()?;
    for o in objects {
        let colour = if o.outside.is_some() { RED } else { BLUE };
        chart.draw_series(std::iter::once(Rectangle::new(
            [(o.lo[0], o.lo[2]), (o.hi[0], o.hi[2])],
            colour.mix(0.25).filled(),
        )))?;
        chart.draw_series(std::iter::once(Rectangle::new(
            [(o.lo[0], o.lo[2]), (o.hi[0], o.hi[2])],
            colour.stroke_width(1),
        )))?;
    }
    let wall = |x: f32| PathElement::new(vec![(x, 0.0), (x, BOX_HEIGHT)], BLACK.stroke_width(3));
    chart.draw_series([
        wall(-BOX_HALF_X),
        wall(BOX_HALF_X),
        PathElement::new(
            vec![(-BOX_HALF_X, 0.0), (BOX_HALF_X, 0.0)],
            BLACK.stroke_width(3),
        ),
    ])?;
    // Dashed: short segments along the top of the success volume.
    let n = 40;
    chart.draw_series((0..n).step_by(2).map(|i| {
        let x = |k: i32| -BOX_HALF_X + 2.0 * BOX_HALF_X * k as f32 / n as f32;
        PathElement::new(
            vec![(x(i), SUCCESS_TOP_Z), (x(i + 1), SUCCESS_TOP_Z)],
            BLACK.stroke_width(2),
        )
    }))?;
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pack_picture_is_drawn_with_an_object_outside() {
        use herb_core::heightmap::GridSpec;
        let spec = GridSpec::for_box(0.005).unwrap();
        let mut hm = Heightmap::new(spec);
        for (i, v) in hm.data_mut().iter_mut().enumerate() {
            *v = (i % spec.nx) as f32 / spec.nx as f32 * 0.2;
        }
        let objects = [
            PictureObject {
                label: "1 003".into(),
                lo: [-0.15, -0.1, 0.0],
                hi: [-0.05, 0.0, 0.2],
                outside: None,
            },
            PictureObject {
                label: "2 011 (fixture)".into(),
                lo: [0.1, 0.0, 0.0],
                hi: [0.19, 0.05, 0.04],
                outside: Some(("+x wall".into(), 0.017)),
            },
        ];
        let path = std::env::temp_dir().join(format!("herb-picture-{}.png", std::process::id()));
        write_pack_picture(&path, "FAILED: fixture", &hm, &objects).unwrap();
        let decoder =
            png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&path).unwrap()));
        let info = decoder.read_info().unwrap();
        assert_eq!((info.info().width, info.info().height), (1000, 1040));
        std::fs::remove_file(&path).unwrap();
        // A path that cannot be written is an error naming it, not a panic.
        let bad = Path::new("/proc/herb-no/pack.png");
        assert!(
            write_pack_picture(bad, "x", &hm, &objects)
                .unwrap_err()
                .to_string()
                .contains("/proc/herb-no")
        );
    }

    #[test]
    fn the_colour_scale_runs_from_dark_to_light_and_clamps() {
        let lum = |c: RGBColor| 0.2126 * c.0 as f32 + 0.7152 * c.1 as f32 + 0.0722 * c.2 as f32;
        let v: Vec<f32> = (0..=10)
            .map(|i| lum(height_colour(i as f32 / 10.0)))
            .collect();
        assert!(v.windows(2).all(|w| w[1] > w[0]), "{v:?}");
        assert_eq!(height_colour(-1.0), height_colour(0.0));
        assert_eq!(height_colour(2.0), height_colour(1.0));
        assert_eq!(height_colour(f32::NAN), height_colour(0.0));
    }
}
