//! SVG figures for reports: line/point plots with a legend, and correlation stem plots
//! with confidence bands. Drawn with plotters' SVG backend (no fonts or system libraries).

use std::path::Path;

use plotters::prelude::*;

use crate::atomic::write_atomic;
use crate::error::{MmennError, Result};

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mark {
    /// Connected line.
    Line,
    /// Unconnected dots (measurements, scatter plots).
    Points,
}

/// One series of a figure.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend label (put fit % here for compare plots).
    pub label: String,
    /// Abscissae.
    pub x: Vec<f64>,
    /// Ordinates (NaN points are skipped).
    pub y: Vec<f64>,
    /// How it is drawn.
    pub mark: Mark,
}

impl Series {
    /// A line series.
    pub fn line(label: impl Into<String>, x: Vec<f64>, y: Vec<f64>) -> Self {
        Self {
            label: label.into(),
            x,
            y,
            mark: Mark::Line,
        }
    }
    /// A point series.
    pub fn points(label: impl Into<String>, x: Vec<f64>, y: Vec<f64>) -> Self {
        Self {
            label: label.into(),
            x,
            y,
            mark: Mark::Points,
        }
    }
}

/// A figure: title, axis labels, series, optional symmetric horizontal bands (e.g. ±z/√N).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Figure {
    /// Title.
    pub title: String,
    /// x-axis label.
    pub x_label: String,
    /// y-axis label.
    pub y_label: String,
    /// The series.
    pub series: Vec<Series>,
    /// Horizontal dashed lines at ±value (with their label).
    pub bands: Vec<(String, f64)>,
}

const PALETTE: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !lo.is_finite() {
        return (-1.0, 1.0);
    }
    let pad = if hi > lo {
        0.05 * (hi - lo)
    } else {
        lo.abs().max(1.0) * 0.05
    };
    (lo - pad, hi + pad)
}

fn draw_err<E: std::error::Error + Send + Sync>(e: DrawingAreaErrorKind<E>) -> MmennError {
    MmennError::Plot(e.to_string())
}

impl Figure {
    /// Render to SVG text.
    pub fn to_svg(&self) -> Result<String> {
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, (900, 500)).into_drawing_area();
            root.fill(&WHITE).map_err(draw_err)?;
            let (x0, x1) = range(self.series.iter().flat_map(|s| s.x.iter().copied()));
            let band_max = self.bands.iter().map(|b| b.1.abs()).fold(0.0, f64::max);
            let (y0, y1) = range(
                self.series
                    .iter()
                    .flat_map(|s| s.y.iter().copied())
                    .chain([band_max, -band_max].into_iter().filter(|_| band_max > 0.0)),
            );
            let mut chart = ChartBuilder::on(&root)
                .caption(&self.title, ("sans-serif", 22))
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(70)
                .build_cartesian_2d(x0..x1, y0..y1)
                .map_err(draw_err)?;
            chart
                .configure_mesh()
                .x_desc(&self.x_label)
                .y_desc(&self.y_label)
                .draw()
                .map_err(draw_err)?;
            for (i, s) in self.series.iter().enumerate() {
                let color = PALETTE[i % PALETTE.len()];
                let pts: Vec<(f64, f64)> =
                    s.x.iter()
                        .zip(&s.y)
                        .filter(|(a, b)| a.is_finite() && b.is_finite())
                        .map(|(a, b)| (*a, *b))
                        .collect();
                match s.mark {
                    Mark::Line => chart
                        .draw_series(LineSeries::new(pts, color.stroke_width(2)))
                        .map_err(draw_err)?
                        .label(&s.label)
                        .legend(move |(x, y)| {
                            PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                        }),
                    Mark::Points => chart
                        .draw_series(pts.into_iter().map(|p| Circle::new(p, 2, color.filled())))
                        .map_err(draw_err)?
                        .label(&s.label)
                        .legend(move |(x, y)| Circle::new((x + 10, y), 3, color.filled())),
                };
            }
            for (label, b) in &self.bands {
                for sign in [1.0, -1.0] {
                    let series = chart
                        .draw_series(DashedLineSeries::new(
                            vec![(x0, sign * b), (x1, sign * b)],
                            6,
                            4,
                            BLACK.stroke_width(1),
                        ))
                        .map_err(draw_err)?;
                    if sign > 0.0 {
                        series
                            .label(label)
                            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
                    }
                }
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .position(SeriesLabelPosition::UpperRight)
                .draw()
                .map_err(draw_err)?;
            root.present().map_err(draw_err)?;
        }
        Ok(svg)
    }

    /// Render and write atomically to `path`.
    pub fn write(&self, path: &Path) -> Result<()> {
        write_atomic(path, self.to_svg()?.as_bytes())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn svg_contains_title_legend_and_every_series() {
        let x: Vec<f64> = (0..50).map(|k| k as f64 * 0.1).collect();
        let fig = Figure {
            title: "compare".into(),
            x_label: "t (s)".into(),
            y_label: "theta (rad)".into(),
            series: vec![
                Series::points("measured", x.clone(), x.iter().map(|t| t.sin()).collect()),
                Series::line(
                    "model (fit 97.3 %)",
                    x.clone(),
                    x.iter().map(|t| t.sin() * 0.98).collect(),
                ),
            ],
            bands: vec![("99 % band".into(), 0.3)],
        };
        let svg = fig.to_svg().unwrap();
        assert!(svg.starts_with("<svg"));
        for needle in [
            "compare",
            "measured",
            "model (fit 97.3 %)",
            "99 % band",
            "t (s)",
        ] {
            assert!(svg.contains(needle), "missing {needle}");
        }
        // 50 measured points drawn as circles.
        assert!(svg.matches("<circle").count() >= 50);
    }
}
