//! `mvem map`: steady states over a grid of one to four inputs (the others fixed), in parallel,
//! with a CSV of every state and signal and validity flags, heat-map figures of chosen outputs,
//! and optionally the DC gain and right-half-plane zeros of SISO channels over the grid (the
//! sign-reversal maps).

use crate::commands::step::display;
use crate::common::{self, ModelArgs};
use crate::plot_maps::{self, Contours, Field, Heat, MapFigure, MapPanel, Points, Scheme};
use anyhow::{Context, Result};
use mvem::analysis::map::{
    channel_map, steady_map, Axis, ChannelMapOptions, Grid, MapOptions, SteadyMap,
};
use mvem::analysis::zeros::{parse_channel, Channel};
use mvem::model::{Drive, Model, Signals};
use std::path::PathBuf;

/// Arguments of `mvem map`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  mvem map --axis u_egr=0:100:41 --axis u_vgt=20:100:41 --n-e 1500 --u-delta 110 --out map.csv --plot map.png
  mvem map --axis n_e=800:2000:25 --axis u_delta=20:240:23 --u-egr 50 --u-vgt 50 --plot-outputs lambda_O,M_e --plot load.svg
  mvem map --axis u_vgt=20.5:100:33 --axis u_egr=0:100:33 --n-e 1500 --u-delta 110 --channel 'u_vgt->W_c' --channel 'u_egr->p_im' --plot sign.png
  mvem map --axis n_e=1000,1500,2000 --axis u_delta=50,150 --axis u_egr=0,50 --axis u_vgt=40,80 --out grid4.csv

Axes: NAME=LO:HI:N (N evenly spaced values) or NAME=V1,V2,... (increasing), NAME one of n_e
[rpm], u_delta [mg/cycle], u_egr [%], u_vgt [%]. Inputs without an axis are held at their
option (--n-e, --u-delta, --u-egr, --u-vgt), which is then required.

CSV: one row per grid point (never dropped), columns n_e_rpm, u_delta_mg, u_egr_pct, u_vgt_pct, converged,
physically_valid, flags (';'-separated), error, every state, every signal, residual; with
--channel also CH:dc_gain, CH:rhp_zero, CH:zeros, CH:error. Points without an equilibrium have
converged = 0, empty values and the solver's message in `error`; each is also reported on stderr.
Exit code 1 only when no point at all has an equilibrium (the files are still written).
The figure (two axes only) has one heat map per --plot-outputs entry, grey where there is no
equilibrium, crosses where the equilibrium is not physically valid, and per channel the DC gain
with its sign-change boundary and the region with a right-half-plane zero.")]
pub struct Args {
    /// A grid axis: NAME=LO:HI:N or NAME=V1,V2,... (1 to 4 axes; repeat the option).
    #[arg(long = "axis", value_name = "SPEC", required = true)]
    pub axes: Vec<String>,
    /// The operating point; inputs that are not given otherwise are required.
    #[command(flatten)]
    pub point: common::OptionalPointArgs,
    /// SISO channel whose DC gain and RHP zeros are mapped, e.g. u_vgt->W_c (repeatable).
    #[arg(long = "channel", value_name = "IN->OUT")]
    pub channels: Vec<String>,
    /// Write the CSV of all points here.
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Write the heat-map figure here (.png or .svg; two axes only).
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    /// Outputs drawn in the figure (comma separated state or signal names).
    #[arg(
        long = "plot-outputs",
        value_name = "LIST",
        value_delimiter = ',',
        default_value = "lambda_O,x_egr,p_im,W_c,M_e,eta_c"
    )]
    pub plot_outputs: Vec<String>,
    /// Worker threads (0: all cores; at most 1024).
    #[arg(long, value_name = "N", default_value = "0", value_parser = common::threads_arg)]
    pub threads: usize,
    #[command(flatten)]
    pub model: ModelArgs,
}

/// CSV columns of the grid inputs in `Drive::NAMES` order.
pub const INPUT_COLUMNS: [&str; 4] = ["n_e_rpm", "u_delta_mg", "u_egr_pct", "u_vgt_pct"];

/// Units of the inputs in `Drive::NAMES` order.
pub const DRIVE_UNITS: [&str; 4] = ["rpm", "mg/cycle", "%", "%"];

/// Parse `NAME=LO:HI:N` or `NAME=V1,V2,...`.
pub fn parse_axis(spec: &str) -> Result<Axis> {
    let bad = |why: &str| common::usage(format!("--axis {spec}: {why}"));
    let (name, rest) = spec
        .split_once('=')
        .ok_or_else(|| bad("expected NAME=LO:HI:N or NAME=V1,V2,..."))?;
    let name = name.trim();
    if !Drive::NAMES.contains(&name) {
        return Err(bad(&format!(
            "unknown input {name:?} (known: {})",
            Drive::NAMES.join(", ")
        )));
    }
    let num = |s: &str| -> Result<f64> {
        let v: f64 = s
            .trim()
            .parse()
            .map_err(|_| bad(&format!("{:?} is not a number", s.trim())))?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(bad(&format!("{v} is not finite")))
        }
    };
    let values = if rest.contains(':') {
        let parts: Vec<&str> = rest.split(':').collect();
        if parts.len() != 3 {
            return Err(bad("expected LO:HI:N"));
        }
        let (lo, hi) = (num(parts[0])?, num(parts[1])?);
        let n: usize = parts[2]
            .trim()
            .parse()
            .map_err(|_| bad(&format!("N = {:?} is not a whole number", parts[2].trim())))?;
        if !(2..=2000).contains(&n) {
            return Err(bad("N must lie in 2..=2000"));
        }
        if hi <= lo {
            return Err(bad("HI must be greater than LO"));
        }
        Axis::linspace(name, lo, hi, n).values
    } else {
        let v = rest.split(',').map(num).collect::<Result<Vec<f64>>>()?;
        if v.windows(2).any(|w| w[1] <= w[0]) {
            return Err(bad("values must be strictly increasing"));
        }
        v
    };
    Ok(Axis::new(name, values))
}

/// The grid from the axes and the base options.
fn grid(a: &Args) -> Result<Grid> {
    let axes = a
        .axes
        .iter()
        .map(|s| parse_axis(s))
        .collect::<Result<Vec<_>>>()?;
    if axes.len() > 4 {
        return Err(common::usage(format!(
            "{} --axis options given; at most 4",
            axes.len()
        )));
    }
    let given = a.point.given();
    let mut base = [0.0; 4];
    for k in 0..4 {
        let on_axis = axes.iter().any(|ax| ax.input == Drive::NAMES[k]);
        base[k] = match (on_axis, given[k]) {
            (true, Some(_)) => {
                return Err(common::usage(format!(
                    "{} given for {}, which is an --axis",
                    common::INPUT_OPTIONS[k],
                    Drive::NAMES[k]
                )))
            }
            (true, None) => axes
                .iter()
                .find(|ax| ax.input == Drive::NAMES[k])
                .map_or(0.0, |ax| ax.values[0]),
            (false, Some(v)) => v,
            (false, None) => {
                return Err(common::usage(format!(
                    "{} is required ({} is not an --axis)",
                    common::INPUT_OPTIONS[k],
                    Drive::NAMES[k]
                )))
            }
        };
    }
    let ranges = a.model.input_ranges()?;
    // an input on an axis is warned of per axis below, not as the point's placeholder value
    let on_axis = std::array::from_fn(|k| axes.iter().any(|ax| ax.input == Drive::NAMES[k]));
    common::check_drive_except(&Drive::from_array(base), ranges.as_ref(), on_axis)?;
    // (no warnings when the model saturates nothing: --semantics paper)
    for (ax, ranges) in axes.iter().filter_map(|ax| Some((ax, ranges.as_ref()?))) {
        let k = Drive::NAMES
            .iter()
            .position(|n| *n == ax.input)
            .unwrap_or(0);
        let (_, lo, hi) = ranges[k];
        let out: Vec<f64> = ax
            .values
            .iter()
            .copied()
            .filter(|v| *v < lo || *v > hi)
            .collect();
        if !out.is_empty() {
            eprintln!(
                "warning: --axis {}: {} value(s) outside [{lo}, {hi}] (e.g. {}); the authors' saturation clamps them",
                ax.input,
                out.len(),
                out[0]
            );
        }
    }
    Grid::new(Drive::from_array(base), axes).map_err(|e| common::usage(e.to_string()))
}

/// A progress bar on stderr (only when stderr is a terminal).
pub fn progress_bar(msg: &str, total: usize) -> Option<indicatif::ProgressBar> {
    if !common::stderr_is_terminal() {
        return None;
    }
    let pb = indicatif::ProgressBar::new(total as u64);
    pb.set_draw_target(indicatif::ProgressDrawTarget::stderr());
    if let Ok(s) = indicatif::ProgressStyle::with_template(
        "{msg} [{bar:40}] {pos}/{len} points ({elapsed}, eta {eta})",
    ) {
        pb.set_style(s.progress_chars("=> "));
    }
    pb.set_message(msg.to_string());
    Some(pb)
}

/// A steady-state map and the channel results, with a progress bar.
pub struct MapRun<const N: usize> {
    /// The steady states.
    pub map: SteadyMap<N>,
    /// Per channel (name, per point result).
    pub channels: Vec<(String, Vec<Result<Channel, String>>)>,
}

/// Solve the grid and the channels.
pub fn compute<const N: usize, M: Model<N>>(
    m: &M,
    grid: &Grid,
    channels: &[String],
    threads: usize,
) -> Result<MapRun<N>> {
    let pb = progress_bar("steady states", grid.len());
    let cb = |k: usize, _n: usize| {
        if let Some(p) = &pb {
            p.set_position(k as u64);
        }
    };
    let map = steady_map(
        m,
        grid,
        &MapOptions {
            threads,
            ..MapOptions::default()
        },
        Some(&cb),
    )?;
    if let Some(p) = &pb {
        p.finish_and_clear();
    }
    let mut out = Vec::new();
    for ch in channels {
        let (i, o) = parse_channel(ch).map_err(|e| common::usage(format!("--channel: {e}")))?;
        let pb = progress_bar(&format!("channel {ch}"), grid.len());
        let cb = |k: usize, _n: usize| {
            if let Some(p) = &pb {
                p.set_position(k as u64);
            }
        };
        let r = channel_map(
            m,
            &map,
            &i,
            &o,
            &ChannelMapOptions {
                threads,
                ..ChannelMapOptions::default()
            },
            Some(&cb),
        )?;
        if let Some(p) = &pb {
            p.finish_and_clear();
        }
        out.push((ch.clone(), r));
    }
    Ok(MapRun { map, channels: out })
}

/// Check channel names before solving anything.
pub fn check_channels<const N: usize, M: Model<N>>(m: &M, channels: &[String]) -> Result<()> {
    for ch in channels {
        let (i, o) = parse_channel(ch).map_err(|e| common::usage(format!("--channel: {e}")))?;
        if !mvem::analysis::linearize::INPUT_NAMES.contains(&i.as_str()) {
            return Err(common::usage(format!(
                "--channel {ch}: unknown input {i:?} (known: u_delta, u_egr, u_vgt, n_e)"
            )));
        }
        check_output(m, &o, &format!("--channel {ch}"))?;
    }
    Ok(())
}

/// A usage error unless `name` is a state or signal.
pub fn check_output<const N: usize, M: Model<N>>(m: &M, name: &str, what: &str) -> Result<()> {
    if m.state_names().contains(&name) || Signals::NAMES.contains(&name) {
        Ok(())
    } else {
        Err(common::usage(format!(
            "{what}: unknown output {name:?}; known: the states {} and the signals {}",
            m.state_names().join(", "),
            Signals::NAMES.join(", ")
        )))
    }
}

/// The CSV text of a map run.
pub fn csv_text<const N: usize, M: Model<N>>(m: &M, r: &MapRun<N>) -> Result<String> {
    let mut w = csv::Writer::from_writer(Vec::new());
    // the input columns as in input CSVs (the signals n_e, u_delta, ... are the saturated inputs)
    let mut header: Vec<String> = INPUT_COLUMNS.iter().map(|s| s.to_string()).collect();
    header.extend(
        ["converged", "physically_valid", "flags", "error"]
            .iter()
            .map(|s| s.to_string()),
    );
    header.extend(m.state_names().iter().map(|s| s.to_string()));
    header.extend(Signals::NAMES.iter().map(|s| s.to_string()));
    header.push("residual".into());
    for (ch, _) in &r.channels {
        for c in ["dc_gain", "rhp_zero", "zeros", "error"] {
            header.push(format!("{ch}:{c}"));
        }
    }
    w.write_record(&header)?;
    let empty = N + Signals::COUNT + 1;
    for (k, p) in r.map.points.iter().enumerate() {
        let mut row: Vec<String> = p.drive.to_array().iter().map(|v| v.to_string()).collect();
        match &p.result {
            Ok(ss) => {
                row.push("1".into());
                row.push(if ss.physically_valid() { "1" } else { "0" }.into());
                row.push(ss.flags.join(";"));
                row.push(String::new());
                row.extend(ss.x.iter().map(|v| v.to_string()));
                row.extend(ss.signals.values().iter().map(|v| v.to_string()));
                row.push(ss.residual.to_string());
            }
            Err(e) => {
                row.extend(["0".into(), "0".into(), String::new(), e.clone()]);
                row.extend(std::iter::repeat_n(String::new(), empty));
            }
        }
        for (_, res) in &r.channels {
            match &res[k] {
                Ok(c) => {
                    row.push(c.dc_gain.to_string());
                    row.push(if c.zeros.has_rhp() { "1" } else { "0" }.into());
                    row.push(
                        c.zeros
                            .finite
                            .iter()
                            .map(|z| {
                                if z.im == 0.0 {
                                    format!("{}", z.re)
                                } else {
                                    format!("{}{:+}i", z.re, z.im)
                                }
                            })
                            .collect::<Vec<_>>()
                            .join(";"),
                    );
                    row.push(String::new());
                }
                Err(e) => row.extend([String::new(), String::new(), String::new(), e.clone()]),
            }
        }
        w.write_record(&row)?;
    }
    let bytes = w.into_inner().map_err(|e| anyhow::anyhow!("CSV: {e}"))?;
    Ok(String::from_utf8(bytes)?)
}

/// Report the points without an equilibrium on stderr (one line each, at most `max`).
pub fn report_failures<const N: usize>(r: &MapRun<N>, max: usize) {
    let failed: Vec<_> = r.map.points.iter().filter(|p| p.result.is_err()).collect();
    for p in failed.iter().take(max) {
        if let Err(e) = &p.result {
            eprintln!("point ({}): {e}", common::fmt_drive(&p.drive));
        }
    }
    if failed.len() > max {
        eprintln!(
            "... and {} more points without an equilibrium (see the error column of the CSV)",
            failed.len() - max
        );
    }
}

fn axis_label(name: &str) -> String {
    let k = Drive::NAMES.iter().position(|n| *n == name).unwrap_or(0);
    format!("{name} [{}]", DRIVE_UNITS[k])
}

fn field<const N: usize>(r: &MapRun<N>, z: Vec<f64>) -> Field {
    Field {
        x: r.map.grid.axes[0].values.clone(),
        y: r.map.grid.axes[1].values.clone(),
        z,
    }
}

/// Points converged but not physically valid, as crosses.
fn invalid_points<const N: usize>(r: &MapRun<N>) -> Points {
    let g = &r.map.grid;
    let (mut x, mut y) = (Vec::new(), Vec::new());
    for p in &r.map.points {
        if let Ok(ss) = &p.result {
            if !ss.physically_valid() {
                x.push(g.axes[0].values[p.index[0]]);
                y.push(g.axes[1].values[p.index[1]]);
            }
        }
    }
    Points {
        x,
        y,
        label: "not physically valid (flags)".into(),
        color: 7,
        radius: 3,
        cross: true,
    }
}

/// The heat-map panel of one output.
pub fn output_panel<const N: usize, M: Model<N>>(m: &M, r: &MapRun<N>, name: &str) -> MapPanel {
    let (sc, unit) = display(name);
    let z: Vec<f64> = r
        .map
        .values(name, &m.state_names())
        .iter()
        .map(|v| v * sc)
        .collect();
    let f = field(r, z);
    let g = &r.map.grid;
    let mut p = MapPanel::new(
        format!("{name} [{unit}]"),
        axis_label(&g.axes[0].input),
        axis_label(&g.axes[1].input),
    );
    let levels = plot_maps::nice_levels(&f.z, 7);
    let dec = plot_maps::level_decimals(&levels);
    p.contours.push(Contours {
        field: f.clone(),
        levels,
        label: String::new(),
        color: 7,
        width: 1,
        dashed: false,
        level_labels: Some(dec),
    });
    p.heat = Some(Heat {
        field: f,
        label: format!("{name} [{unit}]"),
        scheme: Scheme::Sequential,
        nan_label: "no equilibrium".into(),
    });
    let inv = invalid_points(r);
    if !inv.x.is_empty() {
        p.points.push(inv);
    }
    p
}

/// The DC-gain panel of a channel: diverging heat map, the sign-change boundary (gain = 0),
/// the boundary of the RHP-zero region and dots where there is an RHP zero.
pub fn channel_panel<const N: usize>(
    r: &MapRun<N>,
    ch: &str,
    res: &[Result<Channel, String>],
) -> MapPanel {
    let (i, o) = parse_channel(ch).unwrap_or_default();
    let gains: Vec<f64> = res
        .iter()
        .map(|c| c.as_ref().map_or(f64::NAN, |c| c.dc_gain))
        .collect();
    let rhp: Vec<f64> = res
        .iter()
        .map(|c| {
            c.as_ref()
                .map_or(f64::NAN, |c| if c.zeros.has_rhp() { 1.0 } else { 0.0 })
        })
        .collect();
    let g = &r.map.grid;
    let mut p = MapPanel::new(
        format!("DC gain and RHP zeros of {i} → {o}"),
        axis_label(&g.axes[0].input),
        axis_label(&g.axes[1].input),
    );
    p.heat = Some(Heat {
        field: field(r, gains.clone()),
        label: format!(
            "dc gain [{}]",
            mvem::model::meta::gain_unit(common::unit(&o), common::unit(&i))
        ),
        scheme: Scheme::Diverging,
        nan_label: "no equilibrium / kink".into(),
    });
    // the sign-change boundary separates strictly negative from strictly positive gains;
    // points with a gain of exactly 0 (no path, e.g. no EGR flow or f_egr past its vertex)
    // are left out of it
    let gmax = gains
        .iter()
        .filter(|g| g.is_finite())
        .fold(0.0f64, |a, g| a.max(g.abs()));
    let signed: Vec<f64> = gains
        .iter()
        .map(|&g| if g.abs() <= 1e-12 * gmax { f64::NAN } else { g })
        .collect();
    p.contours.push(Contours {
        field: field(r, signed),
        levels: vec![0.0],
        label: "sign change (DC gain = 0)".into(),
        color: 7,
        width: 3,
        dashed: false,
        level_labels: None,
    });
    p.contours.push(Contours {
        field: field(r, rhp.clone()),
        levels: vec![0.5],
        label: "boundary of the RHP-zero region".into(),
        color: 3,
        width: 3,
        dashed: true,
        level_labels: None,
    });
    let (mut x, mut y) = (Vec::new(), Vec::new());
    for (pt, v) in r.map.points.iter().zip(&rhp) {
        if *v == 1.0 {
            x.push(g.axes[0].values[pt.index[0]]);
            y.push(g.axes[1].values[pt.index[1]]);
        }
    }
    p.points.push(Points {
        x,
        y,
        label: "RHP zero (non-minimum phase)".into(),
        color: 7,
        radius: 2,
        cross: false,
    });
    p
}

/// The figure of a two-axis map run.
pub fn figure<const N: usize, M: Model<N>>(
    m: &M,
    r: &MapRun<N>,
    outputs: &[String],
    title: &str,
) -> MapFigure {
    let mut f = MapFigure::new(if outputs.len() + r.channels.len() == 1 {
        1
    } else {
        2
    });
    f.title = Some(title.to_string());
    for o in outputs {
        f.panels.push(output_panel(m, r, o));
    }
    for (ch, res) in &r.channels {
        f.panels.push(channel_panel(r, ch, res));
    }
    f
}

/// Title naming the fixed inputs.
pub fn title(grid: &Grid) -> String {
    let fixed: Vec<String> = Drive::NAMES
        .iter()
        .zip(grid.base.to_array())
        .zip(DRIVE_UNITS)
        .filter(|((n, _), _)| !grid.axes.iter().any(|a| a.input == **n))
        .map(|((n, v), u)| format!("{n} = {v} {u}"))
        .collect();
    format!("Steady-state map at {}", fixed.join(", "))
}

/// Run `mvem map`.
pub fn run(a: &Args) -> Result<()> {
    let grid = grid(a)?;
    if a.plot.is_some() && grid.axes.len() != 2 {
        return Err(common::usage(format!(
            "--plot needs exactly two --axis options ({} given); the CSV holds any grid",
            grid.axes.len()
        )));
    }
    for (p, what) in [(&a.plot, "--plot"), (&a.out, "--out")] {
        if let Some(p) = p {
            common::check_output_path(p, what)?;
        }
    }
    if let Some(p) = &a.plot {
        crate::plot::Format::of(p)?;
    }
    let model = a.model.build()?;
    mvem::dispatch!(&model, m => {
        check_channels(m, &a.channels)?;
        if a.plot.is_some() {
            for o in &a.plot_outputs {
                check_output(m, o.trim(), "--plot-outputs")?;
            }
        }
        let t = std::time::Instant::now();
        let r = compute(m, &grid, &a.channels, a.threads)?;
        let secs = t.elapsed().as_secs_f64();
        report_failures(&r, 20);
        let valid = r
            .map
            .points
            .iter()
            .filter(|p| p.result.as_ref().is_ok_and(|s| s.physically_valid()))
            .count();
        eprintln!(
            "{} points: {} with an equilibrium ({} physically valid), {} without; {:.2} s",
            grid.len(),
            r.map.converged(),
            valid,
            grid.len() - r.map.converged(),
            secs
        );
        for (ch, res) in &r.channels {
            let ok: Vec<&Channel> = res.iter().filter_map(|c| c.as_ref().ok()).collect();
            eprintln!(
                "channel {ch}: {} points analysed, DC gain negative at {}, positive at {}, RHP zero at {}",
                ok.len(),
                ok.iter().filter(|c| c.dc_gain < 0.0).count(),
                ok.iter().filter(|c| c.dc_gain > 0.0).count(),
                ok.iter().filter(|c| c.zeros.has_rhp()).count()
            );
        }
        let fig = match &a.plot {
            Some(p) => {
                let outs: Vec<String> = a.plot_outputs.iter().map(|s| s.trim().to_string()).collect();
                let f = figure(m, &r, &outs, &title(&grid));
                Some((p, plot_maps::render(&f, crate::plot::Format::of(p)?)?))
            }
            None => None,
        };
        let csv = csv_text(m, &r)?;
        match &a.out {
            Some(p) => mvem::io::output::write_atomic(p, csv.as_bytes())
                .with_context(|| format!("cannot write {}", p.display()))?,
            None if a.plot.is_none() => print!("{csv}"),
            None => {}
        }
        if let Some((p, bytes)) = fig {
            mvem::io::output::write_atomic(p, &bytes)
                .with_context(|| format!("cannot write {}", p.display()))?;
        }
        if r.map.converged() == 0 {
            anyhow::bail!("no grid point has an equilibrium (the CSV lists each point's reason)");
        }
        Ok::<(), anyhow::Error>(())
    })?;
    Ok(())
}
