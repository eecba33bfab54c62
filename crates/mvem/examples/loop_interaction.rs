//! Steady-state interaction of the two main air-path loops (docs/control.md, "Session 38"):
//! at operating points `n_e,u_delta,u_egr,u_vgt` given as arguments, the DC gain matrix
//! G(0) = D - C A^-1 B of (lambda_O, x_egr) over (u_egr, u_vgt) of the linearization at the
//! steady state, and the relative gain array's diagonal element
//! lambda_11 = g_le g_xv / (g_le g_xv - g_lv g_xe) of the pairing lambda_O -> u_egr,
//! x_egr -> u_vgt (negative: integral action on this pairing is unstable with the other loop
//! closed, whatever the gains).
//!
//! `cargo run --profile ci -p mvem --example loop_interaction -- 1040,120,2.1,24.0`

use mvem::analysis::linearize::{linearize, LinearizeOptions};
use mvem::analysis::steady::steady_state;
use mvem::analysis::zeros::dc_gain_matrix;
use mvem::model::{Drive, Engine8};

fn main() {
    let m = Engine8::published();
    for a in std::env::args().skip(1) {
        let v: Vec<f64> = a.split(',').map(|s| s.parse().expect("number")).collect();
        assert_eq!(v.len(), 4, "n_e,u_delta,u_egr,u_vgt");
        let d = Drive::new(v[0], v[1], v[2], v[3]);
        let ss = match steady_state(&m, &d) {
            Ok(s) => s,
            Err(e) => {
                println!("{a}: {e}");
                continue;
            }
        };
        let opts = LinearizeOptions {
            outputs: vec!["lambda_O".into(), "x_egr".into()],
            strict: false,
            ..LinearizeOptions::default()
        };
        let lin = linearize(&m, &ss.x, &d, &opts).expect("linearize");
        let g = dc_gain_matrix(&lin).expect("dc gain");
        let col = |name: &str| lin.input_names.iter().position(|n| n == name).unwrap();
        let (e, vg) = (col("u_egr"), col("u_vgt"));
        let (g_le, g_lv, g_xe, g_xv) = (g[(0, e)], g[(0, vg)], g[(1, e)], g[(1, vg)]);
        let det = g_le * g_xv - g_lv * g_xe;
        println!(
            "{a}: lambda_O {:.3} x_egr {:.4} | g_le {g_le:.4e} g_lv {g_lv:.4e} g_xe {g_xe:.4e} g_xv {g_xv:.4e} | rga11 {:.3} | h_le (x loop closed) {:.4e}",
            ss.signals.lambda_o,
            ss.signals.x_egr,
            g_le * g_xv / det,
            det / g_xv
        );
    }
}
