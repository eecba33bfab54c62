//! Reusable plotting helpers: figures made of a grid of time-series panels, rendered to SVG or
//! PNG (chosen by the file extension) with the embedded DejaVu Sans font, so that no system font
//! is needed. Files are written atomically.

use anyhow::{anyhow, bail, Result};
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use std::path::Path;

/// DejaVu Sans (licence: `assets/DejaVuSans-LICENSE.txt`).
static FONT: &[u8] = include_bytes!("../../../assets/DejaVuSans.ttf");

/// Font family name used for all text.
pub(crate) const FAMILY: &str = "sans-serif";

/// Register the embedded font once (plotters' ab_glyph font table is global).
pub(crate) fn register_font() -> Result<()> {
    static ONCE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok = *ONCE
        .get_or_init(|| plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_ok());
    if ok {
        Ok(())
    } else {
        bail!("the embedded font could not be loaded")
    }
}

/// Colour-blind-safe palette (Okabe-Ito), indexed by [`Series::color`].
pub(crate) const PALETTE: [RGBColor; 7] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(0, 0, 0),
];

/// One line of a panel.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// Abscissa values (e.g. time [s]).
    pub x: Vec<f64>,
    /// Ordinate values, same length as `x`.
    pub y: Vec<f64>,
    /// Palette index.
    pub color: usize,
    /// Dashed instead of solid.
    pub dashed: bool,
    /// Markers at the points instead of a line.
    pub markers: bool,
    /// Radius of the markers [px].
    pub marker_radius: u32,
}

impl Series {
    /// A solid line.
    pub fn line(label: impl Into<String>, x: &[f64], y: &[f64], color: usize) -> Self {
        Self {
            label: label.into(),
            x: x.to_vec(),
            y: y.to_vec(),
            color,
            dashed: false,
            markers: false,
            marker_radius: 6,
        }
    }

    /// A dashed line.
    pub fn dashed(label: impl Into<String>, x: &[f64], y: &[f64], color: usize) -> Self {
        Self {
            dashed: true,
            ..Self::line(label, x, y, color)
        }
    }

    /// Circle markers at the points (e.g. an extremum).
    pub fn markers(label: impl Into<String>, x: &[f64], y: &[f64], color: usize) -> Self {
        Self {
            markers: true,
            ..Self::line(label, x, y, color)
        }
    }

    /// Smaller (or larger) markers: `r` pixels (for many points).
    pub fn radius(mut self, r: u32) -> Self {
        self.marker_radius = r;
        self
    }

    /// A dashed horizontal line at `y` over `[x0, x1]` (e.g. a steady-state value).
    pub fn hline(label: impl Into<String>, x0: f64, x1: f64, y: f64, color: usize) -> Self {
        Self::dashed(label, &[x0, x1], &[y, y], color)
    }
}

/// One axes: several series sharing x and y axes, with a legend.
#[derive(Debug, Clone)]
pub struct Panel {
    /// Title above the panel (optional).
    pub title: Option<String>,
    /// Abscissa label with unit, e.g. `t [s]`.
    pub x_label: String,
    /// Ordinate label with unit, e.g. `W_c [kg/s]`.
    pub y_label: String,
    /// The lines.
    pub series: Vec<Series>,
    /// The series' x are log10 of the quantity: the ticks show 10^x (a frequency axis).
    pub log_x: bool,
    /// The legend in one row above the axes, right-aligned, instead of in a corner over them
    /// (a dense trace that fills every corner: the axes then fit the data).
    pub legend_above: bool,
}

impl Panel {
    /// A panel with axis labels and no series yet.
    pub fn new(x_label: impl Into<String>, y_label: impl Into<String>) -> Self {
        Self {
            title: None,
            x_label: x_label.into(),
            y_label: y_label.into(),
            series: Vec::new(),
            log_x: false,
            legend_above: false,
        }
    }

    /// Put the legend in a row above the axes (see [`Panel::legend_above`]).
    pub fn legend_above(mut self) -> Self {
        self.legend_above = true;
        self
    }

    /// The x values are log10 of the quantity; ticks are labelled with 10^x.
    pub fn log_x(mut self) -> Self {
        self.log_x = true;
        self
    }

    /// Set the title.
    pub fn title(mut self, t: impl Into<String>) -> Self {
        self.title = Some(t.into());
        self
    }

    /// Add a series.
    pub fn with(mut self, s: Series) -> Self {
        self.series.push(s);
        self
    }
}

/// A grid of panels, filled row by row.
#[derive(Debug, Clone)]
pub struct Figure {
    /// Title over the whole figure (optional).
    pub title: Option<String>,
    /// Number of panel columns.
    pub cols: usize,
    /// Panels in row-major order.
    pub panels: Vec<Panel>,
    /// Size of one panel [px].
    pub panel_size: (u32, u32),
}

impl Figure {
    /// A figure with `cols` columns and panels of 760 x 300 px.
    pub fn new(cols: usize) -> Self {
        Self {
            title: None,
            cols: cols.max(1),
            panels: Vec::new(),
            panel_size: (760, 300),
        }
    }

    fn rows(&self) -> usize {
        self.panels.len().div_ceil(self.cols).max(1)
    }

    fn title_height(&self) -> u32 {
        if self.title.is_some() {
            50
        } else {
            0
        }
    }

    /// Total size [px].
    pub fn size(&self) -> (u32, u32) {
        (
            self.panel_size.0 * self.cols as u32,
            self.panel_size.1 * self.rows() as u32 + self.title_height(),
        )
    }
}

/// Output format, from a file extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// Scalable vector graphics.
    Svg,
    /// Portable network graphics.
    Png,
}

impl Format {
    /// The format of `path` by its extension (`.svg` or `.png`, any case).
    pub fn of(path: &Path) -> Result<Format> {
        match path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .as_deref()
        {
            Some("svg") => Ok(Format::Svg),
            Some("png") => Ok(Format::Png),
            _ => Err(crate::common::usage(format!(
                "{}: figure files must end in .svg or .png",
                path.display()
            ))),
        }
    }
}

/// Render `fig` in `format` to bytes (an SVG document or a PNG file).
pub fn render(fig: &Figure, format: Format) -> Result<Vec<u8>> {
    register_font()?;
    let size = fig.size();
    match format {
        Format::Svg => svg_bytes(size, |root| draw(root, fig, false)),
        Format::Png => png_bytes(size, |root| draw(root, fig, true)),
    }
}

/// An SVG document of `size` drawn by `f`, as bytes.
pub(crate) fn svg_bytes(
    size: (u32, u32),
    f: impl FnOnce(&DrawingArea<SVGBackend<'_>, Shift>) -> Result<()>,
) -> Result<Vec<u8>> {
    let mut s = String::new();
    {
        let root = SVGBackend::with_string(&mut s, size).into_drawing_area();
        f(&root)?;
        root.present().map_err(|e| anyhow!("SVG rendering: {e}"))?;
    }
    Ok(s.into_bytes())
}

/// A PNG of `size` drawn by `f`, as bytes: plotters draws into an RGB buffer, which is encoded
/// at the best compression (about 3 times smaller than plotters' own encoder). The caller
/// writes the result atomically.
pub(crate) fn png_bytes(
    size: (u32, u32),
    f: impl FnOnce(&DrawingArea<BitMapBackend<'_>, Shift>) -> Result<()>,
) -> Result<Vec<u8>> {
    let mut buf = vec![0u8; size.0 as usize * size.1 as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buf, size).into_drawing_area();
        f(&root)?;
        root.present().map_err(|e| anyhow!("PNG rendering: {e}"))?;
    }
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, size.0, size.1);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::Best);
        enc.set_adaptive_filter(png::AdaptiveFilterType::Adaptive);
        let mut w = enc
            .write_header()
            .map_err(|e| anyhow!("PNG encoding: {e}"))?;
        w.write_image_data(&buf)
            .map_err(|e| anyhow!("PNG encoding: {e}"))?;
    }
    Ok(out)
}

/// `pieces`: draw lines as separate straight pieces (bitmap output, see [`pieces`]).
fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    fig: &Figure,
    pieces: bool,
) -> Result<()> {
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing: {e}");
    root.fill(&WHITE).map_err(err)?;
    let area = match &fig.title {
        Some(t) => root.titled(t, (FAMILY, 26)).map_err(err)?,
        None => root.clone(),
    };
    let cells = area.split_evenly((fig.rows(), fig.cols));
    for (panel, cell) in fig.panels.iter().zip(cells) {
        draw_panel(&cell, panel, pieces).map_err(err)?;
    }
    Ok(())
}

/// Data range with a margin; a flat signal gets a small symmetric range.
fn range(values: impl Iterator<Item = f64>, pad: f64) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let span = hi - lo;
    if span <= 1e-12 * lo.abs().max(hi.abs()).max(1e-300) {
        let d = if lo == 0.0 { 1.0 } else { 0.01 * lo.abs() };
        return (lo - d, hi + d);
    }
    (lo - pad * span, hi + pad * span)
}

/// Decimals for tick labels so that neighbouring ticks differ (about 5 ticks per axis).
fn decimals(lo: f64, hi: f64) -> usize {
    let step = (hi - lo) / 5.0;
    if step <= 0.0 || !step.is_finite() {
        return 2;
    }
    (-(step.log10().floor()) as i64).clamp(0, 8) as usize
}

/// At most about `2 * buckets` points: min and max of each bucket, in time order. Keeps the
/// envelope of long records (drive cycles) while keeping figure files small.
fn decimate(x: &[f64], y: &[f64], buckets: usize) -> Vec<(f64, f64)> {
    let n = x.len().min(y.len());
    if n <= 4 * buckets {
        return x.iter().copied().zip(y.iter().copied()).take(n).collect();
    }
    let per = n.div_ceil(buckets);
    let mut out = Vec::with_capacity(2 * buckets + 2);
    for start in (0..n).step_by(per) {
        let end = (start + per).min(n);
        let (mut imin, mut imax) = (start, start);
        for i in start..end {
            if y[i] < y[imin] {
                imin = i;
            }
            if y[i] > y[imax] {
                imax = i;
            }
        }
        let (a, b) = if imin <= imax {
            (imin, imax)
        } else {
            (imax, imin)
        };
        out.push((x[a], y[a]));
        if b != a {
            out.push((x[b], y[b]));
        }
    }
    out
}

/// A polyline as separate straight pieces in data coordinates, solid or dashed (`dash` = on,
/// off lengths in pixels), skipping pieces shorter than a pixel. Used for bitmap output: the
/// wide-line rasterizer of plotters joins polyline segments with miter vertices that shoot far
/// out at near-reversals (dense min/max envelopes) and breaks on zero-length segments; separate
/// pieces have no joins.
fn pieces(
    pts: &[(f64, f64)],
    px: &[(i32, i32)],
    dash: Option<(f64, f64)>,
) -> Vec<((f64, f64), (f64, f64))> {
    let lerp =
        |a: (f64, f64), b: (f64, f64), f: f64| (a.0 + f * (b.0 - a.0), a.1 + f * (b.1 - a.1));
    let mut out = Vec::new();
    // position along the dash pattern [px]
    let mut phase = 0.0;
    for i in 1..pts.len().min(px.len()) {
        let (a, b) = (pts[i - 1], pts[i]);
        let dx = f64::from(px[i].0 - px[i - 1].0);
        let dy = f64::from(px[i].1 - px[i - 1].1);
        let len = dx.hypot(dy);
        if len < 1.0 {
            continue;
        }
        match dash {
            None => out.push((a, b)),
            Some((on, off)) => {
                let period = on + off;
                let mut s = 0.0;
                while s < len {
                    let in_on = phase < on;
                    let step = if in_on { on - phase } else { period - phase }.min(len - s);
                    if in_on && step >= 1.0 {
                        out.push((lerp(a, b, s / len), lerp(a, b, (s + step) / len)));
                    }
                    s += step;
                    phase = (phase + step) % period;
                }
            }
        }
    }
    out
}

/// The points of a series with at least 200 points per segment for short series (so that a
/// two-point line counts along its length).
fn densify(x: &[f64], y: &[f64]) -> Vec<(f64, f64)> {
    let n = x.len().min(y.len());
    if !(2..200).contains(&n) {
        return x.iter().copied().zip(y.iter().copied()).take(n).collect();
    }
    let mut out = Vec::with_capacity(200 * n);
    for i in 0..n - 1 {
        for k in 0..200 {
            let f = k as f64 / 200.0;
            out.push((x[i] + f * (x[i + 1] - x[i]), y[i] + f * (y[i + 1] - y[i])));
        }
    }
    out.push((x[n - 1], y[n - 1]));
    out
}

/// The legend corner whose region holds the fewest data points: (position, fraction of the
/// series inside the legend box summed over the series (0: the box covers no data), box height
/// as a fraction of the plot height).
fn legend_corner(
    panel: &Panel,
    x: (f64, f64),
    y: (f64, f64),
    plot_height_px: f64,
) -> (SeriesLabelPosition, f64, f64) {
    // (position, right side, vertical place: 2 upper, 1 middle, 0 lower); ties go to the first
    let corners = [
        (SeriesLabelPosition::UpperRight, true, 2),
        (SeriesLabelPosition::LowerRight, true, 0),
        (SeriesLabelPosition::MiddleRight, true, 1),
        (SeriesLabelPosition::UpperLeft, false, 2),
        (SeriesLabelPosition::LowerLeft, false, 0),
        (SeriesLabelPosition::MiddleLeft, false, 1),
    ];
    // legend box: about 24 px per entry plus margins; width about 45 % of the panel
    let entries = panel.series.iter().filter(|s| !s.label.is_empty()).count() as f64;
    let wx = 0.45;
    let wy = ((entries * 24.0 + 24.0) / plot_height_px.max(1.0)).min(0.9);
    let mut best = (f64::INFINITY, SeriesLabelPosition::UpperRight);
    for (pos, right, place) in corners {
        // fraction of each series inside the box, summed (independent of sampling density)
        let count: f64 = panel
            .series
            .iter()
            .map(|s| {
                let pts = densify(&s.x, &s.y);
                let inside = pts
                    .iter()
                    .filter(|&&(xv, yv)| {
                        let fx = (xv - x.0) / (x.1 - x.0);
                        let fy = (yv - y.0) / (y.1 - y.0);
                        let in_x = if right { fx > 1.0 - wx } else { fx < wx };
                        let in_y = match place {
                            2 => fy > 1.0 - wy,
                            1 => (fy - 0.5).abs() < 0.5 * wy,
                            _ => fy < wy,
                        };
                        in_x && in_y
                    })
                    .count();
                inside as f64 / pts.len().max(1) as f64
            })
            .sum();
        if count < best.0 {
            best = (count, pos);
        }
    }
    (best.1, best.0, wy)
}

/// The tick label of a log10 axis at `v`: 10^v to two significant digits (0.032, 3.2, 32, 320).
fn log_tick(v: f64) -> String {
    let f = 10f64.powf(v);
    let decimals = (1.0 - f.log10().floor()).clamp(0.0, 12.0) as usize;
    format!("{f:.decimals$}")
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    panel: &Panel,
    as_pieces: bool,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let (x0, x1) = range(panel.series.iter().flat_map(|s| s.x.iter().copied()), 0.0);
    let labelled = panel.series.iter().any(|s| !s.label.is_empty());
    let above = panel.legend_above && labelled;
    // extra head- and foot-room for a legend over the axes
    let pad = if above { 0.04 } else { 0.12 };
    let (y0, mut y1) = range(panel.series.iter().flat_map(|s| s.y.iter().copied()), pad);
    let plot_height_px = area.dim_in_pixel().1 as f64 - 110.0;
    let mut corner = SeriesLabelPosition::UpperRight;
    if labelled && !above {
        let (pos, covered, wy) = legend_corner(panel, (x0, x1), (y0, y1), plot_height_px);
        corner = pos;
        let keep = 1.0 - wy - 0.03;
        if covered > 0.0 && keep >= 0.6 {
            // every corner holds data (e.g. a response between two steady-state lines): raise
            // the top of the axes so that the data end below the legend box
            y1 = y0 + (y1 - y0) / keep;
            corner = SeriesLabelPosition::UpperRight;
        }
        // A legend taller than 40 % of a short panel (a dense drive-cycle trace covers every
        // corner) stays over the data in the least covered corner on its translucent
        // background: raising the axes would flatten the data into the lower half.
    }
    let mut b = ChartBuilder::on(area);
    b.margin(8)
        .margin_top(if above { 8 + LEGEND_ROW } else { 8 })
        .margin_right(18)
        .x_label_area_size(48)
        .y_label_area_size(86);
    if let Some(t) = &panel.title {
        b.caption(t, (FAMILY, 21));
    }
    let mut chart = b.build_cartesian_2d(x0..x1, y0..y1)?;
    let (dx, dy) = (decimals(x0, x1), decimals(y0, y1));
    chart
        .configure_mesh()
        .x_desc(panel.x_label.as_str())
        .y_desc(panel.y_label.as_str())
        .x_labels(8)
        .y_labels(6)
        .x_label_formatter(&|v| {
            if panel.log_x {
                log_tick(*v)
            } else {
                format!("{v:.dx$}")
            }
        })
        .y_label_formatter(&|v| format!("{v:.dy$}"))
        .label_style((FAMILY, 16))
        .axis_desc_style((FAMILY, 18))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(205, 205, 205))
        .draw()?;
    let width = area.dim_in_pixel().0 as usize;
    for s in &panel.series {
        let color = PALETTE[s.color % PALETTE.len()];
        let style = ShapeStyle {
            color: color.to_rgba(),
            filled: false,
            stroke_width: 2,
        };
        // Drop points that land on the same pixel as the previous one: the wide-line
        // rasterizer of plotters computes the line normal from the segment direction, which is
        // undefined for zero-length segments and produces spikes.
        let pts = decimate(&s.x, &s.y, width.max(100));
        if as_pieces && !s.markers {
            let px: Vec<(i32, i32)> = pts.iter().map(|p| chart.backend_coord(p)).collect();
            let dash = if s.dashed { Some((8.0, 5.0)) } else { None };
            let segs = pieces(&pts, &px, dash);
            let legend_style = style;
            let anno = chart.draw_series(
                segs.into_iter()
                    .map(|(a, b)| PathElement::new(vec![a, b], style)),
            )?;
            if s.label.is_empty() {
                // no legend entry for an unlabelled series
                continue;
            }
            anno.label(s.label.as_str());
            if s.dashed {
                anno.legend(move |(x, y)| {
                    DashedPathElement::new(vec![(x, y), (x + 24, y)], 6, 4, legend_style)
                });
            } else {
                anno.legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 24, y)], legend_style)
                });
            }
            continue;
        }
        if s.markers {
            let filled = style.filled();
            let anno =
                chart.draw_series(pts.iter().map(|&p| Circle::new(p, s.marker_radius, filled)))?;
            if !s.label.is_empty() {
                anno.label(s.label.as_str())
                    .legend(move |(x, y)| Circle::new((x + 12, y), 5, filled));
            }
        } else if s.dashed {
            chart
                .draw_series(DashedLineSeries::new(pts, 8, 5, style))?
                .label(s.label.as_str())
                .legend(move |(x, y)| {
                    DashedPathElement::new(vec![(x, y), (x + 24, y)], 6, 4, style)
                });
        } else {
            chart
                .draw_series(LineSeries::new(pts, style))?
                .label(s.label.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], style));
        }
    }
    if above {
        legend_row(area, &chart.plotting_area().get_pixel_range(), panel)?;
    } else if labelled {
        chart
            .configure_series_labels()
            .position(corner)
            .label_font((FAMILY, 16))
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(160, 160, 160))
            .margin(8)
            .draw()?;
    }
    Ok(())
}

/// Height of the legend row above the axes of a [`Panel::legend_above`] panel [px].
const LEGEND_ROW: u32 = 24;

/// The legend of `panel` in one row just above its axes, right-aligned with them (`plot`: the
/// axes' pixel ranges in the backend's coordinates): per labelled series a 24 px sample of its
/// line (dashed, or a marker) and its label.
fn legend_row<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    plot: &(std::ops::Range<i32>, std::ops::Range<i32>),
    panel: &Panel,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let (bx, by) = area.get_base_pixel();
    let font: TextStyle = (FAMILY, 16).into_font().into();
    let y = plot.1.start - by - LEGEND_ROW as i32 / 2 - 2;
    let mut x = plot.0.end - bx;
    for s in panel.series.iter().rev().filter(|s| !s.label.is_empty()) {
        let (w, h) = area.estimate_text_size(&s.label, &font)?;
        x -= w as i32;
        area.draw(&Text::new(
            s.label.as_str(),
            (x, y - h as i32 / 2),
            font.clone(),
        ))?;
        x -= 32;
        let style = ShapeStyle {
            color: PALETTE[s.color % PALETTE.len()].to_rgba(),
            filled: s.markers,
            stroke_width: 2,
        };
        if s.markers {
            area.draw(&Circle::new((x + 12, y), 5, style))?;
        } else if s.dashed {
            area.draw(&DashedPathElement::new(
                vec![(x, y), (x + 24, y)],
                6,
                4,
                style,
            ))?;
        } else {
            area.draw(&PathElement::new(vec![(x, y), (x + 24, y)], style))?;
        }
        x -= 20;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimation_keeps_the_envelope() {
        let x: Vec<f64> = (0..10_000).map(|i| i as f64).collect();
        let y: Vec<f64> = x.iter().map(|v| (v * 0.37).sin()).collect();
        let d = decimate(&x, &y, 100);
        assert!(d.len() <= 202);
        let max = d.iter().map(|p| p.1).fold(f64::MIN, f64::max);
        let min = d.iter().map(|p| p.1).fold(f64::MAX, f64::min);
        assert!(max > 0.999 && min < -0.999);
        assert!(d.windows(2).all(|w| w[0].0 <= w[1].0));
    }

    #[test]
    fn formats_by_extension() {
        assert_eq!(Format::of(Path::new("a.SVG")).unwrap(), Format::Svg);
        assert_eq!(Format::of(Path::new("a.png")).unwrap(), Format::Png);
        assert!(Format::of(Path::new("a.pdf")).is_err());
    }

    #[test]
    fn renders_both_formats() {
        let t: Vec<f64> = (0..50).map(|i| i as f64 * 0.1).collect();
        let y: Vec<f64> = t.iter().map(|v| v * v).collect();
        let mut f = Figure::new(1);
        f.panels.push(
            Panel::new("t [s]", "y [m]")
                .title("test")
                .with(Series::line("y", &t, &y, 0))
                .with(Series::hline("ref", 0.0, 4.9, 10.0, 1)),
        );
        let svg = String::from_utf8(render(&f, Format::Svg).unwrap()).unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("t [s]"));
        let png = render(&f, Format::Png).unwrap();
        assert_eq!(&png[1..4], b"PNG");
    }
}
