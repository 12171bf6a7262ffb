//! The plots of `mocapstore bench`, over the totals of the benchmarked takes: rate against
//! distortion (bits per frame against the max-error bound, one line per codec), and speed
//! (encode and decode frames/s per codec). Both on log axes: codecs differ by orders of
//! magnitude in size at tight bounds and in speed, and a linear axis hides all but the
//! largest.

use std::path::Path;

use plotters::prelude::*;

use super::Row;

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
    register_font();
    let mut series: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    for r in totals {
        if r.bound.mean_mm().is_some() {
            continue;
        }
        let b = r.bound.max_mm();
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
    let all = || series.iter().flat_map(|(_, p)| p.iter());
    let (xmin, xmax) = range(all().map(|p| p.0));
    let (ymin, ymax) = range(all().map(|p| p.1));
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
        .build_cartesian_2d((xmin..xmax).log_scale(), (ymin..ymax).log_scale())
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("bits per frame, log scale (lower is better)")
        .y_desc("max error bound (mm), log scale")
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
    legend(&mut chart, SeriesLabelPosition::MiddleRight).map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))
}

/// The bitmap backend draws text with a font we embed, so no system fonts are needed.
fn register_font() {
    let _ =
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
}

/// Both charts' legend, at `position`.
fn legend<'a, X: Ranged, Y: Ranged>(
    chart: &mut ChartContext<'a, BitMapBackend<'a>, Cartesian2d<X, Y>>,
    position: SeriesLabelPosition,
) -> Result<(), String> {
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 16))
        .draw()
        .map_err(|e| e.to_string())
}

/// A log axis's range around positive values: a little room either side.
fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold((f64::INFINITY, 0f64), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if hi <= 0.0 {
        return (0.1, 1.0);
    }
    (lo / 1.25, hi * 1.25)
}

/// Encode and decode frames/s of each codec (one row per label, one dot per bound; the
/// decoder built beforehand, as a server keeps it), on a log axis.
pub fn speed(totals: &[Row], path: &Path) -> Result<(), String> {
    register_font();
    let mut labels: Vec<String> = Vec::new();
    let mut points: Vec<(usize, f64, f64)> = Vec::new();
    for r in totals {
        let i = match labels.iter().position(|l| *l == r.label) {
            Some(i) => i,
            None => {
                labels.push(r.label.clone());
                labels.len() - 1
            }
        };
        let fps = |s: f64| {
            if s > 0.0 {
                r.frames as f64 / s
            } else {
                f64::NAN
            }
        };
        points.push((i, fps(r.encode_s), fps(r.decode_s)));
    }
    if labels.is_empty() {
        return Ok(());
    }
    let (xmin, xmax) = range(points.iter().flat_map(|p| [p.1, p.2]));
    let height = 160 + 48 * labels.len() as u32;
    let root = BitMapBackend::new(path, (900, height)).into_drawing_area();
    let err = |e: &dyn std::fmt::Display| format!("{}: {e}", path.display());
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let n = labels.len();
    let mut chart = ChartBuilder::on(&root)
        .caption("Speed (all benchmarked takes, 1 core)", ("sans-serif", 24))
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(220)
        .build_cartesian_2d((xmin..xmax).log_scale(), -0.5f64..n as f64 - 0.5)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("frames per second, log scale (higher is better)")
        .x_label_formatter(&|x| si(*x))
        .y_labels(n)
        .y_label_formatter(&|y| {
            let i = y.round();
            if (y - i).abs() < 1e-6 && i >= 0.0 {
                labels.get(i as usize).cloned().unwrap_or_default()
            } else {
                String::new()
            }
        })
        .label_style(("sans-serif", 15))
        .draw()
        .map_err(|e| err(&e))?;
    let (enc, dec) = (COLOURS[0], COLOURS[1]);
    let at = |i: usize, shift: f64| i as f64 + shift;
    chart
        .draw_series(
            points
                .iter()
                .filter(|p| p.1.is_finite())
                .map(|&(i, e, _)| Circle::new((e, at(i, -0.12)), 5, enc.filled())),
        )
        .map_err(|e| err(&e))?
        .label("encode")
        .legend(move |(x, y)| Circle::new((x + 10, y), 5, enc.filled()));
    chart
        .draw_series(
            points
                .iter()
                .filter(|p| p.2.is_finite())
                .map(|&(i, _, d)| TriangleMarker::new((d, at(i, 0.12)), 6, dec.filled())),
        )
        .map_err(|e| err(&e))?
        .label("decode")
        .legend(move |(x, y)| TriangleMarker::new((x + 10, y), 6, dec.filled()));
    legend(&mut chart, SeriesLabelPosition::UpperMiddle).map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))
}

/// `12000` as `12k`, `3000000` as `3M`: axis labels a reader takes in at a glance.
fn si(x: f64) -> String {
    let (v, unit) = if x >= 1e6 {
        (x / 1e6, "M")
    } else if x >= 1e3 {
        (x / 1e3, "k")
    } else {
        (x, "")
    };
    let digits = if v < 10.0 && v.fract().abs() > 1e-9 {
        1
    } else {
        0
    };
    format!("{v:.digits$}{unit}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_and_ranges_for_log_axes() {
        assert_eq!(si(10_000.0), "10k");
        assert_eq!(si(2_500.0), "2.5k");
        assert_eq!(si(3_000_000.0), "3M");
        assert_eq!(si(100.0), "100");
        let (lo, hi) = range([4.0, 0.0, f64::NAN, 100.0].into_iter());
        assert!(lo > 0.0 && lo < 4.0 && hi > 100.0);
        assert_eq!(range(std::iter::empty()), (0.1, 1.0));
    }
}
