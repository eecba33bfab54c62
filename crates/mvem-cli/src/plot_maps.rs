//! Plotting helpers for maps: heat maps with a colour bar, contour lines (marching squares)
//! with level labels, curves and scatter overlays on x-y axes. Used by `mvem map`,
//! `mvem components` and `mvem report`. Same font, palette and atomic PNG/SVG rendering as
//! [`crate::plot`].

use crate::plot::{self, Format, FAMILY, PALETTE};
use anyhow::{anyhow, Result};
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// Colour scale of a heat map.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scheme {
    /// Sequential (viridis-like), low = dark blue, high = yellow.
    Sequential,
    /// Diverging around 0: negative blue, 0 white, positive red (symmetric range).
    Diverging,
}

/// A scalar field on a rectangular grid: `z[i * y.len() + j]` at `(x[i], y[j])`; NaN = no
/// value (drawn grey).
#[derive(Debug, Clone)]
pub struct Field {
    /// Abscissa grid values (increasing).
    pub x: Vec<f64>,
    /// Ordinate grid values (increasing).
    pub y: Vec<f64>,
    /// Values, x-major.
    pub z: Vec<f64>,
}

impl Field {
    fn at(&self, i: usize, j: usize) -> f64 {
        self.z[i * self.y.len() + j]
    }
}

/// A heat map of a field with a colour bar.
#[derive(Debug, Clone)]
pub struct Heat {
    /// The field.
    pub field: Field,
    /// Colour-bar label with unit.
    pub label: String,
    /// Colour scale.
    pub scheme: Scheme,
    /// Legend text of the grey (NaN) cells, if any are present.
    pub nan_label: String,
}

/// Contour lines of a field at given levels.
#[derive(Debug, Clone)]
pub struct Contours {
    /// The field.
    pub field: Field,
    /// Levels.
    pub levels: Vec<f64>,
    /// Legend text (empty: no legend entry).
    pub label: String,
    /// Palette index (7 = black).
    pub color: usize,
    /// Line width [px].
    pub width: u32,
    /// Dashed.
    pub dashed: bool,
    /// Write the level value next to each contour (with this many decimals).
    pub level_labels: Option<usize>,
}

/// A curve.
#[derive(Debug, Clone)]
pub struct Curve {
    /// Abscissa values.
    pub x: Vec<f64>,
    /// Ordinate values (NaN breaks the curve).
    pub y: Vec<f64>,
    /// Legend text (empty: no legend entry).
    pub label: String,
    /// Palette index (7 = black).
    pub color: usize,
    /// Dashed.
    pub dashed: bool,
    /// Text written at the curve's last point (e.g. a speed-line value).
    pub end_text: Option<String>,
}

/// Scatter points.
#[derive(Debug, Clone)]
pub struct Points {
    /// Abscissa values.
    pub x: Vec<f64>,
    /// Ordinate values.
    pub y: Vec<f64>,
    /// Legend text.
    pub label: String,
    /// Palette index (7 = black).
    pub color: usize,
    /// Radius [px].
    pub radius: u32,
    /// Crosses instead of filled circles.
    pub cross: bool,
}

/// One x-y axes with optional heat map, contours, curves and points.
#[derive(Debug, Clone, Default)]
pub struct MapPanel {
    /// Title above the panel.
    pub title: String,
    /// Abscissa label with unit.
    pub x_label: String,
    /// Ordinate label with unit.
    pub y_label: String,
    /// Heat map (drawn first).
    pub heat: Option<Heat>,
    /// Contour sets.
    pub contours: Vec<Contours>,
    /// Curves.
    pub curves: Vec<Curve>,
    /// Points (drawn last).
    pub points: Vec<Points>,
    /// Axis ranges (default: the heat-map grid, else the data).
    pub x_range: Option<(f64, f64)>,
    /// Ordinate range.
    pub y_range: Option<(f64, f64)>,
}

impl MapPanel {
    /// An empty panel with a title and axis labels.
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
    ) -> Self {
        Self {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            ..Self::default()
        }
    }
}

/// A grid of map panels.
#[derive(Debug, Clone)]
pub struct MapFigure {
    /// Title over the figure.
    pub title: Option<String>,
    /// Columns.
    pub cols: usize,
    /// Panels, row-major.
    pub panels: Vec<MapPanel>,
    /// Size of one panel [px].
    pub panel_size: (u32, u32),
}

impl MapFigure {
    /// A figure with `cols` columns of 640 x 520 px panels.
    pub fn new(cols: usize) -> Self {
        Self {
            title: None,
            cols: cols.max(1),
            panels: Vec::new(),
            panel_size: (640, 520),
        }
    }

    fn rows(&self) -> usize {
        self.panels.len().div_ceil(self.cols).max(1)
    }

    /// Total size [px].
    pub fn size(&self) -> (u32, u32) {
        let title = if self.title.is_some() { 46 } else { 0 };
        (
            self.panel_size.0 * self.cols as u32,
            self.panel_size.1 * self.rows() as u32 + title,
        )
    }
}

/// Render a map figure to SVG or PNG bytes.
pub fn render(fig: &MapFigure, format: Format) -> Result<Vec<u8>> {
    plot::register_font()?;
    match format {
        Format::Svg => plot::svg_bytes(fig.size(), |root| draw(root, fig)),
        Format::Png => plot::png_bytes(fig.size(), |root| draw(root, fig)),
    }
}

fn color(i: usize) -> RGBColor {
    if i == 7 {
        BLACK
    } else {
        PALETTE[i % PALETTE.len()]
    }
}

/// Viridis-like sequential colour at t in [0, 1].
fn sequential(t: f64) -> RGBColor {
    const STOPS: [(f64, f64, f64); 6] = [
        (68.0, 1.0, 84.0),
        (65.0, 68.0, 135.0),
        (42.0, 120.0, 142.0),
        (34.0, 168.0, 132.0),
        (122.0, 209.0, 81.0),
        (253.0, 231.0, 37.0),
    ];
    lerp_stops(&STOPS, t)
}

/// Blue-white-red diverging colour at t in [0, 1] (0.5 = white).
fn diverging(t: f64) -> RGBColor {
    const STOPS: [(f64, f64, f64); 5] = [
        (33.0, 102.0, 172.0),
        (146.0, 197.0, 222.0),
        (247.0, 247.0, 247.0),
        (244.0, 165.0, 130.0),
        (178.0, 24.0, 43.0),
    ];
    lerp_stops(&STOPS, t)
}

fn lerp_stops(stops: &[(f64, f64, f64)], t: f64) -> RGBColor {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let f = t * (stops.len() - 1) as f64;
    let k = (f.floor() as usize).min(stops.len() - 2);
    let w = f - k as f64;
    let (a, b) = (stops[k], stops[k + 1]);
    let c = |x: f64, y: f64| (x + w * (y - x)).round() as u8;
    RGBColor(c(a.0, b.0), c(a.1, b.1), c(a.2, b.2))
}

/// Range of the finite values (symmetric about 0 for a diverging scale).
fn value_range(z: &[f64], scheme: Scheme) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for &v in z.iter().filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if scheme == Scheme::Diverging {
        let m = lo.abs().max(hi.abs()).max(1e-300);
        return (-m, m);
    }
    if hi - lo <= 1e-12 * hi.abs().max(1e-300) {
        let d = if hi == 0.0 { 1.0 } else { 0.01 * hi.abs() };
        return (lo - d, hi + d);
    }
    (lo, hi)
}

/// "Nice" contour levels: about `n` round values strictly inside the field's range.
pub fn nice_levels(z: &[f64], n: usize) -> Vec<f64> {
    let (lo, hi) = value_range(z, Scheme::Sequential);
    let raw = (hi - lo) / n.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let mut v = (lo / step).floor() * step + step;
    let mut out = Vec::new();
    while v < hi && out.len() < 4 * n + 4 {
        if v > lo {
            out.push(if v.abs() < 1e-9 * step { 0.0 } else { v });
        }
        v += step;
    }
    out
}

/// Decimals to print the levels `l` distinguishably.
pub fn level_decimals(l: &[f64]) -> usize {
    let step = l
        .windows(2)
        .map(|w| w[1] - w[0])
        .fold(f64::INFINITY, f64::min);
    if !step.is_finite() || step <= 0.0 {
        return 2;
    }
    (-(step.log10().floor()) as i64).clamp(0, 6) as usize
}

/// A straight piece of a contour line: its two end points (x, y).
type Segment = ((f64, f64), (f64, f64));

/// Contour segments of `f` at `level` (marching squares; cells with a NaN corner are skipped;
/// saddles are resolved by the cell average).
pub fn contour_segments(f: &Field, level: f64) -> Vec<Segment> {
    let (nx, ny) = (f.x.len(), f.y.len());
    let mut segs = Vec::new();
    if nx < 2 || ny < 2 || f.z.len() != nx * ny {
        return segs;
    }
    for i in 0..nx - 1 {
        for j in 0..ny - 1 {
            // corners counter-clockwise: (i,j), (i+1,j), (i+1,j+1), (i,j+1)
            let c = [
                (f.x[i], f.y[j], f.at(i, j)),
                (f.x[i + 1], f.y[j], f.at(i + 1, j)),
                (f.x[i + 1], f.y[j + 1], f.at(i + 1, j + 1)),
                (f.x[i], f.y[j + 1], f.at(i, j + 1)),
            ];
            if c.iter().any(|p| !p.2.is_finite()) {
                continue;
            }
            let above: Vec<bool> = c.iter().map(|p| p.2 >= level).collect();
            let mut cross = Vec::with_capacity(4);
            for e in 0..4 {
                let (a, b) = (c[e], c[(e + 1) % 4]);
                if above[e] != above[(e + 1) % 4] {
                    let t = (level - a.2) / (b.2 - a.2);
                    cross.push((a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1)));
                }
            }
            match cross.len() {
                2 => segs.push((cross[0], cross[1])),
                4 => {
                    let mean = c.iter().map(|p| p.2).sum::<f64>() / 4.0;
                    // crossings are on edges 0,1,2,3 in order; pair so that the centre's side
                    // matches corner 0's opposite when the centre differs from it
                    if (mean >= level) == above[0] {
                        segs.push((cross[0], cross[1]));
                        segs.push((cross[2], cross[3]));
                    } else {
                        segs.push((cross[3], cross[0]));
                        segs.push((cross[1], cross[2]));
                    }
                }
                _ => {}
            }
        }
    }
    segs
}

fn data_range(vals: impl Iterator<Item = f64>, pad: f64) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in vals.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let span = hi - lo;
    if span <= 1e-12 * hi.abs().max(1e-300) {
        let d = if hi == 0.0 { 1.0 } else { 0.01 * hi.abs() };
        return (lo - d, hi + d);
    }
    (lo - pad * span, hi + pad * span)
}

/// Cell edges around grid values (midpoints, ends extended by half a spacing).
fn edges(v: &[f64]) -> Vec<f64> {
    let n = v.len();
    if n == 1 {
        return vec![v[0] - 0.5, v[0] + 0.5];
    }
    let mut e = Vec::with_capacity(n + 1);
    e.push(v[0] - 0.5 * (v[1] - v[0]));
    for k in 0..n - 1 {
        e.push(0.5 * (v[k] + v[k + 1]));
    }
    e.push(v[n - 1] + 0.5 * (v[n - 1] - v[n - 2]));
    e
}

fn tick_decimals(lo: f64, hi: f64) -> usize {
    let step = (hi - lo) / 5.0;
    if step <= 0.0 || !step.is_finite() {
        return 2;
    }
    (-(step.log10().floor()) as i64).clamp(0, 8) as usize
}

fn draw<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, fig: &MapFigure) -> Result<()> {
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing: {e}");
    root.fill(&WHITE).map_err(err)?;
    let area = match &fig.title {
        Some(t) => root.titled(t, (FAMILY, 24)).map_err(err)?,
        None => root.clone(),
    };
    let cells = area.split_evenly((fig.rows(), fig.cols));
    for (panel, cell) in fig.panels.iter().zip(cells) {
        draw_panel(&cell, panel).map_err(err)?;
    }
    Ok(())
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    p: &MapPanel,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    // colour bar strip on the right
    let (w, _) = area.dim_in_pixel();
    let (plot_area, bar_area) = if p.heat.is_some() {
        let (a, b) = area.split_horizontally(w.saturating_sub(120));
        (a, Some(b))
    } else {
        (area.clone(), None)
    };
    let (x0, x1) = p.x_range.unwrap_or_else(|| match &p.heat {
        Some(h) => {
            let e = edges(&h.field.x);
            (e[0], e[e.len() - 1])
        }
        None => data_range(
            p.curves
                .iter()
                .flat_map(|c| c.x.iter().copied())
                .chain(p.points.iter().flat_map(|c| c.x.iter().copied())),
            0.03,
        ),
    });
    let (y0, mut y1) = p.y_range.unwrap_or_else(|| match &p.heat {
        Some(h) => {
            let e = edges(&h.field.y);
            (e[0], e[e.len() - 1])
        }
        None => data_range(
            p.curves
                .iter()
                .flat_map(|c| c.y.iter().copied())
                .chain(p.points.iter().flat_map(|c| c.y.iter().copied())),
            0.05,
        ),
    });
    // curves and markers are drawn up to the data top, also when the axes are raised
    let y_top = y1;
    if p.heat.is_none() {
        // the legend sits in the upper right corner: when data lie under it, raise the top of
        // the axes so that the data end below the legend box
        let plot_h = plot_area.dim_in_pixel().1 as f64 - 100.0;
        if let Some(wy) = legend_covers_data(p, (x0, x1), (y0, y1), plot_h) {
            y1 = y0 + (y1 - y0) / (1.0 - wy - 0.03).max(0.3);
        }
    }
    let mut b = ChartBuilder::on(&plot_area);
    b.margin(10)
        .margin_right(16)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .caption(&p.title, (FAMILY, 19));
    let mut chart = b.build_cartesian_2d(x0..x1, y0..y1)?;
    let (dx, dy) = (tick_decimals(x0, x1), tick_decimals(y0, y1));
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc(p.x_label.as_str())
        .y_desc(p.y_label.as_str())
        .x_labels(7)
        .y_labels(7)
        .x_label_formatter(&|v| format!("{v:.dx$}"))
        .y_label_formatter(&|v| format!("{v:.dy$}"))
        .label_style((FAMILY, 15))
        .axis_desc_style((FAMILY, 17))
        .draw()?;
    let mut legend = false;
    // pixel centres of the contour level labels drawn so far (labels keep apart)
    let mut placed: Vec<(i32, i32)> = Vec::new();

    if let Some(h) = &p.heat {
        let f = &h.field;
        let (lo, hi) = value_range(&f.z, h.scheme);
        let cmap = |v: f64| {
            let t = (v - lo) / (hi - lo);
            match h.scheme {
                Scheme::Sequential => sequential(t),
                Scheme::Diverging => diverging(t),
            }
        };
        let (ex, ey) = (edges(&f.x), edges(&f.y));
        let grey = RGBColor(200, 200, 200);
        let mut rects = Vec::with_capacity(f.z.len());
        let mut any_nan = false;
        for i in 0..f.x.len() {
            for j in 0..f.y.len() {
                let v = f.at(i, j);
                let c = if v.is_finite() {
                    cmap(v)
                } else {
                    any_nan = true;
                    grey
                };
                rects.push(Rectangle::new(
                    [(ex[i], ey[j]), (ex[i + 1], ey[j + 1])],
                    c.filled(),
                ));
            }
        }
        chart.draw_series(rects)?;
        if any_nan && !h.nan_label.is_empty() {
            chart
                .draw_series(std::iter::empty::<Rectangle<(f64, f64)>>())?
                .label(h.nan_label.as_str())
                .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 16, y + 6)], grey.filled()));
            legend = true;
        }
        if let Some(bar) = &bar_area {
            draw_colorbar(bar, &h.label, lo, hi, h.scheme)?;
        }
    }

    for cs in &p.contours {
        let style = ShapeStyle {
            color: color(cs.color).to_rgba(),
            filled: false,
            stroke_width: cs.width,
        };
        let mut first = true;
        for &level in &cs.levels {
            // left to right: plotters' bitmap backend drops the end pixels of a one-pixel
            // horizontal line drawn right to left, which made flat contours look dashed
            let segs: Vec<Segment> = contour_segments(&cs.field, level)
                .into_iter()
                .map(|(a, b)| if a.0 <= b.0 { (a, b) } else { (b, a) })
                .collect();
            if segs.is_empty() {
                continue;
            }
            let anno = if cs.dashed {
                chart.draw_series(
                    segs.iter()
                        .map(|(a, b)| DashedPathElement::new(vec![*a, *b], 5, 4, style)),
                )?
            } else {
                chart.draw_series(
                    segs.iter()
                        .map(|(a, b)| PathElement::new(vec![*a, *b], style)),
                )?
            };
            if first && !cs.label.is_empty() {
                let dashed = cs.dashed;
                anno.label(cs.label.as_str()).legend(move |(x, y)| {
                    if dashed {
                        DashedPathElement::new(vec![(x, y), (x + 22, y)], 5, 4, style).into_dyn()
                    } else {
                        PathElement::new(vec![(x, y), (x + 22, y)], style).into_dyn()
                    }
                });
                legend = true;
                first = false;
            }
            if let Some(dec) = cs.level_labels {
                // label at the segment furthest inside the axes whose label box does not
                // overlap one already drawn (on a coarse grid nested contours run close
                // together); no label if there is no such segment
                let depth = |s: &((f64, f64), (f64, f64))| {
                    let fx = (0.5 * (s.0 .0 + s.1 .0) - x0) / (x1 - x0);
                    let fy = (0.5 * (s.0 .1 + s.1 .1) - y0) / (y1 - y0);
                    fx.min(1.0 - fx).min(fy).min(1.0 - fy)
                };
                let txt = format!("{level:.dec$}");
                let half_w = 4 * txt.len() as i32 + 4;
                let mut order: Vec<&Segment> = segs.iter().filter(|s| depth(s) > 0.02).collect();
                order.sort_by(|s, t| depth(t).total_cmp(&depth(s)));
                let free = order.into_iter().find(|(a, b)| {
                    let mid = (0.5 * (a.0 + b.0), 0.5 * (a.1 + b.1));
                    let (px, py) = chart.backend_coord(&mid);
                    placed
                        .iter()
                        .all(|&(qx, qy)| (px - qx).abs() > 2 * half_w || (py - qy).abs() > 18)
                });
                if let Some((a, b)) = free {
                    let mid = (0.5 * (a.0 + b.0), 0.5 * (a.1 + b.1));
                    placed.push(chart.backend_coord(&mid));
                    chart.draw_series(std::iter::once(Text::new(
                        txt,
                        mid,
                        TextStyle::from((FAMILY, 13).into_font())
                            .color(&color(cs.color))
                            .pos(Pos::new(HPos::Center, VPos::Bottom)),
                    )))?;
                }
            }
        }
    }

    for c in &p.curves {
        let style = ShapeStyle {
            color: color(c.color).to_rgba(),
            filled: false,
            stroke_width: 2,
        };
        // runs of consecutive finite points inside the axes (a point outside breaks the curve,
        // so that nothing is drawn clamped onto the border)
        let inside = |x: f64, y: f64| {
            x.is_finite() && y.is_finite() && x >= x0 && x <= x1 && y >= y0 && y <= y_top
        };
        let mut runs: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
        for (&x, &y) in c.x.iter().zip(&c.y) {
            if inside(x, y) {
                if let Some(r) = runs.last_mut() {
                    r.push((x, y));
                }
            } else if runs.last().is_some_and(|r| !r.is_empty()) {
                runs.push(Vec::new());
            }
        }
        runs.retain(|r| r.len() >= 2);
        let anno = if c.dashed {
            chart.draw_series(
                runs.into_iter()
                    .map(|r| DashedPathElement::new(r, 6, 4, style)),
            )?
        } else {
            chart.draw_series(runs.into_iter().map(|r| PathElement::new(r, style)))?
        };
        if !c.label.is_empty() {
            let dashed = c.dashed;
            anno.label(c.label.as_str()).legend(move |(x, y)| {
                if dashed {
                    DashedPathElement::new(vec![(x, y), (x + 22, y)], 5, 4, style).into_dyn()
                } else {
                    PathElement::new(vec![(x, y), (x + 22, y)], style).into_dyn()
                }
            });
            legend = true;
        }
        if let Some(t) = &c.end_text {
            let last = c.x.iter().zip(&c.y).rfind(|(x, y)| {
                x.is_finite()
                    && y.is_finite()
                    && **x >= x0
                    && **x <= x1
                    && **y >= y0
                    && **y <= y_top
            });
            if let Some((&x, &y)) = last {
                chart.draw_series(std::iter::once(Text::new(
                    t.clone(),
                    (x, y),
                    TextStyle::from((FAMILY, 13).into_font())
                        .color(&color(c.color))
                        .pos(Pos::new(HPos::Left, VPos::Bottom)),
                )))?;
            }
        }
    }

    for pts in &p.points {
        let c = color(pts.color);
        let r = pts.radius as i32;
        let inside = |x: f64, y: f64| x >= x0 && x <= x1 && y >= y0 && y <= y_top;
        let xy: Vec<(f64, f64)> = pts
            .x
            .iter()
            .zip(&pts.y)
            .map(|(a, b)| (*a, *b))
            .filter(|(a, b)| a.is_finite() && b.is_finite() && inside(*a, *b))
            .collect();
        let anno = if pts.cross {
            chart.draw_series(xy.iter().map(|&q| Cross::new(q, r, c.stroke_width(2))))?
        } else {
            chart.draw_series(xy.iter().map(|&q| Circle::new(q, r, c.mix(0.6).filled())))?
        };
        if !pts.label.is_empty() {
            let cross = pts.cross;
            anno.label(pts.label.as_str()).legend(move |(x, y)| {
                if cross {
                    Cross::new((x + 10, y), 5, c.stroke_width(2)).into_dyn()
                } else {
                    Circle::new((x + 10, y), 4, c.filled()).into_dyn()
                }
            });
            legend = true;
        }
    }

    if legend {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font((FAMILY, 14))
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(160, 160, 160))
            .margin(6)
            .draw()?;
    }
    Ok(())
}

/// If the upper-right legend box (about 45 % of the width, 22 px per entry high) would cover
/// any curve point, contour segment or marker of `p`: the box height as a fraction of the plot
/// height `plot_h` [px]. `None` when there is no legend or it covers nothing.
fn legend_covers_data(p: &MapPanel, x: (f64, f64), y: (f64, f64), plot_h: f64) -> Option<f64> {
    let entries = p.contours.iter().filter(|c| !c.label.is_empty()).count()
        + p.curves.iter().filter(|c| !c.label.is_empty()).count()
        + p.points.iter().filter(|c| !c.label.is_empty()).count();
    if entries == 0 {
        return None;
    }
    let wy = ((entries as f64 * 22.0 + 20.0) / plot_h.max(1.0)).min(0.9);
    let inside = |xv: f64, yv: f64| {
        let fx = (xv - x.0) / (x.1 - x.0);
        let fy = (yv - y.0) / (y.1 - y.0);
        fx > 0.55 && fx <= 1.0 && fy > 1.0 - wy && fy <= 1.0
    };
    let curves = p
        .curves
        .iter()
        .map(|c| (&c.x, &c.y))
        .chain(p.points.iter().map(|c| (&c.x, &c.y)));
    for (xs, ys) in curves {
        if xs.iter().zip(ys.iter()).any(|(a, b)| inside(*a, *b)) {
            return Some(wy);
        }
    }
    for cs in &p.contours {
        for &level in &cs.levels {
            let hit = contour_segments(&cs.field, level)
                .iter()
                .any(|(a, b)| inside(a.0, a.1) || inside(b.0, b.1));
            if hit {
                return Some(wy);
            }
        }
    }
    None
}

fn draw_colorbar<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    label: &str,
    lo: f64,
    hi: f64,
    scheme: Scheme,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let (_, h) = area.dim_in_pixel();
    let (top, bottom) = (46i32, h as i32 - 62);
    let (left, right) = (8i32, 30i32);
    let n = (bottom - top).max(1);
    for k in 0..n {
        let t = 1.0 - k as f64 / n as f64;
        let c = match scheme {
            Scheme::Sequential => sequential(t),
            Scheme::Diverging => diverging(t),
        };
        area.draw(&Rectangle::new(
            [(left, top + k), (right, top + k + 1)],
            c.filled(),
        ))?;
    }
    area.draw(&Rectangle::new(
        [(left, top), (right, bottom)],
        BLACK.stroke_width(1),
    ))?;
    let dec = tick_decimals(lo, hi) + 1;
    let style = TextStyle::from((FAMILY, 13).into_font()).pos(Pos::new(HPos::Left, VPos::Center));
    for k in 0..=5 {
        let f = k as f64 / 5.0;
        let v = lo + f * (hi - lo);
        let y = bottom - (f * (bottom - top) as f64).round() as i32;
        area.draw(&PathElement::new(vec![(right, y), (right + 4, y)], BLACK))?;
        let txt = if v != 0.0 && (v.abs() < 1e-3 || v.abs() >= 1e5) {
            format!("{v:.2e}")
        } else {
            format!("{v:.dec$}")
        };
        area.draw(&Text::new(txt, (right + 6, y), style.clone()))?;
    }
    // label below the bar (may wrap over two lines at a space)
    let ls = TextStyle::from((FAMILY, 14).into_font()).pos(Pos::new(HPos::Left, VPos::Top));
    let (l1, l2) = match label.len() > 14 {
        true => match label.rfind(' ') {
            Some(k) => (&label[..k], &label[k + 1..]),
            None => (label, ""),
        },
        false => (label, ""),
    };
    area.draw(&Text::new(l1.to_string(), (4, bottom + 10), ls.clone()))?;
    area.draw(&Text::new(l2.to_string(), (4, bottom + 28), ls))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn contours_of_a_plane_are_straight_lines_at_the_right_place() {
        // z = x + y on [0, 1]^2: the 1.0 contour is the anti-diagonal x + y = 1
        let g: Vec<f64> = (0..11).map(|i| i as f64 / 10.0).collect();
        let z: Vec<f64> = g
            .iter()
            .flat_map(|x| g.iter().map(move |y| x + y))
            .collect();
        let f = Field {
            x: g.clone(),
            y: g,
            z,
        };
        let segs = contour_segments(&f, 1.05);
        assert!(!segs.is_empty());
        for (a, b) in segs {
            assert!((a.0 + a.1 - 1.05).abs() < 1e-12 && (b.0 + b.1 - 1.05).abs() < 1e-12);
        }
        // NaN cells are skipped
        let mut f2 = f.clone();
        f2.z.iter_mut().for_each(|v| *v = f64::NAN);
        assert!(contour_segments(&f2, 1.0).is_empty());
    }

    #[test]
    fn nice_levels_are_round_and_inside() {
        let l = nice_levels(&[0.13, 0.87], 6);
        assert!(l.iter().all(|v| *v > 0.13 && *v < 0.87));
        assert!(l.len() >= 4, "{l:?}");
        assert_eq!(level_decimals(&l), 1);
        let d = diverging(0.5);
        assert_eq!((d.0, d.1, d.2), (247, 247, 247));
    }

    #[test]
    fn renders_heat_map_png_and_svg() {
        let g: Vec<f64> = (0..5).map(|i| i as f64).collect();
        let mut z: Vec<f64> = g
            .iter()
            .flat_map(|x| g.iter().map(move |y| x - y))
            .collect();
        z[3] = f64::NAN;
        let f = Field {
            x: g.clone(),
            y: g,
            z,
        };
        let mut p = MapPanel::new("t", "a [-]", "b [-]");
        p.heat = Some(Heat {
            field: f.clone(),
            label: "z [-]".into(),
            scheme: Scheme::Diverging,
            nan_label: "no value".into(),
        });
        p.contours.push(Contours {
            field: f,
            levels: vec![0.0],
            label: "zero".into(),
            color: 7,
            width: 2,
            dashed: false,
            level_labels: Some(1),
        });
        let mut fig = MapFigure::new(1);
        fig.panels.push(p);
        let svg = String::from_utf8(render(&fig, Format::Svg).unwrap()).unwrap();
        assert!(svg.contains("a [-]") && svg.contains("z [-]"));
        let png = render(&fig, Format::Png).unwrap();
        assert_eq!(&png[1..4], b"PNG");
    }
}
