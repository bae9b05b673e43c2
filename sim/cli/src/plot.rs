//! Table I plots: compactness per step and a histogram of objects packed, per method.
//!
//! Text needs a TrueType font, read at run time from `$HERB_FONT` or the DejaVu Sans path of
//! Debian/Ubuntu (`fonts-dejavu-core`): `herb_picture::register_font`.

use herb_sim::eval::{EpisodeOutcome, EpisodeResult};
use plotters::prelude::*;
use std::path::{Path, PathBuf};

type Results = [(String, Vec<EpisodeOutcome>)];

/// Writes `compactness_per_step.png` and `objects_packed.png` into `dir`.
pub fn write_plots(dir: &Path, results: &Results) -> Result<Vec<PathBuf>, String> {
    herb_picture::register_font().map_err(|e| e.to_string())?;
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let a = dir.join("compactness_per_step.png");
    compactness_per_step(&a, results).map_err(|e| format!("{}: {e}", a.display()))?;
    let b = dir.join("objects_packed.png");
    objects_packed(&b, results).map_err(|e| format!("{}: {e}", b.display()))?;
    Ok(vec![a, b])
}

/// Mean C after step k (1-based) over the episodes that made at least k placements.
fn mean_compactness(results: &[EpisodeOutcome]) -> Vec<(u32, f64)> {
    let ok: Vec<&EpisodeResult> = results.iter().filter_map(|r| r.as_ref().ok()).collect();
    let max = ok
        .iter()
        .map(|r| r.compactness_per_step.len())
        .max()
        .unwrap_or(0);
    (0..max)
        .filter_map(|k| {
            let v: Vec<f64> = ok
                .iter()
                .filter_map(|r| r.compactness_per_step.get(k).map(|&c| c as f64))
                .collect();
            (!v.is_empty()).then(|| (k as u32 + 1, v.iter().sum::<f64>() / v.len() as f64))
        })
        .collect()
}

fn compactness_per_step(path: &Path, results: &Results) -> Result<(), Box<dyn std::error::Error>> {
    let root = BitMapBackend::new(path, (900, 560)).into_drawing_area();
    root.fill(&WHITE)?;
    let series: Vec<(String, Vec<(u32, f64)>)> = results
        .iter()
        .map(|(name, r)| (name.clone(), mean_compactness(r)))
        .collect();
    let max_k = series
        .iter()
        .flat_map(|(_, s)| s.iter().map(|p| p.0))
        .max()
        .unwrap_or(1);
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Compactness per step (mean over episodes still running)",
            ("sans-serif", 22),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(1u32..max_k.max(2), 0.0f64..1.0)?;
    chart
        .configure_mesh()
        .x_desc("placement")
        .y_desc("C")
        .draw()?;
    for (i, (name, s)) in series.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        chart
            .draw_series(LineSeries::new(s.iter().copied(), color.stroke_width(2)))?
            .label(name.as_str())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

fn objects_packed(path: &Path, results: &Results) -> Result<(), Box<dyn std::error::Error>> {
    let n = results.len().max(1);
    let root = BitMapBackend::new(path, (900, 220 * n as u32)).into_drawing_area();
    root.fill(&WHITE)?;
    let max_objects = results
        .iter()
        .flat_map(|(_, r)| r.iter().filter_map(|e| e.as_ref().ok()).map(|e| e.objects))
        .max()
        .unwrap_or(1) as u32;
    for ((name, r), area) in results.iter().zip(root.split_evenly((n, 1))) {
        let mut counts = vec![0u32; max_objects as usize + 1];
        for e in r.iter().filter_map(|e| e.as_ref().ok()) {
            counts[e.packed.min(max_objects as usize)] += 1;
        }
        let top = counts.iter().copied().max().unwrap_or(1).max(1);
        let mut chart = ChartBuilder::on(&area)
            .caption(
                format!("{name}: objects packed per episode"),
                ("sans-serif", 18),
            )
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(45)
            .build_cartesian_2d(0u32..max_objects + 1, 0u32..top + top / 10 + 1)?;
        chart
            .configure_mesh()
            .x_desc("objects packed")
            .y_desc("episodes")
            .draw()?;
        chart.draw_series(counts.iter().enumerate().map(|(k, &c)| {
            let k = k as u32;
            Rectangle::new([(k, 0), (k + 1, c)], BLUE.mix(0.6).filled())
        }))?;
    }
    root.present()?;
    Ok(())
}
