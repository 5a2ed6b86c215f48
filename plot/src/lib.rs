//! Small, dependency-free SVG plots: line, marker, band and dashed series on linear or logarithmic
//! axes ([`Plot`]), and overlaid histograms ([`histogram_svg`]).
//!
//! Layout (pixels, SVG user units): the plot area spans from [`MARGIN_LEFT`] to `width −`
//! [`MARGIN_RIGHT`] horizontally and from [`MARGIN_TOP`] to `height −` [`MARGIN_BOTTOM`] vertically.
//! A value `v` on an axis with range `[lo, hi]` lands at the fraction `(t(v) − t(lo)) / (t(hi) − t(lo))`
//! of the area, with `t = log10` on a logarithmic axis and the identity otherwise; `y` grows upwards.
//! Linear ranges are widened to multiples of a "nice" tick step (1, 2 or 5 × 10ᵏ), logarithmic ones to
//! whole decades, with a tick at every decade. Non-finite points (and points ≤ 0 on a logarithmic axis)
//! are skipped; a plot without any drawable point still renders its frame, title and labels.
//!
//! ```
//! use plot::{Plot, Series, Style};
//! let plot = Plot {
//!     title: "held-out error".into(),
//!     x_label: "poses".into(),
//!     y_label: "error (m)".into(),
//!     log_x: true,
//!     log_y: true,
//!     series: vec![Series {
//!         label: "measured".into(),
//!         points: vec![(20.0, 3e-5), (40.0, 2e-5), (80.0, 1.4e-5)],
//!         style: Style::LineMarkers,
//!     }],
//! };
//! let svg = plot.to_svg(640, 420);
//! assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
//! ```

#![warn(missing_docs)]

use std::fmt::Write;

/// Left margin of the plot area (px): room for the y tick labels and the y label.
pub const MARGIN_LEFT: f64 = 70.0;
/// Right margin of the plot area (px).
pub const MARGIN_RIGHT: f64 = 20.0;
/// Top margin of the plot area (px): room for the title.
pub const MARGIN_TOP: f64 = 40.0;
/// Bottom margin of the plot area (px): room for the x tick labels and the x label.
pub const MARGIN_BOTTOM: f64 = 50.0;

/// Series colours, in order (a colour-blind-friendly qualitative palette).
pub const PALETTE: [&str; 8] = [
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf",
];

/// A 2-D plot: axes, labels and series. Units are whatever the labels say.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Plot {
    /// Title above the plot area.
    pub title: String,
    /// Label of the horizontal axis (name the unit, e.g. `poses` or `error (m)`).
    pub x_label: String,
    /// Label of the vertical axis.
    pub y_label: String,
    /// Logarithmic horizontal axis (decades).
    pub log_x: bool,
    /// Logarithmic vertical axis (decades).
    pub log_y: bool,
    /// What is drawn, in drawing order (later series on top).
    pub series: Vec<Series>,
}

/// One data series. Series with the same label share a colour and one legend entry (so a measured
/// median, its band and a prediction can be grouped under one name); colours follow [`PALETTE`] in
/// order of the first appearance of each label. An empty label leaves the series out of the legend.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// Data points `(x, y)` in axis units; for [`Style::Band`], `(x, lower)`.
    pub points: Vec<(f64, f64)>,
    /// How the points are drawn.
    pub style: Style,
}

/// How a series is drawn.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum Style {
    /// A solid polyline (broken where a point is skipped).
    #[default]
    Line,
    /// A circle at each point.
    Markers,
    /// A solid polyline with a circle at each point.
    LineMarkers,
    /// A filled, semi-transparent band between `points[i].1` (lower) and `upper[i]` at `points[i].0`.
    /// Pairs where either bound cannot be drawn are skipped; `upper` shorter than `points` cuts the band.
    Band {
        /// Upper bound per point (axis units).
        upper: Vec<f64>,
    },
    /// A dashed polyline.
    Dashed,
}

/// One axis: range in transformed units (`log10` when logarithmic) and its ticks.
#[derive(Clone, Debug, PartialEq)]
struct Axis {
    log: bool,
    /// Range in transformed units.
    t0: f64,
    t1: f64,
    /// Labelled ticks, transformed units.
    ticks: Vec<f64>,
    /// Unlabelled ticks (2…9 × 10ᵏ on a log axis), transformed units.
    minor: Vec<f64>,
}

impl Axis {
    /// An axis covering the values `v` (non-drawable ones ignored).
    fn covering(values: impl Iterator<Item = f64>, log: bool) -> Axis {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for v in values {
            if let Some(t) = transform(v, log) {
                lo = lo.min(t);
                hi = hi.max(t);
            }
        }
        if log {
            log_axis(lo, hi)
        } else {
            linear_axis(lo, hi)
        }
    }

    /// Fraction `[0, 1]` of the axis at value `v`, or `None` when `v` cannot be drawn.
    fn fraction(&self, v: f64) -> Option<f64> {
        transform(v, self.log).map(|t| (t - self.t0) / (self.t1 - self.t0))
    }

    /// Label of a tick at transformed position `t`.
    fn label(&self, t: f64) -> String {
        if self.log {
            let k = t.round() as i32;
            if (-3..=3).contains(&k) {
                format_number(10f64.powi(k), 10f64.powi(k))
            } else {
                format!("1e{k}")
            }
        } else {
            let step = if self.ticks.len() >= 2 {
                self.ticks[1] - self.ticks[0]
            } else {
                1.0
            };
            format_number(t, step)
        }
    }
}

/// `v` in axis units (`log10 v` on a log axis), or `None` when not drawable.
fn transform(v: f64, log: bool) -> Option<f64> {
    if !v.is_finite() {
        return None;
    }
    if log {
        (v > 0.0).then(|| v.log10())
    } else {
        Some(v)
    }
}

/// A linear axis from `lo` to `hi` (infinite when there was no value), widened to nice steps.
fn linear_axis(lo: f64, hi: f64) -> Axis {
    let (mut lo, mut hi) = if lo.is_finite() { (lo, hi) } else { (0.0, 1.0) };
    if hi - lo <= f64::EPSILON * lo.abs().max(hi.abs()).max(f64::MIN_POSITIVE) {
        let d = if lo == 0.0 { 1.0 } else { 0.1 * lo.abs() };
        lo -= d;
        hi += d;
    }
    let step = nice_step((hi - lo) / 5.0);
    let t0 = (lo / step).floor() * step;
    let t1 = (hi / step).ceil() * step;
    let n = ((t1 - t0) / step).round() as usize;
    let ticks = (0..=n).map(|i| t0 + i as f64 * step).collect();
    Axis {
        log: false,
        t0,
        t1,
        ticks,
        minor: Vec::new(),
    }
}

/// 1, 2 or 5 × 10ᵏ, the smallest such value ≥ `raw`.
fn nice_step(raw: f64) -> f64 {
    let mag = 10f64.powf(raw.log10().floor());
    let f = raw / mag;
    let m = if f <= 1.0 + 1e-9 {
        1.0
    } else if f <= 2.0 + 1e-9 {
        2.0
    } else if f <= 5.0 + 1e-9 {
        5.0
    } else {
        10.0
    };
    m * mag
}

/// A log axis from decade exponents `lo` to `hi` (log10 of the values), widened to whole decades.
fn log_axis(lo: f64, hi: f64) -> Axis {
    let (d0, mut d1) = if lo.is_finite() {
        ((lo + 1e-12).floor(), (hi - 1e-12).ceil())
    } else {
        (0.0, 1.0)
    };
    if d1 <= d0 {
        // A single decade value: show the decade above it.
        d1 = d0 + 1.0;
    }
    let decades = (d1 - d0).round() as usize;
    // A labelled tick every `every` decades so that at most about 8 labels are written.
    let every = decades.div_ceil(8).max(1);
    let ticks = (0..=decades)
        .filter(|i| i % every == 0)
        .map(|i| d0 + i as f64)
        .collect();
    let minor = if decades <= 6 {
        (0..decades)
            .flat_map(|i| (2..10).map(move |m| d0 + i as f64 + (m as f64).log10()))
            .collect()
    } else {
        Vec::new()
    };
    Axis {
        log: true,
        t0: d0,
        t1: d1,
        ticks,
        minor,
    }
}

/// A number written with as many decimals as `step` needs (scientific when very large or small).
fn format_number(v: f64, step: f64) -> String {
    if v == 0.0 || v.abs() < 1e-12 * step.abs() {
        return "0".into();
    }
    let a = v.abs();
    if !(1e-4..1e5).contains(&a) {
        let s = format!("{v:.2e}");
        // 1.00e-5 -> 1e-5, 2.50e-5 -> 2.5e-5
        let (m, e) = s.split_once('e').unwrap_or((&s, "0"));
        let m = m.trim_end_matches('0').trim_end_matches('.');
        return format!("{m}e{e}");
    }
    let decimals = (-step.abs().log10().floor()).max(0.0) as usize;
    format!("{v:.decimals$}")
}

/// Escapes text for SVG content and attributes.
fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            _ => out.push(c),
        }
    }
    out
}

/// The plot area and the two axes: maps values to pixels.
struct Frame {
    width: f64,
    height: f64,
    x: Axis,
    y: Axis,
}

impl Frame {
    fn area_w(&self) -> f64 {
        (self.width - MARGIN_LEFT - MARGIN_RIGHT).max(1.0)
    }
    fn area_h(&self) -> f64 {
        (self.height - MARGIN_TOP - MARGIN_BOTTOM).max(1.0)
    }
    /// Pixel of the point `(x, y)`, or `None` when it cannot be drawn.
    fn pixel(&self, x: f64, y: f64) -> Option<(f64, f64)> {
        let fx = self.x.fraction(x)?;
        let fy = self.y.fraction(y)?;
        Some((
            MARGIN_LEFT + fx * self.area_w(),
            MARGIN_TOP + (1.0 - fy) * self.area_h(),
        ))
    }

    /// Opening tag, background, title, axes, ticks, grid and labels; the clip path `plot-area`.
    fn begin(&self, title: &str, x_label: &str, y_label: &str) -> String {
        let (w, h) = (self.width, self.height);
        let (aw, ah) = (self.area_w(), self.area_h());
        let mut s = String::new();
        let _ = writeln!(
            s,
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" \
             viewBox=\"0 0 {w} {h}\" font-family=\"sans-serif\" font-size=\"12\">"
        );
        let _ = writeln!(
            s,
            "<defs><clipPath id=\"plot-area\"><rect x=\"{MARGIN_LEFT:.2}\" y=\"{MARGIN_TOP:.2}\" \
             width=\"{aw:.2}\" height=\"{ah:.2}\"/></clipPath></defs>"
        );
        let _ = writeln!(
            s,
            "<rect x=\"0\" y=\"0\" width=\"{w}\" height=\"{h}\" fill=\"white\"/>"
        );
        let _ = writeln!(
            s,
            "<text x=\"{:.2}\" y=\"{:.2}\" text-anchor=\"middle\" font-size=\"14\">{}</text>",
            w / 2.0,
            MARGIN_TOP / 2.0 + 5.0,
            escape(title)
        );
        let bottom = MARGIN_TOP + ah;
        let right = MARGIN_LEFT + aw;
        // Grid and ticks.
        s.push_str("<g stroke=\"#dddddd\" stroke-width=\"1\">\n");
        for &t in &self.x.ticks {
            let px = MARGIN_LEFT + (t - self.x.t0) / (self.x.t1 - self.x.t0) * aw;
            let _ = writeln!(
                s,
                "<line x1=\"{px:.2}\" y1=\"{MARGIN_TOP:.2}\" x2=\"{px:.2}\" y2=\"{bottom:.2}\"/>"
            );
        }
        for &t in &self.y.ticks {
            let py = MARGIN_TOP + (1.0 - (t - self.y.t0) / (self.y.t1 - self.y.t0)) * ah;
            let _ = writeln!(
                s,
                "<line x1=\"{MARGIN_LEFT:.2}\" y1=\"{py:.2}\" x2=\"{right:.2}\" y2=\"{py:.2}\"/>"
            );
        }
        s.push_str("</g>\n<g stroke=\"black\" stroke-width=\"1\">\n");
        for (&t, len) in self
            .x
            .ticks
            .iter()
            .map(|t| (t, 6.0))
            .chain(self.x.minor.iter().map(|t| (t, 3.0)))
        {
            let px = MARGIN_LEFT + (t - self.x.t0) / (self.x.t1 - self.x.t0) * aw;
            let _ = writeln!(
                s,
                "<line x1=\"{px:.2}\" y1=\"{bottom:.2}\" x2=\"{px:.2}\" y2=\"{:.2}\"/>",
                bottom + len
            );
        }
        for (&t, len) in self
            .y
            .ticks
            .iter()
            .map(|t| (t, 6.0))
            .chain(self.y.minor.iter().map(|t| (t, 3.0)))
        {
            let py = MARGIN_TOP + (1.0 - (t - self.y.t0) / (self.y.t1 - self.y.t0)) * ah;
            let _ = writeln!(
                s,
                "<line x1=\"{MARGIN_LEFT:.2}\" y1=\"{py:.2}\" x2=\"{:.2}\" y2=\"{py:.2}\"/>",
                MARGIN_LEFT - len
            );
        }
        let _ = writeln!(
            s,
            "<rect x=\"{MARGIN_LEFT:.2}\" y=\"{MARGIN_TOP:.2}\" width=\"{aw:.2}\" height=\"{ah:.2}\" \
             fill=\"none\"/>"
        );
        s.push_str("</g>\n");
        // Tick labels.
        for &t in &self.x.ticks {
            let px = MARGIN_LEFT + (t - self.x.t0) / (self.x.t1 - self.x.t0) * aw;
            let _ = writeln!(
                s,
                "<text class=\"tick-x\" x=\"{px:.2}\" y=\"{:.2}\" text-anchor=\"middle\">{}</text>",
                bottom + 20.0,
                escape(&self.x.label(t))
            );
        }
        for &t in &self.y.ticks {
            let py = MARGIN_TOP + (1.0 - (t - self.y.t0) / (self.y.t1 - self.y.t0)) * ah;
            let _ = writeln!(
                s,
                "<text class=\"tick-y\" x=\"{:.2}\" y=\"{:.2}\" text-anchor=\"end\">{}</text>",
                MARGIN_LEFT - 9.0,
                py + 4.0,
                escape(&self.y.label(t))
            );
        }
        let _ = writeln!(
            s,
            "<text x=\"{:.2}\" y=\"{:.2}\" text-anchor=\"middle\">{}</text>",
            MARGIN_LEFT + aw / 2.0,
            h - 10.0,
            escape(x_label)
        );
        let _ = writeln!(
            s,
            "<text x=\"16\" y=\"{y:.2}\" text-anchor=\"middle\" transform=\"rotate(-90 16 {y:.2})\">{}</text>",
            escape(y_label),
            y = MARGIN_TOP + ah / 2.0
        );
        s
    }

    /// A legend box in the top right corner of the plot area; `entries` are (label, colour, style).
    fn legend(&self, entries: &[(String, &str, LegendMark)]) -> String {
        let mut s = String::new();
        if entries.is_empty() {
            return s;
        }
        let longest = entries
            .iter()
            .map(|(l, _, _)| l.chars().count())
            .max()
            .unwrap_or(0) as f64;
        let bw = 40.0 + 7.0 * longest;
        let bh = 8.0 + 18.0 * entries.len() as f64;
        let x0 = MARGIN_LEFT + self.area_w() - bw - 8.0;
        let y0 = MARGIN_TOP + 8.0;
        let _ = writeln!(
            s,
            "<g class=\"legend\"><rect x=\"{x0:.2}\" y=\"{y0:.2}\" width=\"{bw:.2}\" height=\"{bh:.2}\" \
             fill=\"white\" fill-opacity=\"0.85\" stroke=\"#999999\"/>"
        );
        for (i, (label, colour, mark)) in entries.iter().enumerate() {
            let y = y0 + 4.0 + 18.0 * i as f64 + 9.0;
            let (a, b) = (x0 + 6.0, x0 + 28.0);
            match mark {
                LegendMark::Line { dashed, marker } => {
                    let dash = if *dashed {
                        " stroke-dasharray=\"6 4\""
                    } else {
                        ""
                    };
                    let _ = writeln!(
                        s,
                        "<line x1=\"{a:.2}\" y1=\"{y:.2}\" x2=\"{b:.2}\" y2=\"{y:.2}\" stroke=\"{colour}\" \
                         stroke-width=\"2\"{dash}/>"
                    );
                    if *marker {
                        let _ = writeln!(
                            s,
                            "<circle cx=\"{:.2}\" cy=\"{y:.2}\" r=\"3\" fill=\"{colour}\"/>",
                            (a + b) / 2.0
                        );
                    }
                }
                LegendMark::Marker => {
                    let _ = writeln!(
                        s,
                        "<circle cx=\"{:.2}\" cy=\"{y:.2}\" r=\"3\" fill=\"{colour}\"/>",
                        (a + b) / 2.0
                    );
                }
                LegendMark::Patch => {
                    let _ = writeln!(
                        s,
                        "<rect x=\"{a:.2}\" y=\"{:.2}\" width=\"{:.2}\" height=\"10\" fill=\"{colour}\" \
                         fill-opacity=\"0.45\"/>",
                        y - 5.0,
                        b - a
                    );
                }
            }
            let _ = writeln!(
                s,
                "<text x=\"{:.2}\" y=\"{:.2}\">{}</text>",
                b + 6.0,
                y + 4.0,
                escape(label)
            );
        }
        s.push_str("</g>\n");
        s
    }
}

/// What a legend entry shows.
#[derive(Clone, Copy, Debug)]
enum LegendMark {
    Line { dashed: bool, marker: bool },
    Marker,
    Patch,
}

fn mark_of(style: &Style) -> LegendMark {
    match style {
        Style::Line => LegendMark::Line {
            dashed: false,
            marker: false,
        },
        Style::LineMarkers => LegendMark::Line {
            dashed: false,
            marker: true,
        },
        Style::Dashed => LegendMark::Line {
            dashed: true,
            marker: false,
        },
        Style::Markers => LegendMark::Marker,
        Style::Band { .. } => LegendMark::Patch,
    }
}

/// Polylines through the drawable points, broken at skipped ones.
fn polylines(frame: &Frame, points: &[(f64, f64)], colour: &str, dashed: bool) -> String {
    let mut s = String::new();
    let mut run: Vec<(f64, f64)> = Vec::new();
    let dash = if dashed {
        " stroke-dasharray=\"6 4\""
    } else {
        ""
    };
    let flush = |run: &mut Vec<(f64, f64)>, s: &mut String| {
        if run.len() >= 2 {
            s.push_str("<polyline points=\"");
            for (i, (x, y)) in run.iter().enumerate() {
                if i > 0 {
                    s.push(' ');
                }
                let _ = write!(s, "{x:.2},{y:.2}");
            }
            let _ = writeln!(
                s,
                "\" fill=\"none\" stroke=\"{colour}\" stroke-width=\"2\"{dash}/>"
            );
        }
        run.clear();
    };
    for &(x, y) in points {
        match frame.pixel(x, y) {
            Some(p) => run.push(p),
            None => flush(&mut run, &mut s),
        }
    }
    flush(&mut run, &mut s);
    s
}

fn markers(frame: &Frame, points: &[(f64, f64)], colour: &str) -> String {
    let mut s = String::new();
    for &(x, y) in points {
        if let Some((px, py)) = frame.pixel(x, y) {
            let _ = writeln!(
                s,
                "<circle cx=\"{px:.2}\" cy=\"{py:.2}\" r=\"3\" fill=\"{colour}\"/>"
            );
        }
    }
    s
}

fn band(frame: &Frame, points: &[(f64, f64)], upper: &[f64], colour: &str) -> String {
    let pairs: Vec<((f64, f64), (f64, f64))> = points
        .iter()
        .zip(upper)
        .filter_map(|(&(x, lo), &hi)| Some((frame.pixel(x, lo)?, frame.pixel(x, hi)?)))
        .collect();
    if pairs.len() < 2 {
        return String::new();
    }
    let mut s = String::from("<polygon points=\"");
    let all = pairs
        .iter()
        .map(|p| p.0)
        .chain(pairs.iter().rev().map(|p| p.1));
    for (i, (x, y)) in all.enumerate() {
        if i > 0 {
            s.push(' ');
        }
        let _ = write!(s, "{x:.2},{y:.2}");
    }
    let _ = writeln!(
        s,
        "\" fill=\"{colour}\" fill-opacity=\"0.2\" stroke=\"none\"/>"
    );
    s
}

impl Plot {
    /// The plot as a standalone SVG document of `width_px` × `height_px` pixels.
    pub fn to_svg(&self, width_px: u32, height_px: u32) -> String {
        let xs = self
            .series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.0));
        let ys = self.series.iter().flat_map(|s| {
            let upper: &[f64] = match &s.style {
                Style::Band { upper } => upper,
                _ => &[],
            };
            s.points.iter().map(|p| p.1).chain(upper.iter().copied())
        });
        let frame = Frame {
            width: f64::from(width_px.max(1)),
            height: f64::from(height_px.max(1)),
            x: Axis::covering(xs, self.log_x),
            y: Axis::covering(ys, self.log_y),
        };
        let mut s = frame.begin(&self.title, &self.x_label, &self.y_label);
        // Colours per distinct label, in order of first appearance.
        let mut labels: Vec<&str> = Vec::new();
        let mut legend: Vec<(String, &str, LegendMark)> = Vec::new();
        s.push_str("<g clip-path=\"url(#plot-area)\">\n");
        for series in &self.series {
            let idx = match labels.iter().position(|l| *l == series.label) {
                Some(i) => i,
                None => {
                    labels.push(&series.label);
                    if !series.label.is_empty() {
                        legend.push((
                            series.label.clone(),
                            PALETTE[(labels.len() - 1) % PALETTE.len()],
                            mark_of(&series.style),
                        ));
                    }
                    labels.len() - 1
                }
            };
            let colour = PALETTE[idx % PALETTE.len()];
            let p = &series.points;
            match &series.style {
                Style::Line => s.push_str(&polylines(&frame, p, colour, false)),
                Style::Dashed => s.push_str(&polylines(&frame, p, colour, true)),
                Style::Markers => s.push_str(&markers(&frame, p, colour)),
                Style::LineMarkers => {
                    s.push_str(&polylines(&frame, p, colour, false));
                    s.push_str(&markers(&frame, p, colour));
                }
                Style::Band { upper } => s.push_str(&band(&frame, p, upper, colour)),
            }
        }
        s.push_str("</g>\n");
        s.push_str(&frame.legend(&legend));
        s.push_str("</svg>\n");
        s
    }
}

/// Counts of the finite values of `values` in `bins` equal bins from `lo` to `hi` (the last bin closed).
fn bin_counts(values: &[f64], lo: f64, hi: f64, bins: usize) -> Vec<usize> {
    let mut counts = vec![0; bins];
    let w = (hi - lo) / bins as f64;
    for &v in values {
        if v.is_finite() && v >= lo && v <= hi {
            let k = (((v - lo) / w).floor() as usize).min(bins - 1);
            counts[k] += 1;
        }
    }
    counts
}

/// Overlaid, semi-transparent histograms of `datasets` (label, values) in `bins` common equal-width bins
/// over the range of all finite values; the vertical axis counts values per bin. Non-finite values are
/// skipped; `bins = 0` is taken as 1.
pub fn histogram_svg(
    title: &str,
    x_label: &str,
    datasets: &[(&str, &[f64])],
    bins: usize,
    width_px: u32,
    height_px: u32,
) -> String {
    let bins = bins.max(1);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (_, v) in datasets {
        for &x in v.iter().filter(|x| x.is_finite()) {
            lo = lo.min(x);
            hi = hi.max(x);
        }
    }
    if !lo.is_finite() {
        (lo, hi) = (0.0, 1.0);
    }
    if hi <= lo {
        (lo, hi) = (lo - 0.5, hi + 0.5);
    }
    let counts: Vec<Vec<usize>> = datasets
        .iter()
        .map(|(_, v)| bin_counts(v, lo, hi, bins))
        .collect();
    let top = counts.iter().flatten().copied().max().unwrap_or(0).max(1);
    let mut x = linear_axis(lo, hi);
    // Bars must fill exactly [lo, hi]; keep the nice ticks but widen only as they require.
    x.t0 = x.t0.min(lo);
    x.t1 = x.t1.max(hi);
    let frame = Frame {
        width: f64::from(width_px.max(1)),
        height: f64::from(height_px.max(1)),
        x,
        y: linear_axis(0.0, top as f64),
    };
    let mut s = frame.begin(title, x_label, "count");
    let w = (hi - lo) / bins as f64;
    let mut legend = Vec::new();
    s.push_str("<g clip-path=\"url(#plot-area)\">\n");
    for (d, c) in counts.iter().enumerate() {
        let colour = PALETTE[d % PALETTE.len()];
        if !datasets[d].0.is_empty() {
            legend.push((datasets[d].0.to_string(), colour, LegendMark::Patch));
        }
        for (k, &n) in c.iter().enumerate() {
            if n == 0 {
                continue;
            }
            let a = lo + k as f64 * w;
            if let (Some((x0, y0)), Some((x1, y1))) =
                (frame.pixel(a, n as f64), frame.pixel(a + w, 0.0))
            {
                let _ = writeln!(
                    s,
                    "<rect class=\"bar\" x=\"{x0:.2}\" y=\"{y0:.2}\" width=\"{:.2}\" height=\"{:.2}\" \
                     fill=\"{colour}\" fill-opacity=\"0.45\" stroke=\"{colour}\"/>",
                    x1 - x0,
                    y1 - y0
                );
            }
        }
    }
    s.push_str("</g>\n");
    s.push_str(&frame.legend(&legend));
    s.push_str("</svg>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Checks that every element opened is closed in order (a small XML well-formedness check) and
    /// returns the number of elements.
    fn check_balanced(svg: &str) -> usize {
        let mut stack: Vec<String> = Vec::new();
        let mut count = 0;
        let mut rest = svg;
        while let Some(i) = rest.find('<') {
            let j = rest[i..].find('>').expect("unterminated tag") + i;
            let tag = &rest[i + 1..j];
            assert!(!tag.contains('<'), "'<' inside a tag: {tag}");
            if let Some(name) = tag.strip_prefix('/') {
                assert_eq!(
                    stack.pop().as_deref(),
                    Some(name.trim()),
                    "mismatched </{name}>"
                );
            } else {
                count += 1;
                let name = tag.split_whitespace().next().unwrap().trim_end_matches('/');
                if !tag.ends_with('/') {
                    stack.push(name.to_string());
                }
            }
            rest = &rest[j + 1..];
        }
        assert!(stack.is_empty(), "unclosed: {stack:?}");
        // Text outside tags must not hold a raw '&' that is not an entity.
        for (k, _) in svg.match_indices('&') {
            let ent = &svg[k..(k + 6).min(svg.len())];
            assert!(
                ["&amp;", "&lt;", "&gt;", "&quot", "&#39;"]
                    .iter()
                    .any(|e| ent.starts_with(e)),
                "raw & at {k}"
            );
        }
        count
    }

    fn attr_values(svg: &str, element: &str, attr: &str) -> Vec<String> {
        svg.lines()
            .filter(|l| l.trim_start().starts_with(&format!("<{element} ")))
            .filter_map(|l| {
                let key = format!(" {attr}=\"");
                let a = l.find(&key)? + key.len();
                let b = l[a..].find('"')? + a;
                Some(l[a..b].to_string())
            })
            .collect()
    }

    fn sample() -> Plot {
        Plot {
            title: "error <m> & more".into(),
            x_label: "poses".into(),
            y_label: "error (m)".into(),
            log_x: true,
            log_y: true,
            series: vec![
                Series {
                    label: "a".into(),
                    points: vec![(20.0, 1e-5), (40.0, 7e-6), (80.0, 5e-6)],
                    style: Style::Band {
                        upper: vec![2e-5, 1.4e-5, 1e-5],
                    },
                },
                Series {
                    label: "a".into(),
                    points: vec![
                        (20.0, 1.5e-5),
                        (30.0, 1.2e-5),
                        (40.0, f64::NAN),
                        (80.0, 7e-6),
                    ],
                    style: Style::LineMarkers,
                },
                Series {
                    label: "b".into(),
                    points: vec![(20.0, 3e-5), (80.0, 1.5e-5)],
                    style: Style::Dashed,
                },
                Series {
                    label: "c".into(),
                    points: vec![(30.0, 2e-6)],
                    style: Style::Markers,
                },
            ],
        }
    }

    #[test]
    fn svg_is_well_formed_and_escapes_text() {
        let svg = sample().to_svg(640, 400);
        assert!(svg.starts_with("<svg "));
        assert!(svg.trim_end().ends_with("</svg>"));
        assert!(check_balanced(&svg) > 20);
        assert!(svg.contains("error &lt;m&gt; &amp; more"));
        assert!(!svg.contains("NaN") && !svg.contains("inf"));
        // Three legend entries (a, b, c): "a" twice shares one entry and one colour.
        assert_eq!(svg.matches("<g class=\"legend\">").count(), 1);
        let legend = &svg[svg.find("class=\"legend\"").unwrap()..];
        assert_eq!(legend.matches("<text ").count(), 3);
        let band_colour = attr_values(&svg, "polygon", "fill");
        let line_colour = attr_values(&svg, "polyline", "stroke");
        assert_eq!(band_colour[0], PALETTE[0]);
        assert_eq!(line_colour[0], PALETTE[0]);
        assert!(svg.contains(&format!(
            "stroke=\"{}\" stroke-width=\"2\" stroke-dasharray",
            PALETTE[1]
        )));
    }

    #[test]
    fn log_ticks_sit_at_decades() {
        // Values from 3e-6 to 2e-3 span the decades 1e-6 … 1e-2.
        let a = Axis::covering([3e-6, 2e-3, -1.0, 0.0, f64::NAN].into_iter(), true);
        assert_eq!(a.ticks, vec![-6.0, -5.0, -4.0, -3.0, -2.0]);
        assert_eq!((a.t0, a.t1), (-6.0, -2.0));
        assert_eq!(a.label(-5.0), "1e-5");
        assert_eq!(a.label(-2.0), "0.01");
        assert_eq!(a.label(2.0), "100");
        // Minor ticks at 2…9 × 10ᵏ: 8 per decade.
        assert_eq!(a.minor.len(), 32);
        assert!((a.minor[0] - 2f64.log10() - (-6.0)).abs() < 1e-12);
        // Exact decades stay on the boundary: 1e-6 … 1e-3 is three decades, not five.
        let b = Axis::covering([1e-6, 1e-3].into_iter(), true);
        assert_eq!((b.t0, b.t1), (-6.0, -3.0));
        // Labels in the SVG: one per decade on the y axis.
        let svg = sample().to_svg(640, 400);
        let labels: Vec<&str> = svg
            .lines()
            .filter(|l| l.contains("class=\"tick-y\""))
            .map(|l| &l[l.find('>').unwrap() + 1..l.find("</text>").unwrap()])
            .collect();
        assert_eq!(labels, vec!["1e-6", "1e-5", "1e-4"]);
    }

    #[test]
    fn a_point_lands_on_its_hand_computed_pixel() {
        // 400 × 300 px: plot area x 70 … 380 (310 px wide), y 40 … 250 (210 px high).
        // Linear axes over 0 … 10 (nice step 2): (5, 5) is the centre, (70 + 155, 40 + 105) = (225, 145);
        // (2.5, 7.5) is at x 70 + 0.25·310 = 147.5, y 40 + 0.25·210 = 92.5.
        let plot = Plot {
            series: vec![Series {
                label: String::new(),
                points: vec![(0.0, 0.0), (5.0, 5.0), (2.5, 7.5), (10.0, 10.0)],
                style: Style::Markers,
            }],
            ..Plot::default()
        };
        let svg = plot.to_svg(400, 300);
        assert!(svg.contains("cx=\"225.00\" cy=\"145.00\""), "{svg}");
        assert!(svg.contains("cx=\"147.50\" cy=\"92.50\""));
        assert!(svg.contains("cx=\"70.00\" cy=\"250.00\""));
        // Log x over 1 … 100 (two decades): x = 10 is the middle, 225; linear y over 0 … 1 (step 0.2).
        let plot = Plot {
            log_x: true,
            series: vec![Series {
                label: "p".into(),
                points: vec![(1.0, 0.0), (10.0, 0.5), (100.0, 1.0)],
                style: Style::Markers,
            }],
            ..Plot::default()
        };
        let svg = plot.to_svg(400, 300);
        assert!(svg.contains("cx=\"225.00\" cy=\"145.00\""), "{svg}");
    }

    #[test]
    fn empty_and_degenerate_plots_still_render() {
        for plot in [
            Plot::default(),
            Plot {
                log_x: true,
                log_y: true,
                series: vec![Series {
                    label: "nothing drawable".into(),
                    points: vec![(f64::NAN, 1.0), (-1.0, 2.0), (f64::INFINITY, 0.0)],
                    style: Style::Line,
                }],
                ..Plot::default()
            },
            Plot {
                series: vec![Series {
                    label: "one point".into(),
                    points: vec![(3.0, 3.0)],
                    style: Style::LineMarkers,
                }],
                ..Plot::default()
            },
        ] {
            let svg = plot.to_svg(300, 200);
            check_balanced(&svg);
            assert!(!svg.contains("NaN"));
        }
    }

    #[test]
    fn nice_linear_ticks() {
        let a = linear_axis(0.13, 0.87);
        assert_eq!(a.ticks.len(), 6);
        assert!((a.t0 - 0.0).abs() < 1e-12 && (a.t1 - 1.0).abs() < 1e-12);
        assert_eq!(a.label(a.ticks[1]), "0.2");
        let b = linear_axis(3.0, 3.0);
        assert!(b.t0 < 3.0 && b.t1 > 3.0);
        assert_eq!(nice_step(0.3), 0.5);
        assert_eq!(nice_step(7.0), 10.0);
        assert_eq!(nice_step(2.0), 2.0);
    }

    #[test]
    fn histogram_counts_and_bars() {
        let a = [0.0, 0.1, 0.2, 0.9, 1.0, f64::NAN];
        let b = [0.5, 0.55];
        assert_eq!(bin_counts(&a, 0.0, 1.0, 4), vec![3, 0, 0, 2]);
        let svg = histogram_svg("h", "value (m)", &[("a", &a), ("b", &b)], 4, 400, 300);
        check_balanced(&svg);
        // Non-empty bins: a has 2, b has 1.
        assert_eq!(svg.matches("class=\"bar\"").count(), 3);
        assert!(svg.contains("fill-opacity=\"0.45\""));
        // The tallest bar (3 counts) reaches the top of the count axis 0 … 3 (step 1):
        // y = 40 px, bars start at x = 70 px (value 0).
        assert!(
            svg.contains("class=\"bar\" x=\"70.00\" y=\"40.00\""),
            "{svg}"
        );
        let empty = histogram_svg("none", "x", &[], 10, 300, 200);
        check_balanced(&empty);
    }
}
