//! A chart of values with their intervals, one horizontal bar per labelled row (a sweep's
//! configurations: success with its 95 % interval, objects packed...).

use crate::{DrawResult, PictureError};
use plotters::prelude::*;
use std::path::Path;

/// One bar: its label, its value and the interval drawn around it.
#[derive(Debug, Clone, PartialEq)]
pub struct IntervalRow {
    /// The row's label (left of its bar).
    pub label: String,
    /// The bar's length.
    pub value: f64,
    /// The interval's low end.
    pub lo: f64,
    /// The interval's high end.
    pub hi: f64,
}

/// Writes a chart of `rows` (top to bottom in the order given) to `path` (PNG): each a bar from
/// 0 to its value with its interval as an error bar, on an axis from 0 to `x_max` named
/// `x_label`, under `title`.
pub fn write_interval_chart(
    path: &Path,
    title: &str,
    x_label: &str,
    x_max: f64,
    rows: &[IntervalRow],
) -> Result<(), PictureError> {
    crate::write_with(path, |path| draw(path, title, x_label, x_max, rows))
}

fn draw(path: &Path, title: &str, x_label: &str, x_max: f64, rows: &[IntervalRow]) -> DrawResult {
    let n = rows.len().max(1);
    let root = BitMapBackend::new(path, (1100, 90 + 30 * n as u32)).into_drawing_area();
    root.fill(&WHITE)?;
    // Row i is drawn at y = n - 1 - i, so the first row is on top.
    let y_of = |i: usize| (n - 1 - i) as f64;
    let label_of = |y: &f64| {
        let k = y.round();
        if (y - k).abs() > 1e-6 || k < 0.0 || k as usize >= n {
            return String::new();
        }
        rows.get(n - 1 - k as usize)
            .map(|r| r.label.clone())
            .unwrap_or_default()
    };
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(10)
        .margin_right(40)
        .x_label_area_size(36)
        .y_label_area_size(520)
        .build_cartesian_2d(0.0f64..x_max.max(1e-9), -0.6f64..n as f64 - 0.4)?;
    chart
        .configure_mesh()
        .disable_y_mesh()
        .y_labels(n)
        .y_label_formatter(&label_of)
        .x_desc(x_label)
        .draw()?;
    chart.draw_series(rows.iter().enumerate().map(|(i, r)| {
        let y = y_of(i);
        Rectangle::new(
            [(0.0, y - 0.3), (r.value, y + 0.3)],
            BLUE.mix(0.45).filled(),
        )
    }))?;
    // The interval: a line from lo to hi with a tick at each end.
    for (i, r) in rows.iter().enumerate() {
        let y = y_of(i);
        let style = BLACK.stroke_width(2);
        chart.draw_series([
            PathElement::new(vec![(r.lo, y), (r.hi, y)], style),
            PathElement::new(vec![(r.lo, y - 0.15), (r.lo, y + 0.15)], style),
            PathElement::new(vec![(r.hi, y - 0.15), (r.hi, y + 0.15)], style),
        ])?;
    }
    root.present()?;
    Ok(())
}
