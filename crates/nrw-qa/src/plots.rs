//! Charts as SVG strings (plotters' SVG backend: text is drawn by the browser, so no font
//! files are needed), inlined into the report.

use plotters::prelude::*;

use crate::error::{QaError, Result};

const W: u32 = 460;
const H: u32 = 280;
/// Colours of the series, colour-blind safe (Okabe–Ito).
pub const PALETTE: [RGBColor; 6] = [
    RGBColor(0, 114, 178),
    RGBColor(230, 159, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(86, 180, 233),
    RGBColor(213, 94, 0),
];

fn chart_err(chart: &str, e: impl std::fmt::Display) -> QaError {
    QaError::Chart {
        chart: chart.into(),
        problem: e.to_string(),
    }
}

/// Tick labels: counts only at whole numbers (no "1, 1, 2, 2" from fractional ticks).
fn count_tick(v: &f64) -> String {
    if (v - v.round()).abs() < 1e-9 {
        format!("{v:.0}")
    } else {
        String::new()
    }
}

/// Tick labels with as many decimals as the axis span needs.
fn tick(span: f64) -> impl Fn(&f64) -> String {
    let decimals = if span >= 20.0 {
        0
    } else if span >= 2.0 {
        1
    } else if span >= 0.02 {
        2
    } else {
        4
    };
    move |v: &f64| {
        if span < 2e-4 {
            format!("{v:.2e}")
        } else {
            format!("{v:.decimals$}")
        }
    }
}

/// Bin `values` into `bins` equal bins over [lo, hi] (values outside are clamped in).
fn bin(values: &[f64], lo: f64, hi: f64, bins: usize) -> Vec<f64> {
    let mut c = vec![0f64; bins];
    let w = (hi - lo).max(f64::MIN_POSITIVE);
    for v in values.iter().filter(|v| v.is_finite()) {
        let b = (((v - lo) / w) * bins as f64)
            .floor()
            .clamp(0.0, bins as f64 - 1.0);
        c[b as usize] += 1.0;
    }
    c
}

/// A histogram of one or more series over a shared range, with optional vertical marker lines
/// (thresholds); several series are drawn side by side within each bin.
pub fn histogram(
    title: &str,
    x_desc: &str,
    series: &[(&str, &[f64])],
    range: Option<(f64, f64)>,
    markers: &[(&str, f64)],
) -> Result<String> {
    let (lo, hi) = histogram_range(series, range, markers);
    let bins = 20;
    let counts: Vec<Vec<f64>> = series.iter().map(|s| bin(s.1, lo, hi, bins)).collect();
    let top = counts.iter().flatten().fold(1f64, |m, v| m.max(*v)) * 1.1;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (W, H)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| chart_err(title, e))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(36)
            .y_label_area_size(44)
            .build_cartesian_2d(lo..hi, 0f64..top)
            .map_err(|e| chart_err(title, e))?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_desc(x_desc)
            .x_label_formatter(&tick(hi - lo))
            .y_desc("photos")
            .y_label_formatter(&count_tick)
            .draw()
            .map_err(|e| chart_err(title, e))?;
        let bw = (hi - lo) / bins as f64;
        let ns = series.len().max(1) as f64;
        for (si, (name, _)) in series.iter().enumerate() {
            let color = PALETTE[si % PALETTE.len()];
            let c = &counts[si];
            chart
                .draw_series((0..bins).filter(|b| c[*b] > 0.0).map(|b| {
                    let x0 = lo + b as f64 * bw + bw * si as f64 / ns;
                    Rectangle::new([(x0, 0.0), (x0 + bw / ns * 0.9, c[b])], color.filled())
                }))
                .map_err(|e| chart_err(title, e))?
                .label(*name)
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 5), (x + 10, y + 5)], color.filled())
                });
        }
        for (label, m) in markers {
            chart
                .draw_series(LineSeries::new([(*m, 0.0), (*m, top)], RED.stroke_width(2)))
                .map_err(|e| chart_err(title, e))?
                .label(*label)
                .legend(|(x, y)| PathElement::new([(x, y), (x + 12, y)], RED.stroke_width(2)));
        }
        if series.len() > 1 || !markers.is_empty() {
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK.mix(0.3))
                .position(SeriesLabelPosition::UpperLeft)
                .draw()
                .map_err(|e| chart_err(title, e))?;
        }
        root.present().map_err(|e| chart_err(title, e))?;
    }
    Ok(svg)
}

/// A histogram's x range: `range`, else the finite values' span, widened to show every
/// marker; [0, 1] when nothing is finite, and never empty.
fn histogram_range(
    series: &[(&str, &[f64])],
    range: Option<(f64, f64)>,
    markers: &[(&str, f64)],
) -> (f64, f64) {
    let all: Vec<f64> = series
        .iter()
        .flat_map(|s| s.1.iter().copied())
        .filter(|v| v.is_finite())
        .collect();
    let (mut lo, mut hi) = range.unwrap_or_else(|| {
        all.iter()
            .fold((f64::MAX, f64::MIN), |(l, h), v| (l.min(*v), h.max(*v)))
    });
    for (_, m) in markers {
        lo = lo.min(*m);
        hi = hi.max(*m);
    }
    if !(lo.is_finite() && hi.is_finite()) {
        (lo, hi) = (0.0, 1.0);
    }
    if hi <= lo {
        hi = lo + 1.0;
    }
    (lo, hi)
}

/// Bars of counts by category (e.g. drop reasons).
pub fn bars(title: &str, bars: &[(String, f64)]) -> Result<String> {
    let top = bars.iter().fold(1f64, |m, b| m.max(b.1)) * 1.15;
    let n = bars.len().max(1);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (W, H)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| chart_err(title, e))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(36)
            .y_label_area_size(44)
            .build_cartesian_2d(0f64..n as f64, 0f64..top)
            .map_err(|e| chart_err(title, e))?;
        let labels: Vec<String> = bars.iter().map(|b| b.0.clone()).collect();
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(n * 2 + 1)
            .x_label_formatter(&|x| {
                let i = x.floor() as usize;
                if (x - i as f64 - 0.5).abs() < 1e-6 && i < labels.len() {
                    labels[i].clone()
                } else {
                    String::new()
                }
            })
            .y_desc("photos")
            .y_label_formatter(&count_tick)
            .draw()
            .map_err(|e| chart_err(title, e))?;
        chart
            .draw_series(bars.iter().enumerate().map(|(i, b)| {
                Rectangle::new(
                    [(i as f64 + 0.15, 0.0), (i as f64 + 0.85, b.1)],
                    PALETTE[i % PALETTE.len()].filled(),
                )
            }))
            .map_err(|e| chart_err(title, e))?;
        chart
            .draw_series(bars.iter().enumerate().map(|(i, b)| {
                Text::new(
                    format!("{}", b.1),
                    (i as f64 + 0.45, b.1 + top * 0.02),
                    ("sans-serif", 13),
                )
            }))
            .map_err(|e| chart_err(title, e))?;
        root.present().map_err(|e| chart_err(title, e))?;
    }
    Ok(svg)
}

/// A 2-D scatter of points grouped by label (one colour per group).
pub fn scatter(title: &str, groups: &[(String, Vec<(f64, f64)>)]) -> Result<String> {
    let pts: Vec<(f64, f64)> = groups.iter().flat_map(|g| g.1.iter().copied()).collect();
    let (mut x0, mut x1, mut y0, mut y1) = pts.iter().fold(
        (f64::MAX, f64::MIN, f64::MAX, f64::MIN),
        |(a, b, c, d), p| (a.min(p.0), b.max(p.0), c.min(p.1), d.max(p.1)),
    );
    if pts.is_empty() {
        (x0, x1, y0, y1) = (-1.0, 1.0, -1.0, 1.0);
    }
    let (px, py) = (((x1 - x0) * 0.08).max(1e-9), ((y1 - y0) * 0.08).max(1e-9));
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (W, H + 40)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| chart_err(title, e))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(44)
            .build_cartesian_2d(x0 - px..x1 + px, y0 - py..y1 + py)
            .map_err(|e| chart_err(title, e))?;
        chart
            .configure_mesh()
            .x_desc("PC 1")
            .y_desc("PC 2")
            .x_label_formatter(&tick(x1 - x0))
            .y_label_formatter(&tick(y1 - y0))
            .draw()
            .map_err(|e| chart_err(title, e))?;
        for (gi, (name, p)) in groups.iter().enumerate() {
            let color = PALETTE[gi % PALETTE.len()];
            chart
                .draw_series(p.iter().map(|q| Circle::new(*q, 4, color.filled())))
                .map_err(|e| chart_err(title, e))?
                .label(name.as_str())
                .legend(move |(x, y)| Circle::new((x + 5, y), 4, color.filled()));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.3))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(|e| chart_err(title, e))?;
        root.present().map_err(|e| chart_err(title, e))?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bins_count_every_finite_value_once_and_clamp_the_ends() {
        let c = bin(&[0.0, 0.05, 0.5, 1.0, 7.0, -3.0, f64::NAN], 0.0, 1.0, 10);
        assert_eq!(c.iter().sum::<f64>(), 6.0);
        assert_eq!(c[0], 3.0, "0, 0.05 and the clamped -3");
        assert_eq!(c[9], 2.0, "1.0 and the clamped 7");
    }

    #[test]
    fn count_ticks_label_whole_numbers_only() {
        assert_eq!(count_tick(&2.0), "2");
        assert_eq!(count_tick(&2.5), "");
        assert_eq!(tick(600.0)(&450.0), "450");
        assert_eq!(tick(1.0)(&0.85), "0.85");
    }

    #[test]
    fn charts_of_empty_and_constant_data_still_draw() {
        let svg = histogram("t", "x", &[("a", &[])], None, &[]).unwrap();
        assert!(svg.starts_with("<svg"));
        let svg = histogram("t", "x", &[("a", &[3.0, 3.0])], None, &[("m", 3.0)]).unwrap();
        assert!(svg.contains("<svg"));
        assert!(scatter("s", &[]).unwrap().contains("<svg"));
        assert!(bars("b", &[]).unwrap().contains("<svg"));
    }
}
