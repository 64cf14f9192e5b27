//! The plots of `rendiff bench`, as SVG (plotters' SVG backend: no fonts
//! needed, the viewer draws the text).

#![expect(
    clippy::cast_precision_loss,
    reason = "statistics over counts and sizes below 2^53, exact in f64"
)]

use plotters::coord::ranged1d::SegmentValue;
use plotters::prelude::*;

use super::{Row, Sweep, pareto_front};
use rendiff::Backend;

/// Why a plot could not be drawn.
#[derive(Debug, thiserror::Error)]
#[error("could not draw the plot: {0}")]
pub struct PlotError(String);

fn err<E: std::fmt::Display>(e: E) -> PlotError {
    PlotError(e.to_string())
}

/// Errors of exactly 0 are drawn at this value on the log axis.
const ERROR_FLOOR: f64 = 1e-3;

/// A value with three significant digits, without exponent notation in
/// the usual range.
fn sig3(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    #[expect(
        clippy::cast_possible_truncation,
        reason = "the decimal exponent of a finite f64 lies in −324 … 309"
    )]
    let digits = (2 - v.abs().log10().floor() as i32).max(0);
    format!("{v:.*}", usize::try_from(digits).unwrap_or(0))
}

/// The colour of each sweep.
fn sweep_color(s: Sweep) -> RGBColor {
    match s {
        Sweep::Tessellation => RGBColor(31, 119, 180),
        Sweep::Samples => RGBColor(255, 127, 14),
        Sweep::Depth => RGBColor(44, 160, 44),
        Sweep::Shadows => RGBColor(214, 39, 40),
        Sweep::MaxDepth => RGBColor(148, 103, 189),
        Sweep::Plan => RGBColor(140, 86, 75),
        Sweep::Threads => RGBColor(127, 127, 127),
    }
}

/// A log range around `values`, padded by a quarter of a decade.
fn log_range(values: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) = values.fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    if !lo.is_finite() || hi <= 0.0 {
        return 0.1..10.0;
    }
    let (lo, hi) = (lo.max(1e-6), hi.max(lo * 1.0001));
    lo / 1.8..hi * 1.8
}

/// Time against error for one scene: a panel per backend, a colour per
/// sweep, and the Pareto front of each reference group (the settings that
/// no other setting beats on both time and error) drawn as a line.
///
/// # Errors
///
/// [`PlotError`] when plotters fails.
pub fn time_vs_error(scene: &str, rows: &[Row]) -> Result<String, PlotError> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1200, 600)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let root = root
            .titled(
                &format!("{scene}: run time against error (each point: one setting; lines: Pareto fronts)"),
                ("sans-serif", 18),
            )
            .map_err(err)?;
        let panels = root.split_evenly((1, 2));
        for (panel, backend) in panels.iter().zip([Backend::Raster, Backend::Ray]) {
            let (area, legend) = panel.split_vertically(panel.dim_in_pixel().1 - 96);
            let mut entries: Vec<(String, Option<RGBColor>)> = Vec::new();
            let mine: Vec<&Row> = rows
                .iter()
                .filter(|r| r.scene == scene && r.backend == backend)
                .collect();
            // Both axes are logarithmic: the chart is linear in log10 of
            // the values, and the labels show the values themselves.
            let y = |r: &Row| r.mae8.max(ERROR_FLOOR).log10();
            let x = |r: &Row| r.median_ms.max(1e-6).log10();
            let xr = log_range(mine.iter().map(|r| r.median_ms));
            let yr = log_range(mine.iter().map(|r| r.mae8.max(ERROR_FLOOR)));
            let (xr, yr) = (
                xr.start.log10()..xr.end.log10(),
                yr.start.log10()..yr.end.log10(),
            );
            let mut chart = ChartBuilder::on(&area)
                .caption(backend.to_string(), ("sans-serif", 16))
                .margin(12)
                .x_label_area_size(42)
                .y_label_area_size(64)
                .build_cartesian_2d(xr, yr)
                .map_err(err)?;
            chart
                .configure_mesh()
                .x_labels(8)
                .y_labels(8)
                .x_label_formatter(&|v| sig3(10f64.powf(*v)))
                .y_label_formatter(&|v| sig3(10f64.powf(*v)))
                .light_line_style(BLACK.mix(0.04))
                .bold_line_style(BLACK.mix(0.15))
                .x_desc("median wall time (ms)")
                .y_desc("error: mean 8-bit difference (0 drawn at 0.001)")
                .draw()
                .map_err(err)?;
            // Points first, then the labels, placed where they overlap
            // neither another label nor a point (or left out).
            let mut labels: Vec<(&Row, RGBColor)> = Vec::new();
            for sweep in Sweep::ALL {
                let pts: Vec<&&Row> = mine.iter().filter(|r| r.sweep == sweep).collect();
                if pts.is_empty() {
                    continue;
                }
                let c = sweep_color(sweep);
                chart
                    .draw_series(pts.iter().map(|r| Circle::new((x(r), y(r)), 4, c.filled())))
                    .map_err(err)?;
                entries.push((
                    format!("{} (vs {})", sweep.name(), pts[0].reference),
                    Some(c),
                ));
                labels.extend(pts.iter().map(|r| (**r, c)));
            }
            let anchors: Vec<(i32, i32)> = labels
                .iter()
                .map(|(r, _)| chart.backend_coord(&(x(r), y(r))))
                .collect();
            let sizes: Vec<(i32, i32)> = labels
                .iter()
                .map(|(r, _)| (label_width(&r.setting), LABEL_HEIGHT))
                .collect();
            let offsets = place_labels(&anchors, &sizes);
            for ((r, c), offset) in labels.iter().zip(offsets) {
                if let Some(d) = offset {
                    chart
                        .plotting_area()
                        .draw(
                            &(EmptyElement::at((x(r), y(r)))
                                + Text::new(
                                    r.setting.clone(),
                                    d,
                                    ("sans-serif", 10).into_font().color(c),
                                )),
                        )
                        .map_err(err)?;
                }
            }
            // A front per reference: points measured against different
            // references are not comparable.
            let mut references: Vec<&str> = mine.iter().map(|r| r.reference.as_str()).collect();
            references.sort_unstable();
            references.dedup();
            for (k, reference) in references.iter().enumerate() {
                let group: Vec<&&Row> = mine.iter().filter(|r| r.reference == *reference).collect();
                let pts: Vec<(f64, f64)> = group.iter().map(|r| (x(r), y(r))).collect();
                let front: Vec<(f64, f64)> =
                    pareto_front(&pts).into_iter().map(|i| pts[i]).collect();
                if front.len() < 2 {
                    continue;
                }
                let style = ShapeStyle::from(&BLACK.mix(0.6)).stroke_width(1 + u32::from(k == 0));
                chart
                    .draw_series(LineSeries::new(front.clone(), style))
                    .map_err(err)?;
                if !entries.iter().any(|e| e.1.is_none()) {
                    entries.push(("Pareto front (ringed: its settings)".into(), None));
                }
                chart
                    .draw_series(
                        front
                            .iter()
                            .map(|&p| Circle::new(p, 7, BLACK.mix(0.6).stroke_width(1))),
                    )
                    .map_err(err)?;
            }
            // The legend, below the chart in two columns.
            for (i, (text, color)) in entries.iter().enumerate() {
                let x = 80 + 260 * i32::try_from(i % 2).unwrap_or(0);
                let yy = 14 + 20 * i32::try_from(i / 2).unwrap_or(0);
                match color {
                    Some(c) => legend
                        .draw(&Circle::new((x, yy), 4, c.filled()))
                        .map_err(err)?,
                    None => legend
                        .draw(&PathElement::new(
                            vec![(x - 8, yy), (x + 8, yy)],
                            BLACK.mix(0.6).stroke_width(2),
                        ))
                        .map_err(err)?,
                }
                legend
                    .draw(&Text::new(
                        text.clone(),
                        (x + 14, yy - 6),
                        ("sans-serif", 12).into_font(),
                    ))
                    .map_err(err)?;
            }
        }
        root.present().map_err(err)?;
    }
    Ok(svg)
}

/// The height of a point label (10 px text) in pixels.
const LABEL_HEIGHT: i32 = 12;

/// The width of a point label in pixels: 10 px sans-serif averages under
/// 6 px a character.
fn label_width(text: &str) -> i32 {
    i32::try_from(text.chars().count())
        .unwrap_or(i32::MAX / 8)
        .saturating_mul(6)
        .saturating_add(2)
}

/// Where each label goes: the offset of its top-left corner from its point
/// (right of it, left, above, below, then further out), the first that
/// overlaps no label already placed and no point's marker; `None` (left
/// out) where every place collides. `anchors` are the points in pixels,
/// `sizes` the labels' widths and heights; earlier labels win.
#[must_use]
pub fn place_labels(anchors: &[(i32, i32)], sizes: &[(i32, i32)]) -> Vec<Option<(i32, i32)>> {
    /// A point marker's half-size (its radius 4, and a pixel of air).
    const MARK: i32 = 5;
    type Rect = (i32, i32, i32, i32);
    let overlaps = |a: &Rect, b: &Rect| {
        a.0 < b.0 + b.2 && b.0 < a.0 + a.2 && a.1 < b.1 + b.3 && b.1 < a.1 + a.3
    };
    let marks: Vec<Rect> = anchors
        .iter()
        .map(|&(x, y)| (x - MARK, y - MARK, 2 * MARK, 2 * MARK))
        .collect();
    let mut placed: Vec<Rect> = Vec::new();
    let mut out = Vec::with_capacity(anchors.len());
    for (&(x, y), &(w, h)) in anchors.iter().zip(sizes) {
        let candidates = [
            (MARK + 1, -h / 2),
            (-w - MARK - 1, -h / 2),
            (-w / 2, -h - MARK),
            (-w / 2, MARK + 1),
            (MARK + 1, -h - MARK),
            (MARK + 1, MARK + 1),
            (-w - MARK - 1, -h - MARK),
            (-w - MARK - 1, MARK + 1),
        ];
        let spot = candidates.into_iter().find(|&(dx, dy)| {
            let r = (x + dx, y + dy, w, h);
            !placed.iter().chain(&marks).any(|o| overlaps(&r, o))
        });
        if let Some((dx, dy)) = spot {
            placed.push((x + dx, y + dy, w, h));
        }
        out.push(spot);
    }
    out
}

/// What the plan saved: per scene and backend, the share of the render
/// time that `--no-plan` spends on top (negative: within noise).
///
/// # Errors
///
/// [`PlotError`] when plotters fails.
pub fn plan_savings(savings: &[(String, Backend, f64, f64)]) -> Result<String, PlotError> {
    let mut scenes: Vec<&str> = savings.iter().map(|s| s.0.as_str()).collect();
    scenes.dedup();
    let n = scenes.len().max(1);
    let pct = |on: f64, off: f64| {
        if off > 0.0 {
            (off - on) / off * 100.0
        } else {
            0.0
        }
    };
    let mut svg = String::new();
    {
        let height = 120 + 28 * u32::try_from(n).unwrap_or(40);
        let root = SVGBackend::with_string(&mut svg, (1000, height)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let root = root
            .titled(
                "What the plan saved: (time without − time with) / time without, median runs",
                ("sans-serif", 18),
            )
            .map_err(err)?;
        let panels = root.split_evenly((1, 2));
        for (area, backend) in panels.iter().zip([Backend::Raster, Backend::Ray]) {
            let values: Vec<(usize, f64)> = scenes
                .iter()
                .enumerate()
                .filter_map(|(i, s)| {
                    savings
                        .iter()
                        .find(|v| v.0 == *s && v.1 == backend)
                        .map(|v| (i, pct(v.2, v.3)))
                })
                .collect();
            let lo = values.iter().map(|v| v.1).fold(0.0f64, f64::min).min(-5.0);
            let hi = values.iter().map(|v| v.1).fold(0.0f64, f64::max).max(5.0);
            let n32 = i32::try_from(n).unwrap_or(i32::MAX);
            let mut chart = ChartBuilder::on(area)
                .caption(backend.to_string(), ("sans-serif", 16))
                .margin(12)
                .x_label_area_size(36)
                .y_label_area_size(110)
                .build_cartesian_2d(lo * 1.1..hi * 1.1, (0..n32).into_segmented())
                .map_err(err)?;
            let names = scenes.clone();
            chart
                .configure_mesh()
                .disable_y_mesh()
                .x_desc("time saved (%)")
                .y_labels(n)
                .y_label_formatter(&|v| match v {
                    SegmentValue::CenterOf(i) => usize::try_from(*i)
                        .ok()
                        .and_then(|i| names.get(i))
                        .map_or_else(String::new, |s| (*s).to_string()),
                    _ => String::new(),
                })
                .draw()
                .map_err(err)?;
            let color = if backend == Backend::Raster {
                RGBColor(31, 119, 180)
            } else {
                RGBColor(214, 39, 40)
            };
            chart
                .draw_series(values.iter().map(|&(i, v)| {
                    let i = i32::try_from(i).unwrap_or(0);
                    let mut bar = Rectangle::new(
                        [
                            (0.0, SegmentValue::Exact(i)),
                            (v, SegmentValue::Exact(i + 1)),
                        ],
                        color.mix(0.8).filled(),
                    );
                    bar.set_margin(4, 4, 0, 0);
                    bar
                }))
                .map_err(err)?;
            chart
                .draw_series(values.iter().map(|&(i, v)| {
                    let i = i32::try_from(i).unwrap_or(0);
                    Text::new(
                        format!("{v:.0} %"),
                        (v.max(0.0), SegmentValue::CenterOf(i)),
                        ("sans-serif", 11).into_font(),
                    )
                }))
                .map_err(err)?;
        }
        root.present().map_err(err)?;
    }
    Ok(svg)
}

/// Which number of a scaling row goes on the x axis.
type XValue = fn(&super::scaling::ScalingRow) -> f64;

/// Time against triangle count and against pixels, log-log, one line per
/// backend (and the ray tracer's build and tracing apart).
///
/// # Errors
///
/// [`PlotError`] when plotters fails.
pub fn scaling(rows: &[super::scaling::ScalingRow]) -> Result<String, PlotError> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1200, 520)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let root = root
            .titled("Scaling: median wall time, log-log", ("sans-serif", 18))
            .map_err(err)?;
        let panels = root.split_evenly((1, 2));
        let series: [(&str, &str, XValue); 2] = [
            (
                "triangles",
                "triangles (one sphere, 640x480, shadowless light)",
                |r| r.triangles as f64,
            ),
            ("pixels", "pixels (bunny.toml)", |r| r.pixels as f64),
        ];
        for (area, (name, desc, xv)) in panels.iter().zip(series) {
            let mine: Vec<&super::scaling::ScalingRow> =
                rows.iter().filter(|r| r.series == name).collect();
            if mine.is_empty() {
                continue;
            }
            let xr = log_range(mine.iter().map(|r| xv(r)));
            let yr = log_range(mine.iter().map(|r| r.median_ms));
            let mut chart = ChartBuilder::on(area)
                .margin(14)
                .x_label_area_size(42)
                .y_label_area_size(64)
                .build_cartesian_2d(
                    xr.start.log10()..xr.end.log10(),
                    yr.start.log10()..yr.end.log10(),
                )
                .map_err(err)?;
            chart
                .configure_mesh()
                .x_labels(8)
                .y_labels(8)
                .light_line_style(BLACK.mix(0.04))
                .bold_line_style(BLACK.mix(0.15))
                .x_label_formatter(&|v| {
                    let x = 10f64.powf(*v);
                    if x >= 1e6 {
                        format!("{:.2}M", x / 1e6)
                    } else if x >= 1e3 {
                        format!("{:.1}k", x / 1e3)
                    } else {
                        sig3(x)
                    }
                })
                .y_label_formatter(&|v| sig3(10f64.powf(*v)))
                .x_desc(desc)
                .y_desc("median wall time (ms)")
                .draw()
                .map_err(err)?;
            let whats = ["raster", "ray", "ray build", "ray trace"];
            let colors = [
                RGBColor(31, 119, 180),
                RGBColor(214, 39, 40),
                RGBColor(255, 127, 14),
                RGBColor(148, 103, 189),
            ];
            for (what, c) in whats.iter().zip(colors) {
                let pts: Vec<(f64, f64)> = mine
                    .iter()
                    .filter(|r| r.what == *what)
                    .map(|r| (xv(r).log10(), r.median_ms.log10()))
                    .collect();
                if pts.is_empty() {
                    continue;
                }
                chart
                    .draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))
                    .map_err(err)?
                    .label(*what)
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 16, y)], c.stroke_width(2))
                    });
                chart
                    .draw_series(pts.iter().map(|&p| Circle::new(p, 3, c.filled())))
                    .map_err(err)?;
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperLeft)
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK.mix(0.3))
                .label_font(("sans-serif", 12))
                .draw()
                .map_err(err)?;
        }
        root.present().map_err(err)?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rect(a: (i32, i32), d: (i32, i32), s: (i32, i32)) -> (i32, i32, i32, i32) {
        (a.0 + d.0, a.1 + d.1, s.0, s.1)
    }

    #[test]
    fn placed_labels_never_overlap_each_other_or_points() {
        // A tight cluster (the overprinting case) and a few loners.
        let anchors: Vec<(i32, i32)> = (0..12)
            .map(|k| (100 + 3 * k, 100 + 2 * (k % 3)))
            .chain([(400, 50), (420, 52), (10, 300)])
            .collect();
        let sizes: Vec<(i32, i32)> = anchors
            .iter()
            .map(|_| (label_width("map:1024"), LABEL_HEIGHT))
            .collect();
        let placed = place_labels(&anchors, &sizes);
        let rects: Vec<_> = placed
            .iter()
            .zip(&anchors)
            .zip(&sizes)
            .filter_map(|((p, &a), &s)| p.map(|d| rect(a, d, s)))
            .collect();
        assert!(rects.len() >= 4, "{placed:?}");
        // The loners all get a label.
        assert!(placed[12..].iter().all(Option::is_some));
        for (i, a) in rects.iter().enumerate() {
            for b in &rects[i + 1..] {
                let overlap =
                    a.0 < b.0 + b.2 && b.0 < a.0 + a.2 && a.1 < b.1 + b.3 && b.1 < a.1 + a.3;
                assert!(!overlap, "{a:?} overlaps {b:?}");
            }
            for &(x, y) in &anchors {
                let inside = x + 4 > a.0 && x - 4 < a.0 + a.2 && y + 4 > a.1 && y - 4 < a.1 + a.3;
                assert!(!inside, "{a:?} covers the point ({x}, {y})");
            }
        }
    }
}
