//! The rate–distortion plot of `mocapstore bench`: bits per frame against the max-error
//! bound, one line per codec, over the totals of the benchmarked takes.

use std::path::Path;

use plotters::prelude::*;

use super::Row;
use mocapstore::codec::ErrorBound;

const COLOURS: [RGBColor; 7] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(127, 127, 127),
];

/// Draw `totals` (one row per codec and bound) to a PNG; rows with mean bounds and codecs
/// with fewer than two max bounds are left out.
pub fn rate_distortion(totals: &[Row], path: &Path) -> Result<(), String> {
    // The bitmap backend draws text with a font we embed, so no system fonts are needed.
    let _ =
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
    let mut series: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    for r in totals {
        let ErrorBound::MaxMm(b) = r.bound else {
            continue;
        };
        let bpf = r.stored_bytes as f64 * 8.0 / r.frames as f64;
        match series.iter_mut().find(|(c, _)| *c == r.label) {
            Some((_, pts)) => pts.push((bpf, b)),
            None => series.push((r.label.clone(), vec![(bpf, b)])),
        }
    }
    series.retain(|(_, pts)| pts.len() >= 2);
    if series.is_empty() {
        return Ok(());
    }
    for (_, pts) in &mut series {
        pts.sort_by(|a, b| a.1.total_cmp(&b.1));
    }
    let all = series.iter().flat_map(|(_, p)| p.iter());
    let (xmax, ymax) = all.fold((1.0f64, 0.1f64), |(x, y), p| (x.max(p.0), y.max(p.1)));
    let root = BitMapBackend::new(path, (900, 600)).into_drawing_area();
    let err = |e: &dyn std::fmt::Display| format!("{}: {e}", path.display());
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Rate–distortion (all benchmarked takes)",
            ("sans-serif", 24),
        )
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(64)
        .build_cartesian_2d(0f64..xmax * 1.05, 0f64..ymax * 1.1)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("bits per frame (lower is better)")
        .y_desc("max error bound (mm)")
        .label_style(("sans-serif", 15))
        .draw()
        .map_err(|e| err(&e))?;
    for (i, (name, pts)) in series.iter().enumerate() {
        let colour = COLOURS[i % COLOURS.len()];
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), colour.stroke_width(2)))
            .map_err(|e| err(&e))?
            .label(name.clone())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
            });
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 4, colour.filled())))
            .map_err(|e| err(&e))?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 16))
        .draw()
        .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))
}
