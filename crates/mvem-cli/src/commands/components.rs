//! `mvem components`: component maps like the paper's figures, computed from the component
//! functions of `mvem::components`: the compressor map with efficiency ellipses and speed lines
//! (Fig. 7), the turbine flow functions (Fig. 5) and efficiency, the EGR flow functions
//! (Fig. 3); operating points of any simulation CSV can be overlaid.

use crate::common::{self, ModelArgs};
use crate::plot::Format;
use crate::plot_maps::{self, Contours, Curve, Field, MapFigure, MapPanel, Points};
use anyhow::{Context, Result};
use mvem::components::{compressor, egr, turbine, Semantics};
use mvem::params::Params;
use std::path::{Path, PathBuf};

/// Arguments of `mvem components`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  mvem components --out out/components
  mvem simulate --scenario whtc --out whtc.csv --dt 0.1 && mvem components --overlay whtc.csv --out out/components
  mvem components --params my.toml --semantics paper --out maps

Writes DIR/compressor.{png,svg} (Pi_c over W_c: efficiency contours eq. (62), speed lines eqs
(66)-(72)), DIR/turbine.{png,svg} (f_Pi_t over Pi_t eq. (53), f_vgt over u_vgt eq. (56), eta_tm
over BSR eqs (49)-(51) at several turbo speeds) and DIR/egr.{png,svg} (Psi_egr over Pi_egr eq.
(34), f_egr over u_egr eq. (38)). --overlay takes a CSV written by `mvem simulate` (columns
W_c, Pi_c, Pi_t, BSR, eta_tm, omega_t, u_vgt_actual, Pi_egr, u_egr_actual, W_egr) and draws its
rows as operating points.")]
pub struct Args {
    /// Output directory (created if missing).
    #[arg(long, value_name = "DIR", default_value = "out/components")]
    pub out: PathBuf,
    /// Simulation CSV whose operating points are drawn on the maps.
    #[arg(long, value_name = "FILE")]
    pub overlay: Option<PathBuf>,
    /// At most this many overlay points per figure (evenly thinned).
    #[arg(long = "max-points", value_name = "N", default_value = "3000")]
    pub max_points: usize,
    #[command(flatten)]
    pub model: ModelArgs,
}

/// Columns read from an overlay CSV.
const OVERLAY_COLUMNS: [&str; 10] = [
    "W_c",
    "Pi_c",
    "Pi_t",
    "BSR",
    "eta_tm",
    "omega_t",
    "u_vgt_actual",
    "Pi_egr",
    "u_egr_actual",
    "W_egr",
];

/// Overlay columns by name (same order as [`OVERLAY_COLUMNS`]), thinned to `max` rows.
pub struct Overlay {
    /// Source file name (legend).
    pub name: String,
    /// Columns.
    pub cols: Vec<Vec<f64>>,
}

impl Overlay {
    fn col(&self, name: &str) -> &[f64] {
        let k = OVERLAY_COLUMNS.iter().position(|c| *c == name).unwrap_or(0);
        &self.cols[k]
    }
}

/// Read the overlay columns of a simulation CSV (usage errors name the file, line and column).
pub fn read_overlay(path: &Path, max: usize) -> Result<Overlay> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| common::usage(format!("--overlay {}: {e}", path.display())))?;
    let mut r = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .from_reader(text.as_bytes());
    let header: Vec<String> = r
        .headers()
        .map_err(|e| common::usage(format!("--overlay {}: {e}", path.display())))?
        .iter()
        .map(|s| s.trim().to_string())
        .collect();
    let idx = OVERLAY_COLUMNS
        .iter()
        .map(|c| {
            header.iter().position(|h| h == c).ok_or_else(|| {
                common::usage(format!(
                    "--overlay {}: no column {c} (a CSV written by `mvem simulate` has it)",
                    path.display()
                ))
            })
        })
        .collect::<Result<Vec<usize>>>()?;
    let mut cols = vec![Vec::new(); OVERLAY_COLUMNS.len()];
    for (line, rec) in r.records().enumerate() {
        let rec = rec.map_err(|e| common::usage(format!("--overlay {}: {e}", path.display())))?;
        for (k, &i) in idx.iter().enumerate() {
            let cell = rec.get(i).unwrap_or("").trim();
            let v: f64 = cell.parse().map_err(|_| {
                common::usage(format!(
                    "--overlay {}, line {}, column {}: {cell:?} is not a number",
                    path.display(),
                    line + 2,
                    OVERLAY_COLUMNS[k]
                ))
            })?;
            cols[k].push(v);
        }
    }
    let n = cols[0].len();
    if n == 0 {
        return Err(common::usage(format!(
            "--overlay {}: no data rows",
            path.display()
        )));
    }
    let step = n.div_ceil(max.max(1));
    let cols = cols
        .into_iter()
        .map(|c| c.into_iter().step_by(step).collect())
        .collect();
    Ok(Overlay {
        name: path
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default(),
        cols,
    })
}

fn linspace(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| lo + (hi - lo) * i as f64 / (n - 1) as f64)
        .collect()
}

fn overlay_points(ov: &Overlay, x: Vec<f64>, y: Vec<f64>, what: &str) -> Points {
    Points {
        x,
        y,
        label: format!("{what} ({})", ov.name),
        color: 1,
        radius: 2,
        cross: false,
    }
}

/// Turbo speeds of the speed lines [rad/s].
pub const SPEED_LINES: [f64; 6] = [4000.0, 6000.0, 8000.0, 10000.0, 12000.0, 14000.0];

/// Compressor map (Fig. 7): efficiency contours, eq. (62), and speed lines, eqs (66)-(72).
pub fn compressor_figure(p: &Params, sem: Semantics, ov: Option<&Overlay>) -> MapFigure {
    let c = &p.compressor;
    let g = &p.gas;
    let (t_amb, p_amb) = (p.ambient.t_amb, p.ambient.p_amb);
    let (w_max, pi_max) = (0.6, 4.0);
    let wx = linspace(0.0, w_max, 181);
    let py = linspace(1.0, pi_max, 181);
    let z: Vec<f64> = wx
        .iter()
        .flat_map(|&w| {
            py.iter()
                .map(move |&pi| compressor::efficiency(c, w, pi, sem))
        })
        .collect();
    let mut panel = MapPanel::new(
        "Compressor map: efficiency eta_c (eq. (62)) and speed lines (eqs (66)-(72))",
        "W_c [kg/s]",
        "Pi_c [-]",
    );
    panel.x_range = Some((0.0, w_max));
    panel.y_range = Some((1.0, pi_max));
    panel.contours.push(Contours {
        field: Field { x: wx, y: py, z },
        levels: vec![0.5, 0.6, 0.65, 0.7, 0.72, 0.73],
        label: "efficiency eta_c [-]".into(),
        color: 0,
        width: 2,
        dashed: false,
        level_labels: Some(2),
    });
    for (k, &omega) in SPEED_LINES.iter().enumerate() {
        let pis = linspace(1.0, pi_max, 400);
        let mut x = Vec::new();
        let mut y = Vec::new();
        for &pi in &pis {
            let iso = compressor::isentropic_term(pi, g.gamma_a);
            let f = compressor::flow(c, g.c_pa, g.r_a, t_amb, p_amb, iso, omega, sem);
            // the speed line ends where the square root of eq. (71) reaches 0 (surge side)
            if f.phi_c - c.c_phi2 > 1e-9 {
                x.push(f.w_c);
                y.push(pi);
            }
        }
        panel.curves.push(Curve {
            x,
            y,
            label: if k == 0 {
                "speed lines (omega_t [rad/s])".into()
            } else {
                String::new()
            },
            color: 7,
            dashed: true,
            end_text: Some(format!("{omega:.0}")),
        });
    }
    if let Some(ov) = ov {
        panel.points.push(overlay_points(
            ov,
            ov.col("W_c").to_vec(),
            ov.col("Pi_c").to_vec(),
            "operating points",
        ));
    }
    let mut f = MapFigure::new(1);
    f.panel_size = (900, 680);
    f.panels.push(panel);
    f
}

/// Turbine (Fig. 5): f_Pi_t (eq. (53)), f_vgt (eq. (56)) and eta_tm over BSR (eqs (49)-(51)).
pub fn turbine_figure(p: &Params, sem: Semantics, ov: Option<&Overlay>) -> MapFigure {
    let t = &p.turbine;
    let g = &p.gas;
    let mut f = MapFigure::new(3);
    f.panel_size = (620, 520);
    f.title = Some("Turbine flow and efficiency (paper Fig. 5)".into());

    let pis = linspace(0.2, 1.0, 200);
    let mut a = MapPanel::new(
        "(a) choking function f_Pi_t, eq. (53)",
        "Pi_t [-]",
        "f_Pi_t [-]",
    );
    a.curves.push(Curve {
        x: pis.clone(),
        y: pis.iter().map(|&pi| turbine::f_pi_t(t, pi)).collect(),
        label: "model".into(),
        color: 0,
        dashed: false,
        end_text: None,
    });
    let us = linspace(20.0, 100.0, 200);
    let mut b = MapPanel::new(
        "(b) effective area f_vgt, eq. (56)",
        "u_vgt [%]",
        "f_vgt [-]",
    );
    b.curves.push(Curve {
        x: us.clone(),
        y: us.iter().map(|&u| turbine::f_vgt(t, u, sem)).collect(),
        label: "model".into(),
        color: 0,
        dashed: false,
        end_text: None,
    });
    let mut c = MapPanel::new(
        "(c) efficiency eta_tm over BSR, eqs (49)-(51)",
        "BSR [-]",
        "eta_tm [-]",
    );
    // eta_tm as a function of BSR at fixed omega_t: eta_tmmax - c_m(omega_t) (BSR - BSR_opt)^2;
    // evaluated through turbine::power with T_em chosen to give each BSR
    let pi_t = 0.5;
    let dh = 1.0 - f64::powf(pi_t, 1.0 - 1.0 / g.gamma_e);
    // c_m (eq. (51)) is 0 below c_m2 = 2769 rad/s, rises on the authors' linear branch up to
    // w_tlin = 2797 rad/s and is almost constant above (c_m3 = 0.01)
    for (k, &omega) in [2775.0, 2785.0, 2797.0, 10000.0].iter().enumerate() {
        let bsrs = linspace(0.05, 2.0 * t.bsr_opt, 120);
        let mut y = Vec::new();
        for &bsr in &bsrs {
            // BSR = R_t omega / sqrt(2 c_pe T_em dh)  =>  T_em = (R_t omega / BSR)^2 / (2 c_pe dh)
            let t_em = (t.r_t * omega / bsr).powi(2) / (2.0 * g.c_pe * dh);
            y.push(turbine::power(t, g.c_pe, g.gamma_e, t_em, pi_t, omega, 0.1, sem).eta_tm);
        }
        c.curves.push(Curve {
            x: bsrs,
            y,
            label: format!("omega_t = {omega:.0} rad/s"),
            color: [0, 2, 4, 3][k],
            dashed: false,
            end_text: None,
        });
    }
    if let Some(ov) = ov {
        let pit = ov.col("Pi_t");
        a.points.push(overlay_points(
            ov,
            pit.to_vec(),
            pit.iter().map(|&pi| turbine::f_pi_t(t, pi)).collect(),
            "operating points",
        ));
        let u = ov.col("u_vgt_actual");
        b.points.push(overlay_points(
            ov,
            u.to_vec(),
            u.iter().map(|&u| turbine::f_vgt(t, u, sem)).collect(),
            "operating points",
        ));
        c.points.push(overlay_points(
            ov,
            ov.col("BSR").to_vec(),
            ov.col("eta_tm").to_vec(),
            "operating points",
        ));
    }
    f.panels.extend([a, b, c]);
    f
}

/// EGR valve (Fig. 3): Psi_egr over Pi_egr (eqs (34)-(35)) and f_egr over u_egr (eq. (38)).
pub fn egr_figure(p: &Params, sem: Semantics, ov: Option<&Overlay>) -> MapFigure {
    let v = &p.egr_valve;
    let mut f = MapFigure::new(2);
    f.panel_size = (700, 520);
    f.title = Some("EGR valve flow functions (paper Fig. 3)".into());
    // p_im / p_em from 0.2 to 1.05; eq. (35) limits it to [Pi_egropt, 1]
    let ratios = linspace(0.2, 1.05, 300);
    let mut a = MapPanel::new(
        "(a) flow function Psi_egr, eqs (34)-(35)",
        "p_im / p_em [-]",
        "Psi_egr [-]",
    );
    a.curves.push(Curve {
        x: ratios.clone(),
        y: ratios
            .iter()
            .map(|&r| egr::psi_egr(v, egr::pi_egr(v, r, 1.0)))
            .collect(),
        label: "model (choked below Pi_egr,opt, no flow above 1)".into(),
        color: 0,
        dashed: false,
        end_text: None,
    });
    let us = linspace(0.0, 100.0, 300);
    let mut b = MapPanel::new(
        "(b) effective area f_egr, eq. (38)",
        "u_egr [%]",
        "f_egr [-]",
    );
    b.curves.push(Curve {
        x: us.clone(),
        y: us.iter().map(|&u| egr::f_egr(v, u, sem)).collect(),
        label: "model".into(),
        color: 0,
        dashed: false,
        end_text: None,
    });
    if let Some(ov) = ov {
        // only rows with EGR flow
        let flowing: Vec<usize> = (0..ov.col("W_egr").len())
            .filter(|&i| ov.col("W_egr")[i] > 1e-6)
            .collect();
        let pi: Vec<f64> = flowing.iter().map(|&i| ov.col("Pi_egr")[i]).collect();
        a.points.push(overlay_points(
            ov,
            pi.clone(),
            pi.iter().map(|&x| egr::psi_egr(v, x)).collect(),
            "operating points with EGR flow",
        ));
        let u: Vec<f64> = flowing.iter().map(|&i| ov.col("u_egr_actual")[i]).collect();
        b.points.push(overlay_points(
            ov,
            u.clone(),
            u.iter().map(|&x| egr::f_egr(v, x, sem)).collect(),
            "operating points with EGR flow",
        ));
    }
    f.panels.extend([a, b]);
    f
}

/// Run `mvem components`.
pub fn run(a: &Args) -> Result<()> {
    if a.out.exists() && !a.out.is_dir() {
        return Err(common::usage(format!(
            "--out {}: exists and is not a directory",
            a.out.display()
        )));
    }
    let p = a.model.load_params()?;
    let sem = a.model.options().semantics;
    let ov = match &a.overlay {
        Some(path) => Some(read_overlay(path, a.max_points)?),
        None => None,
    };
    let figs = [
        ("compressor", compressor_figure(&p, sem, ov.as_ref())),
        ("turbine", turbine_figure(&p, sem, ov.as_ref())),
        ("egr", egr_figure(&p, sem, ov.as_ref())),
    ];
    let mut rendered = Vec::new();
    for (name, f) in &figs {
        for (ext, fmt) in [("png", Format::Png), ("svg", Format::Svg)] {
            rendered.push((format!("{name}.{ext}"), plot_maps::render(f, fmt)?));
        }
    }
    std::fs::create_dir_all(&a.out)
        .map_err(|e| common::usage(format!("--out {}: {e}", a.out.display())))?;
    let mut written = Vec::new();
    for (name, bytes) in rendered {
        let path = a.out.join(name);
        mvem::io::output::write_atomic(&path, &bytes)
            .with_context(|| format!("cannot write {}", path.display()))?;
        written.push(path.display().to_string());
    }
    println!("Wrote {}", written.join(", "));
    Ok(())
}
