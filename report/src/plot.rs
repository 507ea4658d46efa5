//! SVG plots of the report (log-log), drawn with `plotters`: error against
//! time per scene, and time against the number of lights.

use std::error::Error;
use std::path::Path;

use plotters::prelude::*;

use crate::measure::{Measurement, Method, Record};
use crate::scaling::{ScalingRow, scaling_series_of};
use crate::scenes::Scene;

/// Plot size in pixels: two panels side by side for error plots.
const ERROR_PLOT_SIZE: (u32, u32) = (1600, 700);
const SCALING_PLOT_SIZE: (u32, u32) = (900, 650);
/// Errors below this are drawn at it (a log axis has no 0).
pub const ERROR_FLOOR: f64 = 1e-9;
/// Margin factor around the data on each log axis.
const AXIS_MARGIN: f64 = 1.6;
const MARKER_SIZE: i32 = 4;
const FONT: &str = "sans-serif";

/// How a series is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Style {
    /// Solid line with filled circles.
    Solid,
    /// Dashed line with hollow triangles (certified bounds).
    Dashed,
}

/// One labelled curve.
#[derive(Clone, Debug)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// Colour.
    pub colour: RGBColor,
    /// How it is drawn.
    pub style: Style,
    /// Points `(x, y)`, both positive, in drawing order.
    pub points: Vec<(f64, f64)>,
}

/// One panel: a caption, axis descriptions and its curves.
pub struct Panel<'a> {
    /// Panel title.
    pub caption: &'a str,
    /// X axis description.
    pub x_desc: &'a str,
    /// Y axis description.
    pub y_desc: &'a str,
    /// The curves.
    pub series: &'a [Series],
    /// Where the legend goes (the corner the curves leave empty).
    pub legend: SeriesLabelPosition,
}

/// Writes `panels` side by side into one SVG at `path`.
pub fn write_panels(path: &Path, panels: &[Panel<'_>]) -> Result<(), Box<dyn Error>> {
    let size = if panels.len() > 1 {
        ERROR_PLOT_SIZE
    } else {
        SCALING_PLOT_SIZE
    };
    let root = SVGBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE)?;
    let areas = root.split_evenly((1, panels.len()));
    for (area, panel) in areas.iter().zip(panels) {
        draw_panel(area, panel)?;
    }
    root.present()?;
    Ok(())
}

/// Bounds `[lo / margin, hi * margin]` of the positive values `v`.
fn log_range(v: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) = v.fold((f64::INFINITY, 0.0f64), |(lo, hi), x| {
        (lo.min(x), hi.max(x))
    });
    if lo.is_finite() && hi > 0.0 {
        lo / AXIS_MARGIN..hi * AXIS_MARGIN
    } else {
        1.0..10.0
    }
}

fn draw_panel(
    area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    panel: &Panel<'_>,
) -> Result<(), Box<dyn Error>> {
    let clamp = |(x, y): (f64, f64)| (x, y.max(ERROR_FLOOR));
    let all = || {
        panel
            .series
            .iter()
            .flat_map(|s| s.points.iter().copied().map(clamp))
    };
    let x_range = log_range(all().map(|p| p.0));
    let y_range = log_range(all().map(|p| p.1));
    let mut chart = ChartBuilder::on(area)
        .caption(panel.caption, (FONT, 20))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(x_range.log_scale(), y_range.log_scale())?;
    chart
        .configure_mesh()
        .x_desc(panel.x_desc)
        .y_desc(panel.y_desc)
        .x_label_formatter(&|x| format!("{x:.0e}"))
        .y_label_formatter(&|y| format!("{y:.0e}"))
        .draw()?;
    for series in panel.series {
        let colour = series.colour;
        let points: Vec<(f64, f64)> = series.points.iter().copied().map(clamp).collect();
        let line = colour.stroke_width(2);
        match series.style {
            Style::Solid => {
                chart
                    .draw_series(LineSeries::new(points.clone(), line))?
                    .label(&series.label)
                    .legend(move |(x, y)| {
                        // A line and the series' filled circle.
                        EmptyElement::at((x, y))
                            + PathElement::new(vec![(0, 0), (20, 0)], colour.stroke_width(2))
                            + Circle::new((10, 0), MARKER_SIZE - 1, colour.filled())
                    });
                chart.draw_series(
                    points
                        .iter()
                        .map(|&p| Circle::new(p, MARKER_SIZE, colour.filled())),
                )?;
            }
            Style::Dashed => {
                chart
                    .draw_series(DashedLineSeries::new(points.clone(), 6, 4, line))?
                    .label(&series.label)
                    .legend(move |(x, y)| {
                        // Two dashes and the series' triangle marker.
                        EmptyElement::at((x, y))
                            + PathElement::new(vec![(0, 0), (6, 0)], colour.stroke_width(2))
                            + PathElement::new(vec![(14, 0), (20, 0)], colour.stroke_width(2))
                            + TriangleMarker::new((10, 0), MARKER_SIZE, colour)
                    });
                chart.draw_series(
                    points
                        .iter()
                        .map(|&p| TriangleMarker::new(p, MARKER_SIZE + 1, colour)),
                )?;
            }
        }
    }
    chart
        .configure_series_labels()
        .position(panel.legend.clone())
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FONT, 13))
        .draw()?;
    Ok(())
}

/// Plot colour of each method.
fn colour(method: Method) -> RGBColor {
    match method {
        Method::ExactSoa | Method::ExactShadowed => RGBColor(0, 0, 0),
        Method::TreePaper => RGBColor(230, 120, 0),
        Method::TreeRelative => RGBColor(20, 70, 220),
        Method::TreeAbsolute => RGBColor(0, 170, 200),
        Method::PerNode => RGBColor(30, 150, 50),
        Method::PowerSampling => RGBColor(210, 30, 40),
        Method::TreeSampling => RGBColor(150, 50, 180),
        Method::Ward => RGBColor(140, 90, 40),
    }
}

/// The error-against-time plot of one scene: max error (left) and mean
/// error (right), each with the certified bounds dashed.
pub fn plot_scene(path: &Path, scene: &Scene, rows: &[Record]) -> Result<(), Box<dyn Error>> {
    let panel_series = |error: fn(&Measurement) -> f64, bound: fn((f64, f64)) -> f64| {
        let mut series = Vec::new();
        for method in Method::ALL {
            let of = || rows.iter().filter(move |r| r.method == method);
            if of().next().is_none() {
                continue;
            }
            let us = |r: &Record| r.measurement.seconds_per_point * 1e6;
            series.push(Series {
                label: method.label().to_string(),
                colour: colour(method),
                style: Style::Solid,
                points: of().map(|r| (us(r), error(&r.measurement))).collect(),
            });
            if matches!(
                method,
                Method::TreePaper | Method::TreeRelative | Method::PerNode
            ) {
                series.push(Series {
                    label: format!("{}: certified bound", method.label()),
                    colour: colour(method),
                    style: Style::Dashed,
                    points: of()
                        .filter_map(|r| r.measurement.bound.map(|b| (us(r), bound(b))))
                        .collect(),
                });
            }
        }
        series
    };
    let max_series = panel_series(|m| m.max_error, |b| b.1);
    let mean_series = panel_series(|m| m.mean_error, |b| b.0);
    let x_desc = "time per shading point (us)";
    let floor = format!("errors < {:.0e} drawn at it", ERROR_FLOOR);
    let max_desc = format!("max relative error, largest channel ({floor})");
    let mean_desc = format!("mean relative error, largest channel ({floor})");
    let shadows = if rows.iter().any(|r| r.measurement.queries.is_some()) {
        ", with shadows"
    } else {
        ""
    };
    let max_caption = format!(
        "{}: max relative error ({} lights{shadows})",
        scene.name,
        scene.lights.len()
    );
    let mean_caption = format!("{}: mean relative error", scene.name);
    write_panels(
        path,
        &[
            Panel {
                caption: &max_caption,
                x_desc,
                y_desc: &max_desc,
                series: &max_series,
                legend: SeriesLabelPosition::LowerLeft,
            },
            Panel {
                caption: &mean_caption,
                x_desc,
                y_desc: &mean_desc,
                series: &mean_series,
                legend: SeriesLabelPosition::LowerLeft,
            },
        ],
    )
}

/// The time-per-point-against-lights plot of the scaling part.
pub fn plot_scaling(path: &Path, rows: &[ScalingRow]) -> Result<(), Box<dyn Error>> {
    let mut series: Vec<Series> = Vec::new();
    for row in rows {
        for r in &row.records {
            let Some(label) = scaling_series_of(r) else {
                continue;
            };
            let point = (row.lights as f64, r.measurement.seconds_per_point * 1e6);
            match series.iter_mut().find(|s| s.label == label) {
                Some(s) => s.points.push(point),
                None => series.push(Series {
                    label,
                    colour: colour(r.method),
                    style: Style::Solid,
                    points: vec![point],
                }),
            }
        }
    }
    write_panels(
        path,
        &[Panel {
            caption: "city, fixed lamp density: time per shading point",
            x_desc: "number of lights",
            y_desc: "time per shading point (us)",
            series: &series,
            legend: SeriesLabelPosition::UpperLeft,
        }],
    )
}
