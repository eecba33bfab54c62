//! `mvem components`: component maps like the paper's figures, computed from the component
//! functions of `mvem::components`: the compressor map with efficiency ellipses and speed lines
//! (Fig. 7), the turbine flow functions (Fig. 5) and efficiency, the EGR flow functions
//! (Fig. 3); operating points of any simulation CSV can be overlaid.

use crate::common::{self, ModelArgs};
use crate::plot::Format;
use crate::plot_maps::{self, Contours, Curve, Field, MapFigure, MapPanel, Points};
use anyhow::{Context, Result};
use mvem::analysis::component_maps as maps;
use mvem::components::Semantics;
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

fn curve(c: &maps::Curve, label: impl Into<String>, color: usize) -> Curve {
    Curve {
        x: c.x.clone(),
        y: c.y.clone(),
        label: label.into(),
        color,
        dashed: false,
        end_text: None,
    }
}

/// Compressor map (Fig. 7): efficiency contours, eq. (62), and speed lines, eqs (66)-(72).
pub fn compressor_figure(p: &Params, sem: Semantics, ov: Option<&Overlay>) -> MapFigure {
    let m = maps::compressor_map(p, sem);
    let ((w_lo, w_hi), (pi_lo, pi_hi)) = maps::COMPRESSOR_RANGE;
    let mut panel = MapPanel::new(
        "Compressor map: efficiency eta_c (eq. (62)) and speed lines (eqs (66)-(72))",
        "W_c [kg/s]",
        "Pi_c [-]",
    );
    panel.x_range = Some((w_lo, w_hi));
    panel.y_range = Some((pi_lo, pi_hi));
    panel.contours.push(Contours {
        field: Field {
            x: m.efficiency.x,
            y: m.efficiency.y,
            z: m.efficiency.z,
        },
        levels: vec![0.5, 0.6, 0.65, 0.7, 0.72, 0.73],
        label: "efficiency eta_c [-]".into(),
        color: 0,
        width: 2,
        dashed: false,
        level_labels: Some(2),
    });
    for (k, (omega, line)) in m.speed_lines.iter().enumerate() {
        let label = if k == 0 {
            "speed lines (omega_t [rad/s])"
        } else {
            ""
        };
        panel.curves.push(Curve {
            dashed: true,
            end_text: Some(format!("{omega:.0}")),
            ..curve(line, label, 7)
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
    let m = maps::turbine_maps(p, sem);
    let mut f = MapFigure::new(3);
    f.panel_size = (620, 520);
    f.title = Some("Turbine flow and efficiency (paper Fig. 5)".into());
    let mut a = MapPanel::new(
        "(a) choking function f_Pi_t, eq. (53)",
        "Pi_t [-]",
        "f_Pi_t [-]",
    );
    a.curves.push(curve(&m.f_pi_t, "model", 0));
    let mut b = MapPanel::new(
        "(b) effective area f_vgt, eq. (56)",
        "u_vgt [%]",
        "f_vgt [-]",
    );
    b.curves.push(curve(&m.f_vgt, "model", 0));
    let mut c = MapPanel::new(
        "(c) efficiency eta_tm over BSR, eqs (49)-(51)",
        "BSR [-]",
        "eta_tm [-]",
    );
    for (k, (omega, line)) in m.efficiency.iter().enumerate() {
        c.curves.push(curve(
            line,
            format!("omega_t = {omega:.0} rad/s"),
            [0, 2, 4, 3][k % 4],
        ));
    }
    if let Some(ov) = ov {
        let (pit, u) = (ov.col("Pi_t"), ov.col("u_vgt_actual"));
        let (f_pi_t, f_vgt) = maps::turbine_points(p, sem, pit, u);
        a.points
            .push(overlay_points(ov, pit.to_vec(), f_pi_t, "operating points"));
        b.points
            .push(overlay_points(ov, u.to_vec(), f_vgt, "operating points"));
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
    let m = maps::egr_maps(p, sem);
    let mut f = MapFigure::new(2);
    f.panel_size = (700, 520);
    f.title = Some("EGR valve flow functions (paper Fig. 3)".into());
    let mut a = MapPanel::new(
        "(a) flow function Psi_egr, eqs (34)-(35)",
        "p_im / p_em [-]",
        "Psi_egr [-]",
    );
    a.curves.push(curve(
        &m.psi_egr,
        "model (choked below Pi_egr,opt, no flow above 1)",
        0,
    ));
    let mut b = MapPanel::new(
        "(b) effective area f_egr, eq. (38)",
        "u_egr [%]",
        "f_egr [-]",
    );
    b.curves.push(curve(&m.f_egr, "model", 0));
    if let Some(ov) = ov {
        // only rows with EGR flow
        let flowing: Vec<usize> = (0..ov.col("W_egr").len())
            .filter(|&i| ov.col("W_egr")[i] > 1e-6)
            .collect();
        let pi: Vec<f64> = flowing.iter().map(|&i| ov.col("Pi_egr")[i]).collect();
        let u: Vec<f64> = flowing.iter().map(|&i| ov.col("u_egr_actual")[i]).collect();
        let (psi, f_egr) = maps::egr_points(p, sem, &pi, &u);
        a.points.push(overlay_points(
            ov,
            pi,
            psi,
            "operating points with EGR flow",
        ));
        b.points.push(overlay_points(
            ov,
            u,
            f_egr,
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
