//! A data set's settled hold ends against the model's equilibria (docs/tuning.md, session 15):
//! per command hold of set SET of the campaign, the mean of the measured n_t, p_im, W_c over
//! the hold's last two samples; then, per parameter file, the equilibrium at the hold's commands
//! (n_t, p_im, W_c, Pi_c, eta_c, or why there is none) and the compressor flow map (eqs
//! (66)-(72)) at the measured Pi_c and n_t with its error against the measured W_c.
//!
//! `cargo run --release -p mvem --example eq_scan -- CAMPAIGN SET PARAMS.toml [PARAMS2.toml ...]`
use mvem::analysis::steady::steady_state;
use mvem::model::{Drive, Engine8, Model, ModelOptions};
use mvem::tuning::complete::segments;
use mvem::tuning::data::load_campaign;
use mvem::tuning::steps::{w_c_flow_series, FlowPoint};
use std::path::Path;

fn main() {
    let a: Vec<String> = std::env::args().collect();
    if a.len() < 4 {
        eprintln!("usage: eq_scan CAMPAIGN SET PARAMS.toml [PARAMS2.toml ...]");
        std::process::exit(2);
    }
    let c = load_campaign(Path::new(&a[1])).expect("campaign");
    let (_, d) = c.dataset(&a[2]).expect("data set");
    let ms: Vec<Engine8> = a[3..]
        .iter()
        .map(|f| {
            Engine8::new(
                mvem::io::params::load_params(Path::new(f)).expect("parameter file"),
                ModelOptions::default(),
            )
            .expect("valid parameters")
        })
        .collect();
    let col = |n: &str| d.get(n).expect("column");
    for (s, e) in segments(d) {
        let k = e - 1;
        let drive = Drive::new(
            col("n_e")[k],
            col("u_delta")[k],
            col("u_egr")[k],
            col("u_vgt")[k],
        );
        let m0 = (e - 2).max(s);
        let mean = |n: &str| col(n)[m0..e].iter().sum::<f64>() / (e - m0) as f64;
        let mut line = format!(
            "t {:6.1} meas n_t {:6.0} p_im {:6.0} W_c {:.4}",
            d.t[k],
            mean("n_t"),
            mean("p_im"),
            mean("W_c")
        );
        for m in &ms {
            // the flow map at the measured Pi_c and n_t (step 1's model of W_c)
            let p = m.params();
            let hold_end = FlowPoint {
                p_c: mean("p_im"),
                p_amb: p.ambient.p_amb,
                t_amb: p.ambient.t_amb,
                n_t: mean("n_t"),
                w_c: mean("W_c"),
            };
            let w_c = w_c_flow_series(p, &[hold_end]).1[0];
            line += &format!(
                " [W_c map {w_c:.4} {:+.1}%]",
                100.0 * (w_c / hold_end.w_c - 1.0)
            );
            match steady_state(m, &drive) {
                Ok(ss) => {
                    line += &format!(
                        " | n_t {:6.0} p_im {:6.0} W_c {:.4} Pi_c {:.3} eta_c {:.3}",
                        ss.signals.get("n_t").unwrap(),
                        ss.x[0],
                        ss.signals.get("W_c").unwrap(),
                        ss.signals.get("Pi_c").unwrap(),
                        ss.signals.get("eta_c").unwrap()
                    )
                }
                Err(err) => line += &format!(" | fail {err}"),
            }
        }
        println!("{line}");
    }
}
