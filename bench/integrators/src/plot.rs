//! Work-precision figure: wall time vs maximum scaled deviation, one panel per case.

use crate::runners::Method;
use crate::CaseResult;
use anyhow::{anyhow, Result};
use plotters::prelude::*;
use plotters::style::FontStyle;
use std::path::Path;

static FONT: &[u8] = include_bytes!("../../../assets/DejaVuSans.ttf");

fn color(m: Method) -> RGBColor {
    match m {
        Method::MvemDopri5 => RGBColor(0, 0, 0),
        Method::Tsit45 => RGBColor(31, 119, 180),
        Method::Bdf => RGBColor(214, 39, 40),
        Method::TrBdf2 => RGBColor(44, 160, 44),
        Method::Esdirk34 => RGBColor(148, 103, 189),
        Method::MvemDopri5NoStops => RGBColor(127, 127, 127),
        Method::BdfJumpsOnly => RGBColor(255, 127, 14),
    }
}

fn decade_bounds(lo: f64, hi: f64) -> (f64, f64) {
    (
        10f64.powf(lo.log10().floor()),
        10f64.powf(hi.log10().ceil()),
    )
}

/// Tick label on a log axis: only 1, 2 and 5 times a power of ten are labelled.
fn log_label(v: &f64) -> String {
    let e = v.log10().floor();
    let m = v / 10f64.powf(e);
    let nice = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .any(|n| (m - n).abs() < 1e-6 * n);
    if !nice {
        String::new()
    } else if *v >= 1.0 {
        format!("{v:.0}")
    } else {
        format!("{:.*}", (-e) as usize, v)
    }
}

/// Draw the figure to `path` (PNG): one column per case; top row wall time, bottom row CPU
/// time (the machine is shared, so wall time carries the other load).
pub fn work_precision(path: &Path, results: &[CaseResult], rtol_main: f64) -> Result<()> {
    plotters::style::register_font("sans-serif", FontStyle::Normal, FONT)
        .map_err(|_| anyhow!("cannot load the embedded DejaVuSans font"))?;
    let root = BitMapBackend::new(path, (1400, 1100)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow!("{e:?}"))?;
    let (title, body) = root.split_vertically(44);
    title
        .titled(
            "mvem 8-state model: time vs accuracy (points: rtol 1e-4 ... 1e-8, ring: rtol 1e-6)",
            ("sans-serif", 22),
        )
        .map_err(|e| anyhow!("{e:?}"))?;
    let panels = body.split_evenly((2, results.len()));
    for (i, res) in results.iter().enumerate() {
        panel(&panels[i], res, rtol_main, false)?;
        panel(&panels[results.len() + i], res, rtol_main, true)?;
    }
    root.present().map_err(|e| anyhow!("{e:?}"))?;
    Ok(())
}

fn panel(
    area: &DrawingArea<BitMapBackend, plotters::coord::Shift>,
    res: &CaseResult,
    rtol_main: f64,
    cpu: bool,
) -> Result<()> {
    let time = |p: &crate::Point| if cpu { p.cpu_s * 1e3 } else { p.wall_s * 1e3 };
    let pts: Vec<_> = res
        .points
        .iter()
        .filter(|p| p.dev_max().is_finite() && p.dev_max() > 0.0)
        .collect();
    if pts.is_empty() {
        return Ok(());
    }
    let (x0, x1) = (
        pts.iter().map(|p| time(p)).fold(f64::INFINITY, f64::min) / 1.3,
        pts.iter().map(|p| time(p)).fold(0.0, f64::max) * 1.3,
    );
    let (y0, y1) = decade_bounds(
        pts.iter()
            .map(|p| p.dev_max())
            .fold(f64::INFINITY, f64::min),
        pts.iter().map(|p| p.dev_max()).fold(0.0, f64::max),
    );
    let kind = if cpu { "CPU time" } else { "wall time" };
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!("{} ({} stop times): {kind}", res.name, res.n_stops),
            ("sans-serif", 20),
        )
        .margin(12)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
        .map_err(|e| anyhow!("{e:?}"))?;
    chart
        .configure_mesh()
        .x_desc(format!("{kind} per run [ms] (min of 3)"))
        .y_desc("max scaled deviation from reference [-]")
        .x_labels(30)
        .x_label_formatter(&log_label)
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .label_style(("sans-serif", 15))
        .axis_desc_style(("sans-serif", 16))
        .draw()
        .map_err(|e| anyhow!("{e:?}"))?;
    for m in Method::ALL {
        let c = color(m);
        let series: Vec<(f64, f64)> = pts
            .iter()
            .filter(|p| p.method == m)
            .map(|p| (time(p), p.dev_max()))
            .collect();
        if series.is_empty() {
            continue;
        }
        // variants that do not stop at every breakpoint: dashed
        if m.variant() {
            chart
                .draw_series(DashedLineSeries::new(
                    series.clone(),
                    8,
                    5,
                    c.stroke_width(2),
                ))
                .map_err(|e| anyhow!("{e:?}"))?
                .label(m.label())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 8, y)], c.stroke_width(3))
                });
        } else {
            chart
                .draw_series(LineSeries::new(series.clone(), c.stroke_width(2)))
                .map_err(|e| anyhow!("{e:?}"))?
                .label(m.label())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(3))
                });
        }
        chart
            .draw_series(
                series
                    .iter()
                    .map(|&(x, y)| Circle::new((x, y), 4, c.filled())),
            )
            .map_err(|e| anyhow!("{e:?}"))?;
        chart
            .draw_series(
                pts.iter()
                    .filter(|p| p.method == m && p.rtol == rtol_main)
                    .map(|p| Circle::new((time(p), p.dev_max()), 9, c.stroke_width(2))),
            )
            .map_err(|e| anyhow!("{e:?}"))?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerLeft)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 15))
        .draw()
        .map_err(|e| anyhow!("{e:?}"))?;
    Ok(())
}
