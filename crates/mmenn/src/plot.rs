//! SVG figures for reports: line/point plots with a legend, and correlation stem plots
//! with confidence bands. Drawn with plotters' SVG backend (no fonts or system libraries).
//!
//! Figures stay small whatever the number of samples: a line with more points than the
//! plot has pixel columns is reduced to, per column, its first, lowest, highest and last
//! point in their original order (the exact extremes are kept, so a one-sample spike
//! stays visible), and a point series is binned on a grid of cells a few pixels wide, one
//! dot per occupied cell (the grid is coarsened until the dots fit the budget). Both
//! reductions are deterministic and only change what is drawn, never the data.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use nalgebra::DMatrix;
use plotters::prelude::*;
use sysid_core::Experiment;

use crate::atomic::write_atomic;
use crate::error::{MmennError, Result};

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mark {
    /// Connected line.
    Line,
    /// Unconnected dots (measurements, scatter plots).
    Points,
    /// Dashed reference line (a target level, a chosen value), drawn as given.
    Dashed,
    /// Large open rings marking chosen points (e.g. the chosen network of a sweep).
    Highlight,
}

/// One series of a figure.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend label (put fit % here for compare plots).
    pub label: String,
    /// Abscissae (shared: one time axis serves every series of a figure).
    pub x: Arc<[f64]>,
    /// Ordinates (NaN points are skipped).
    pub y: Arc<[f64]>,
    /// How it is drawn.
    pub mark: Mark,
    /// Palette entry (default: the series' position in the figure), so that one model
    /// keeps its colour across the panels of a figure.
    pub colour: Option<usize>,
}

impl Series {
    /// The same series drawn in palette entry `k`.
    pub fn coloured(mut self, k: usize) -> Self {
        self.colour = Some(k);
        self
    }
    /// A line series.
    pub fn line(
        label: impl Into<String>,
        x: impl Into<Arc<[f64]>>,
        y: impl Into<Arc<[f64]>>,
    ) -> Self {
        Self {
            label: label.into(),
            x: x.into(),
            y: y.into(),
            mark: Mark::Line,
            colour: None,
        }
    }
    /// A dashed reference line through the given points.
    pub fn dashed(
        label: impl Into<String>,
        x: impl Into<Arc<[f64]>>,
        y: impl Into<Arc<[f64]>>,
    ) -> Self {
        Self {
            label: label.into(),
            x: x.into(),
            y: y.into(),
            mark: Mark::Dashed,
            colour: None,
        }
    }
    /// Rings around chosen points.
    pub fn highlight(
        label: impl Into<String>,
        x: impl Into<Arc<[f64]>>,
        y: impl Into<Arc<[f64]>>,
    ) -> Self {
        Self {
            label: label.into(),
            x: x.into(),
            y: y.into(),
            mark: Mark::Highlight,
            colour: None,
        }
    }
    /// A point series.
    pub fn points(
        label: impl Into<String>,
        x: impl Into<Arc<[f64]>>,
        y: impl Into<Arc<[f64]>>,
    ) -> Self {
        Self {
            label: label.into(),
            x: x.into(),
            y: y.into(),
            mark: Mark::Points,
            colour: None,
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

/// The finite points of a series, in order.
fn finite(s: &Series) -> impl Iterator<Item = (f64, f64)> + '_ {
    s.x.iter()
        .zip(s.y.iter())
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(a, b)| (*a, *b))
}

/// Plot size in pixels.
const SIZE: (u32, u32) = (900, 500);
/// Columns a line is reduced to (a little more than the plot area is wide).
const LINE_COLUMNS: usize = 1000;
/// Most dots drawn for all point series of one figure together.
const DOT_BUDGET: usize = 8000;
/// Smallest binning cell of a point series, in pixels.
const MIN_CELL_PX: f64 = 3.0;

/// Reduce a line (finite points, in drawing order) to at most four points per column
/// of `columns` equal slices of `[x0, x1]`: for each run of consecutive points in one
/// column, its first, lowest, highest and last point in their original order. The exact
/// extremes of every column are kept. Lines with at most `4·columns` points, and lines
/// whose abscissae are so unordered that the reduction does not shorten them enough, are
/// thinned by a fixed stride after the envelope (never at random).
pub fn decimate_line(pts: &[(f64, f64)], x0: f64, x1: f64, columns: usize) -> Vec<(f64, f64)> {
    decimate_points(pts.iter().copied(), x0, x1, columns)
}

/// [`decimate_line`] over points as they come (no copy of the whole line is made).
pub fn decimate_points(
    pts: impl Iterator<Item = (f64, f64)>,
    x0: f64,
    x1: f64,
    columns: usize,
) -> Vec<(f64, f64)> {
    let columns = columns.max(1);
    let limit = 4 * columns;
    let width = x1 - x0;
    let column = |x: f64| -> usize {
        if width > 0.0 && width.is_finite() {
            cell_index((x - x0) / width * columns as f64, columns)
        } else {
            0
        }
    };
    /// The run of consecutive points in one column: its column, first, lowest, highest
    /// and last point with their positions in the run.
    struct Run {
        column: usize,
        first: (f64, f64),
        lo: (usize, (f64, f64)),
        hi: (usize, (f64, f64)),
        last: (usize, (f64, f64)),
    }
    let flush = |r: &Run, out: &mut Vec<(f64, f64)>| {
        let mut keep = [(0, r.first), r.lo, r.hi, r.last];
        keep.sort_unstable_by_key(|k| k.0);
        let mut prev = usize::MAX;
        for (k, p) in keep {
            if k != prev {
                out.push(p);
                prev = k;
            }
        }
    };
    // The first `limit + 1` points as given: a line that short is returned unchanged.
    let mut head: Vec<(f64, f64)> = Vec::with_capacity(limit + 1);
    let mut out = Vec::with_capacity(limit);
    let mut run: Option<Run> = None;
    for p in pts {
        if head.len() <= limit {
            head.push(p);
        }
        let c = column(p.0);
        match &mut run {
            Some(r) if r.column == c => {
                let k = r.last.0 + 1;
                if p.1 < r.lo.1.1 {
                    r.lo = (k, p);
                }
                if p.1 > r.hi.1.1 {
                    r.hi = (k, p);
                }
                r.last = (k, p);
            }
            _ => {
                if let Some(r) = &run {
                    flush(r, &mut out);
                }
                run = Some(Run {
                    column: c,
                    first: p,
                    lo: (0, p),
                    hi: (0, p),
                    last: (0, p),
                });
            }
        }
    }
    if head.len() <= limit {
        return head;
    }
    if let Some(r) = &run {
        flush(r, &mut out);
    }
    if out.len() > 2 * limit {
        // Unordered abscissae: thin by a fixed stride, keeping the first and last point.
        let stride = out.len().div_ceil(limit);
        let last = out[out.len() - 1];
        let mut thinned: Vec<(f64, f64)> = out.iter().copied().step_by(stride).collect();
        if thinned.last() != Some(&last) {
            thinned.push(last);
        }
        return thinned;
    }
    out
}

/// `floor(v)` clamped to `0..n` (`n ≥ 1`; NaN gives 0). A float-to-integer cast
/// truncates toward zero and saturates, so it equals `floor(v).max(0)` for every `v`
/// without a call to `floor`.
fn cell_index(v: f64, n: usize) -> usize {
    (v as usize).min(n - 1)
}

/// Bin points (finite, any order) on a grid over `[x0, x1] × [y0, y1]` with `cols × rows`
/// cells and keep, per occupied cell, the first point that fell in it (in data order).
fn bin_points(
    pts: impl Iterator<Item = (f64, f64)>,
    (x0, x1): (f64, f64),
    (y0, y1): (f64, f64),
    (cols, rows): (usize, usize),
) -> Vec<(f64, f64)> {
    let cell = |v: f64, lo: f64, hi: f64, n: usize| -> usize {
        let w = hi - lo;
        if w > 0.0 && w.is_finite() {
            cell_index((v - lo) / w * n as f64, n)
        } else {
            0
        }
    };
    let mut seen = vec![false; cols * rows];
    let mut out = Vec::new();
    for (x, y) in pts {
        let k = cell(y, y0, y1, rows) * cols + cell(x, x0, x1, cols);
        if !seen[k] {
            seen[k] = true;
            out.push((x, y));
        }
    }
    out
}

/// Thin point series to at most `budget` dots together: untouched when they already fit;
/// otherwise binned on cells of `MIN_CELL_PX` pixels, doubled until the dots fit.
pub fn thin_points(
    series: &[&[(f64, f64)]],
    xr: (f64, f64),
    yr: (f64, f64),
    plot_px: (u32, u32),
    budget: usize,
) -> Vec<Vec<(f64, f64)>> {
    thin_with(
        series.len(),
        |i| series[i].iter().copied(),
        xr,
        yr,
        plot_px,
        budget,
    )
}

/// [`thin_points`] over `n` series whose points `points(i)` gives afresh on each call
/// (each pass reads them again; no series is copied whole unless it fits).
fn thin_with<I: Iterator<Item = (f64, f64)>>(
    n: usize,
    points: impl Fn(usize) -> I,
    xr: (f64, f64),
    yr: (f64, f64),
    plot_px: (u32, u32),
    budget: usize,
) -> Vec<Vec<(f64, f64)>> {
    if (0..n).map(|i| points(i).count()).sum::<usize>() <= budget {
        return (0..n).map(|i| points(i).collect()).collect();
    }
    let mut cell_px = MIN_CELL_PX;
    loop {
        let cols = ((f64::from(plot_px.0) / cell_px).ceil() as usize).max(1);
        let rows = ((f64::from(plot_px.1) / cell_px).ceil() as usize).max(1);
        let binned: Vec<Vec<(f64, f64)>> = (0..n)
            .map(|i| bin_points(points(i), xr, yr, (cols, rows)))
            .collect();
        if binned.iter().map(Vec::len).sum::<usize>() <= budget || cols * rows <= n {
            return binned;
        }
        cell_px *= 1.5;
    }
}

impl Figure {
    /// Render to SVG text.
    pub fn to_svg(&self) -> Result<String> {
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
            root.fill(&WHITE).map_err(draw_err)?;
            self.draw_on(&root, None)?;
            root.present().map_err(draw_err)?;
        }
        Ok(svg)
    }

    /// The x range the figure draws: its data's, padded.
    fn x_range(&self) -> (f64, f64) {
        range(self.series.iter().flat_map(|s| s.x.iter().copied()))
    }

    /// Draw the figure on `root` (already filled), over `x_range` when given.
    fn draw_on<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, plotters::coord::Shift>,
        x_range: Option<(f64, f64)>,
    ) -> Result<()>
    where
        DB::ErrorType: 'static,
    {
        {
            let (x0, x1) = x_range.unwrap_or_else(|| self.x_range());
            let band_max = self.bands.iter().map(|b| b.1.abs()).fold(0.0, f64::max);
            let (y0, y1) = range(
                self.series
                    .iter()
                    .flat_map(|s| s.y.iter().copied())
                    .chain([band_max, -band_max].into_iter().filter(|_| band_max > 0.0)),
            );
            let mut chart = ChartBuilder::on(root)
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
            // Point series are thinned by passes over their columns (no copy of the
            // points); lines are reduced as their points come.
            let point_series: Vec<&Series> = self
                .series
                .iter()
                .filter(|s| s.mark == Mark::Points)
                .collect();
            let plot_px = chart.plotting_area().dim_in_pixel();
            let thinned = thin_with(
                point_series.len(),
                |i| finite(point_series[i]),
                (x0, x1),
                (y0, y1),
                plot_px,
                DOT_BUDGET,
            );
            let mut thinned = thinned.into_iter();
            for (i, s) in self.series.iter().enumerate() {
                let color = PALETTE[s.colour.unwrap_or(i) % PALETTE.len()];
                match s.mark {
                    Mark::Line => chart
                        .draw_series(LineSeries::new(
                            decimate_points(finite(s), x0, x1, LINE_COLUMNS),
                            color.stroke_width(2),
                        ))
                        .map_err(draw_err)?
                        .label(&s.label)
                        .legend(move |(x, y)| {
                            PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                        }),
                    Mark::Points => {
                        let pts = thinned.next().unwrap_or_default();
                        chart
                            .draw_series(pts.into_iter().map(|p| Circle::new(p, 2, color.filled())))
                            .map_err(draw_err)?
                            .label(&s.label)
                            .legend(move |(x, y)| Circle::new((x + 10, y), 3, color.filled()))
                    }
                    Mark::Dashed => chart
                        .draw_series(DashedLineSeries::new(
                            decimate_points(finite(s), x0, x1, LINE_COLUMNS),
                            8,
                            5,
                            color.stroke_width(2),
                        ))
                        .map_err(draw_err)?
                        .label(&s.label)
                        .legend(move |(x, y)| {
                            PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                        }),
                    Mark::Highlight => chart
                        .draw_series(
                            finite(s)
                                .take(DOT_BUDGET)
                                .map(|p| Circle::new(p, 7, color.stroke_width(2))),
                        )
                        .map_err(draw_err)?
                        .label(&s.label)
                        .legend(move |(x, y)| Circle::new((x + 10, y), 6, color.stroke_width(2))),
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
        }
        Ok(())
    }

    /// Render and write atomically to `path`.
    pub fn write(&self, path: &Path) -> Result<()> {
        write_atomic(path, self.to_svg()?.as_bytes())
    }
}

/// Two figures on one canvas sharing the x axis: a main panel above a lower one of
/// about a third of the height (e.g. measured − simulated under a compare plot).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Panels {
    /// The main panel.
    pub top: Figure,
    /// The lower panel.
    pub bottom: Figure,
}

/// Size in pixels of a two-panel figure, and the height of its upper panel.
const PANELS_SIZE: (u32, u32) = (900, 720);
const PANELS_SPLIT: u32 = 470;

impl Panels {
    /// A time plot (`series` against `t (s)`) over its residual panel ("measured −
    /// simulated", `residuals`), both with the y label `y_label`.
    pub fn time_with_residuals(
        title: String,
        y_label: String,
        series: Vec<Series>,
        residuals: Vec<Series>,
    ) -> Self {
        Self {
            top: Figure {
                title,
                x_label: "t (s)".into(),
                y_label: y_label.clone(),
                series,
                bands: vec![],
            },
            bottom: Figure {
                title: "residual: measured − simulated".into(),
                x_label: "t (s)".into(),
                y_label,
                series: residuals,
                bands: vec![],
            },
        }
    }

    /// A record's outputs measured and simulated, over their residuals: per output
    /// `names[i]` (row `i` of the record's outputs and of `simulated`), its measured
    /// points (legend "name (unit) measured", the unit from `units` when it has one), its
    /// simulated line (legend `labels[i]`, where the caller puts the fit %) and, in the
    /// lower panel, measured − simulated in the line's colour. NaN samples (a missing
    /// measurement, no prediction) are not drawn. The y label is the output with its
    /// unit when there is one output. An error when `simulated`, `labels` or the record's
    /// outputs do not have one row per name, or `simulated` not one column per sample.
    pub fn outputs_with_residuals(
        title: String,
        names: &[String],
        units: &BTreeMap<String, String>,
        record: &Experiment,
        simulated: &DMatrix<f64>,
        labels: &[String],
    ) -> Result<Self> {
        let measured = record.outputs();
        let shapes = [
            ("measured outputs", measured.nrows(), names.len()),
            ("simulated outputs", simulated.nrows(), names.len()),
            ("legend labels", labels.len(), names.len()),
            ("simulated samples", simulated.ncols(), record.len()),
        ];
        if let Some((what, got, want)) = shapes.iter().find(|(_, got, want)| got != want) {
            return Err(MmennError::Plot(format!(
                "figure \"{title}\": {got} {what}, expected {want}"
            )));
        }
        let with_unit = |n: &str| match units.get(n) {
            Some(u) => format!("{n} ({u})"),
            None => n.to_string(),
        };
        let y_label = match names {
            [one] => with_unit(one),
            _ => "output (units in the legend)".to_string(),
        };
        let t: Arc<[f64]> = record.times().into();
        let (mut series, mut residuals) = (Vec::new(), Vec::new());
        for (i, (name, label)) in names.iter().zip(labels).enumerate() {
            let m: Vec<f64> = measured.row(i).iter().copied().collect();
            let s: Vec<f64> = simulated.row(i).iter().copied().collect();
            let r: Vec<f64> = m.iter().zip(&s).map(|(m, s)| m - s).collect();
            series.push(Series::points(
                format!("{} measured", with_unit(name)),
                t.clone(),
                m,
            ));
            series.push(Series::line(label.clone(), t.clone(), s));
            residuals.push(
                Series::line(format!("{name} measured − simulated"), t.clone(), r)
                    .coloured(2 * i + 1),
            );
        }
        Ok(Self::time_with_residuals(title, y_label, series, residuals))
    }

    /// Render to SVG text: both panels over the union of their x ranges.
    pub fn to_svg(&self) -> Result<String> {
        let (a0, a1) = self.top.x_range();
        let (b0, b1) = self.bottom.x_range();
        let x = (a0.min(b0), a1.max(b1));
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, PANELS_SIZE).into_drawing_area();
            root.fill(&WHITE).map_err(draw_err)?;
            let (upper, lower) = root.split_vertically(PANELS_SPLIT);
            self.top.draw_on(&upper, Some(x))?;
            self.bottom.draw_on(&lower, Some(x))?;
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
                Series::points(
                    "measured",
                    x.clone(),
                    x.iter().map(|t| t.sin()).collect::<Vec<f64>>(),
                ),
                Series::line(
                    "model (fit 97.3 %)",
                    x.clone(),
                    x.iter().map(|t| t.sin() * 0.98).collect::<Vec<f64>>(),
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

    /// A deterministic pseudo-random sequence in [0, 1) (no RNG dependency needed).
    fn noise(n: usize, seed: u64) -> Vec<f64> {
        let mut z = seed;
        (0..n)
            .map(|_| {
                z = z
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1_442_695_040_888_963_407);
                (z >> 11) as f64 / (1u64 << 53) as f64
            })
            .collect()
    }

    #[test]
    fn million_sample_figures_stay_under_one_megabyte() {
        let n = 1_000_000;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 1e-3).collect();
        let e = noise(n, 7);
        let y: Vec<f64> = t.iter().zip(&e).map(|(t, e)| t.sin() + e - 0.5).collect();
        let smooth: Vec<f64> = t.iter().map(|t| t.sin()).collect();
        // A time series: measured dots and two lines.
        let time = Figure {
            title: "time series".into(),
            x_label: "t (s)".into(),
            y_label: "x (m)".into(),
            series: vec![
                Series::points("measured", t.clone(), y.clone()),
                Series::line("estimate", t.clone(), smooth.clone()),
                Series::line("noisy line", t.clone(), y.clone()),
            ],
            bands: vec![],
        };
        // A worst-case scatter: independent uniform noise filling the whole plot.
        let scatter = Figure {
            title: "scatter".into(),
            x_label: "u (N)".into(),
            y_label: "d".into(),
            series: vec![
                Series::points("a", noise(n, 1), noise(n, 2)),
                Series::points("b", noise(n, 3), noise(n, 4)),
            ],
            bands: vec![("band".into(), 0.5)],
        };
        for fig in [time, scatter] {
            let svg = fig.to_svg().unwrap();
            assert!(svg.len() < 1_000_000, "{}: {} bytes", fig.title, svg.len());
            for s in &fig.series {
                assert!(svg.contains(&s.label));
            }
        }
    }

    /// The saturating cast gives `floor(v).max(0)` clamped to the last cell, as the
    /// `floor` call it replaced, on negative, fractional, integral, huge, infinite and
    /// NaN values.
    #[test]
    fn cell_index_is_the_clamped_floor() {
        let values = [
            -1e300,
            -3.5,
            -1.0,
            -0.5,
            -0.0,
            0.0,
            0.25,
            0.999_999_999_999_999_9,
            1.0,
            2.5,
            299.0,
            299.999,
            300.0,
            1e20,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        for n in [1, 7, 300] {
            for v in values {
                let floor = (v.floor().max(0.0) as usize).min(n - 1);
                assert_eq!(cell_index(v, n), floor, "v = {v}, n = {n}");
            }
        }
    }

    #[test]
    fn decimation_keeps_every_column_extreme_in_order() {
        let n = 200_000;
        let x: Vec<f64> = (0..n).map(|k| k as f64).collect();
        let mut y = noise(n, 3);
        y[123_457] = 50.0; // one-sample spike
        y[7] = -40.0;
        let pts: Vec<(f64, f64)> = x.iter().copied().zip(y.iter().copied()).collect();
        let d = decimate_line(&pts, 0.0, (n - 1) as f64, 1000);
        assert!(d.len() <= 4000);
        assert!(d.contains(&(123_457.0, 50.0)));
        assert!(d.contains(&(7.0, -40.0)));
        assert_eq!(d.first(), pts.first());
        assert_eq!(d.last(), pts.last());
        assert!(d.windows(2).all(|w| w[0].0 < w[1].0), "order kept");
        // Same input, same output.
        assert_eq!(d, decimate_line(&pts, 0.0, (n - 1) as f64, 1000));
        // Short lines are untouched.
        assert_eq!(
            decimate_line(&pts[..100], 0.0, 99.0, 1000),
            pts[..100].to_vec()
        );
    }

    #[test]
    fn thinning_is_deterministic_and_keeps_isolated_points() {
        let n = 100_000;
        let mut pts: Vec<(f64, f64)> = noise(n, 5).into_iter().zip(noise(n, 6)).collect();
        pts.push((3.0, 3.0)); // an isolated outlier
        let a = thin_points(
            &[pts.as_slice()],
            (0.0, 3.0),
            (0.0, 3.0),
            (800, 400),
            DOT_BUDGET,
        );
        assert!(a[0].len() <= DOT_BUDGET);
        assert!(a[0].contains(&(3.0, 3.0)));
        assert_eq!(
            a,
            thin_points(&[&pts], (0.0, 3.0), (0.0, 3.0), (800, 400), DOT_BUDGET)
        );
    }

    /// The shared record figure of `fit` and `greyest`: two series per output above (its
    /// measured points, its simulated line with the caller's label), one residual per
    /// output below (measured − simulated, in its line's colour, NaN where a measurement
    /// is missing), and an error for shapes that do not match.
    #[test]
    fn outputs_with_residuals_draws_each_output_over_its_residual() {
        let n = 40;
        let t: Vec<f64> = (0..n).map(|k| 0.5 + 0.1 * k as f64).collect();
        let mut y = DMatrix::from_fn(2, n, |i, k| (i + 1) as f64 * (0.2 * k as f64).sin());
        y[(0, 7)] = f64::NAN; // a missing measurement
        let sim = DMatrix::from_fn(2, n, |i, k| 0.9 * (i + 1) as f64 * (0.2 * k as f64).sin());
        let record =
            Experiment::new(0.5, 0.1, DMatrix::from_element(1, n, 1.0), y.clone()).unwrap();
        let names = vec!["x".to_string(), "theta".to_string()];
        let units = BTreeMap::from([("x".to_string(), "m".to_string())]);
        let labels = vec![
            "x model (fit 90.0 %)".to_string(),
            "theta model".to_string(),
        ];
        let p =
            Panels::outputs_with_residuals("title".into(), &names, &units, &record, &sim, &labels)
                .unwrap();
        assert_eq!(p.top.series.len(), 2 * names.len());
        assert_eq!(p.bottom.series.len(), names.len());
        assert_eq!(p.top.title, "title");
        assert_eq!(p.top.y_label, "output (units in the legend)");
        let top: Vec<(&str, Mark)> = p
            .top
            .series
            .iter()
            .map(|s| (s.label.as_str(), s.mark))
            .collect();
        assert_eq!(
            top,
            [
                ("x (m) measured", Mark::Points),
                ("x model (fit 90.0 %)", Mark::Line),
                ("theta measured", Mark::Points),
                ("theta model", Mark::Line),
            ]
        );
        for (i, r) in p.bottom.series.iter().enumerate() {
            assert_eq!(r.label, format!("{} measured − simulated", names[i]));
            assert_eq!(r.colour, Some(2 * i + 1), "the colour of its line");
            assert_eq!(&*r.x, t.as_slice());
            assert_eq!(r.y[12].to_bits(), (y[(i, 12)] - sim[(i, 12)]).to_bits());
            assert_eq!(
                &*p.top.series[2 * i + 1].y,
                sim.row(i).iter().copied().collect::<Vec<f64>>().as_slice()
            );
        }
        // The missing measurement is neither a dot nor a residual point.
        assert!(p.top.series[0].y[7].is_nan() && p.bottom.series[0].y[7].is_nan());
        assert_eq!(finite(&p.top.series[0]).count(), n - 1);
        assert_eq!(finite(&p.bottom.series[0]).count(), n - 1);
        assert_eq!(finite(&p.bottom.series[1]).count(), n);
        let svg = p.to_svg().unwrap();
        for needle in [
            "x (m) measured",
            "x model (fit 90.0 %)",
            "theta measured − simulated",
        ] {
            assert!(svg.contains(needle), "missing {needle}");
        }
        // One output: its name and unit label the y axis.
        let one = Panels::outputs_with_residuals(
            "one".into(),
            &names[..1],
            &units,
            &Experiment::new(
                0.5,
                0.1,
                DMatrix::from_element(1, n, 1.0),
                y.rows(0, 1).into_owned(),
            )
            .unwrap(),
            &sim.rows(0, 1).into_owned(),
            &labels[..1],
        )
        .unwrap();
        assert_eq!(one.top.y_label, "x (m)");
        assert_eq!(one.bottom.y_label, "x (m)");
        // Shapes that do not match are an error, not a truncated or panicking figure.
        let short = sim.columns(0, n - 1).into_owned();
        let fig = |names: &[String], sim: &DMatrix<f64>, labels: &[String]| {
            Panels::outputs_with_residuals("bad".into(), names, &units, &record, sim, labels)
        };
        assert!(matches!(
            fig(&names, &short, &labels),
            Err(MmennError::Plot(_))
        ));
        assert!(fig(&names, &sim, &labels[..1]).is_err());
        assert!(fig(&names[..1], &sim, &labels[..1]).is_err());
        assert!(fig(&names, &sim.rows(0, 1).into_owned(), &labels).is_err());
    }

    #[test]
    fn panels_share_the_x_range_and_show_both_titles() {
        let x: Vec<f64> = (0..200).map(|k| k as f64).collect();
        let top = Figure {
            title: "upper title".into(),
            x_label: "t (s)".into(),
            y_label: "y".into(),
            series: vec![Series::line(
                "model",
                x.clone(),
                x.iter().map(|t| t.sin()).collect::<Vec<f64>>(),
            )],
            bands: vec![],
        };
        // The lower panel covers only half the time: its axis must still span all of it.
        let bottom = Figure {
            title: "lower title".into(),
            x_label: "t (s)".into(),
            y_label: "residual".into(),
            series: vec![Series::line("r", x[..100].to_vec(), vec![0.5; 100])],
            bands: vec![],
        };
        let top_alone = top.to_svg().unwrap();
        let svg = Panels { top, bottom }.to_svg().unwrap();
        assert!(svg.starts_with("<svg width=\"900\" height=\"720\""));
        for needle in ["upper title", "lower title", "residual", "model"] {
            assert!(svg.contains(needle), "missing {needle}");
        }
        // Tick labels beyond 150 can only be on an x axis (|y| ≤ 1 above, 0.5 below):
        // the lower panel, whose data end at 99, has them too when the axis is shared.
        let far_ticks = |svg: &str| {
            svg.split("</text>")
                .filter_map(|chunk| chunk.rsplit('>').next())
                .filter_map(|t| t.trim().parse::<f64>().ok())
                .filter(|v| *v >= 150.0)
                .count()
        };
        assert!(far_ticks(&top_alone) >= 1);
        assert_eq!(far_ticks(&svg), 2 * far_ticks(&top_alone));
    }
}
