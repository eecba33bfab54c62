//! The frequency response with exact delays (`analysis::frequency`): against the nonlinear
//! model driven by small sinusoids (amplitude and phase of the settled output fitted by least
//! squares), against the DC gain at f = 0, and against Padé models (close while w tau is
//! small, apart beyond).

use mvem::analysis::frequency::{
    frequency_response, frequency_response_rational, log_grid, FrequencyResponse,
};
use mvem::analysis::linearize::{linearize, LinearizeOptions};
use mvem::analysis::steady::steady_state;
use mvem::analysis::zeros::dc_gain_matrix;
use mvem::model::{Drive, Engine8};
use mvem::sim::{simulate, InputSchedule, SimOptions, Start};
use nalgebra::{Complex, DMatrix, DVector};
use std::f64::consts::PI;

/// The operating point of the paper's VGT steps (1500 rpm, 110 mg, u_egr 80 %, u_vgt 75 %).
fn point() -> Drive {
    Drive::new(1500.0, 110.0, 80.0, 75.0)
}

/// A point with the EGR valve in its linear range (at u_egr 80 % the valve area saturates at
/// 80.1 %: a sinusoid there crosses the saturation).
fn egr_point() -> Drive {
    Drive::new(1500.0, 110.0, 50.0, 60.0)
}

fn response(f_hz: &[f64]) -> FrequencyResponse {
    response_at(&point(), f_hz)
}

fn response_at(d: &Drive, f_hz: &[f64]) -> FrequencyResponse {
    let m = Engine8::published();
    let ss = steady_state(&m, d).unwrap();
    frequency_response(&m, &ss.x, &ss.drive, &LinearizeOptions::default(), f_hz).unwrap()
}

/// The settled response of `output` to `input` = u0 + amp sin(2 pi f t) of the nonlinear model
/// (from the steady state, 12 periods to settle, the last 8 fitted with a constant, a trend, sin
/// and cos): the complex gain (output per input unit).
fn measured_gain(d: Drive, input: &str, output: &str, f: f64, amp: f64) -> Complex<f64> {
    let m = Engine8::published();
    let ss = steady_state(&m, &d).unwrap();
    let col = match input {
        "u_egr" => 2,
        "u_vgt" => 3,
        "u_delta" => 1,
        _ => unreachable!(),
    };
    let period = 1.0 / f;
    let t_end = 20.0 * period + 2.0;
    let rows_per_period = 400;
    let n_rows = (t_end * f * rows_per_period as f64).ceil() as usize + 1;
    let base = d.to_array();
    let mut times = Vec::with_capacity(n_rows);
    let mut rows = Vec::with_capacity(n_rows);
    for k in 0..n_rows {
        let t = k as f64 * period / rows_per_period as f64;
        let mut r = base;
        r[col] += amp * (2.0 * PI * f * t).sin();
        times.push(t);
        rows.push(r);
    }
    let sched = InputSchedule::new(times, rows).unwrap();
    let opts = SimOptions {
        rtol: 1e-9,
        atol: 1e-9,
        dt_out: period / 50.0,
        ..SimOptions::default()
    };
    let t_last = sched.t_last();
    let sol = simulate(&m, &sched, 0.0, t_last, Start::State(ss.x), &opts).unwrap();
    let (t, y) = (sol.t(), sol.get(output).unwrap());
    let t_fit = t_last - 8.0 * period;
    let idx: Vec<usize> = (0..t.len()).filter(|&k| t[k] >= t_fit).collect();
    let a = DMatrix::from_fn(idx.len(), 4, |r, c| {
        let tk = t[idx[r]];
        match c {
            0 => 1.0,
            1 => tk - t_fit,
            2 => (2.0 * PI * f * tk).sin(),
            _ => (2.0 * PI * f * tk).cos(),
        }
    });
    let b = DVector::from_iterator(idx.len(), idx.iter().map(|&k| y[k]));
    let x = a.clone().svd(true, true).solve(&b, 1e-14).unwrap();
    // y = s sin(w t) + c cos(w t) = Im((s + j c) e^(j w t)); the input amp sin(w t) = Im(amp e^(j w t))
    Complex::new(x[2], x[3]) / amp
}

#[test]
fn sinusoids_through_the_nonlinear_model_meet_the_frequency_response() {
    // u_vgt -> W_c (non-minimum phase, delay 0.04 s) and u_egr -> p_im (delay 0.065 s), below
    // and above the delays' corner (1 / (2 pi tau) = 2.4-4 Hz), and the fuel path
    for (d, input, output, f, amp) in [
        (point(), "u_vgt", "W_c", 0.2, 0.2),
        (point(), "u_vgt", "W_c", 3.0, 0.2),
        (egr_point(), "u_egr", "p_im", 0.5, 0.2),
        (egr_point(), "u_egr", "x_egr", 5.0, 0.2),
        (point(), "u_delta", "p_em", 1.0, 0.2),
    ] {
        let want = response_at(&d, &[f]).channel(input, output).unwrap()[0];
        let got = measured_gain(d, input, output, f, amp);
        let (dm, dp) = (
            got.norm() / want.norm() - 1.0,
            (got / want).arg().to_degrees(),
        );
        eprintln!(
            "{input} -> {output} at {f} Hz: |G| {:.5e} (simulated {:.5e}, {:+.3} %), phase {:.2} deg (simulated {:+.3} deg off)",
            want.norm(),
            got.norm(),
            100.0 * dm,
            want.arg().to_degrees(),
            dp
        );
        // measured: within 0.003 % and 0.001 deg (the 0.2 % sinusoid leaves a small nonlinear
        // part; the fit's trend term takes the slow drift)
        assert!(
            dm.abs() < 1e-3,
            "{input} -> {output} at {f} Hz: magnitude off by {dm}"
        );
        assert!(
            dp.abs() < 0.1,
            "{input} -> {output} at {f} Hz: phase off by {dp} deg"
        );
    }
}

/// The phase does not depend on the caller's grid: three frequencies a decade apart (where a
/// 0.065 s delay turns the phase by 230 deg between 1 and 10 Hz) get the phases of a fine grid.
#[test]
fn the_phase_is_continuous_whatever_the_grid() {
    let fine_f = log_grid(0.1, 10.0, 401).unwrap();
    let fine = response_at(&egr_point(), &fine_f);
    let coarse = response_at(&egr_point(), &[0.1, 1.0, 10.0]);
    for (i, o) in [
        ("u_egr", "p_im"),
        ("u_vgt", "W_c"),
        ("u_egr", "x_egr"),
        ("u_delta", "M_e"),
    ] {
        let (_, pf) = fine.magnitude_phase(i, o).unwrap();
        let (_, pc) = coarse.magnitude_phase(i, o).unwrap();
        for (k, j) in [(0, 0), (1, 200), (2, 400)] {
            assert!(
                (pc[k] - pf[j]).abs() < 1e-9,
                "{i} -> {o} at {} Hz: {} vs {}",
                fine_f[j],
                pc[k],
                pf[j]
            );
        }
        // and the fine grid's own steps are small (no jump left)
        assert!(
            pf.windows(2).all(|w| (w[1] - w[0]).abs() < 30.0),
            "{i} -> {o}"
        );
    }
    // the delay alone: u_egr -> x_egr loses at least 360 * 10 Hz * 0.065 s = 234 deg more
    // between 0.1 and 10 Hz than the undelayed system would
    let (_, p) = coarse.magnitude_phase("u_egr", "x_egr").unwrap();
    assert!(p[2] < -200.0, "{p:?}");
}

#[test]
fn at_zero_frequency_the_response_is_the_dc_gain() {
    let m = Engine8::published();
    let ss = steady_state(&m, &point()).unwrap();
    let opts = LinearizeOptions::default();
    let lin = linearize(&m, &ss.x, &ss.drive, &opts).unwrap();
    let dc = dc_gain_matrix(&lin).unwrap();
    let r = frequency_response(&m, &ss.x, &ss.drive, &opts, &[0.0]).unwrap();
    for o in 0..dc.nrows() {
        for i in 0..dc.ncols() {
            let g = r.g[0][(o, i)];
            let tol = 1e-9 * dc[(o, i)].abs().max(1e-12);
            assert!(
                (g.re - dc[(o, i)]).abs() <= tol && g.im.abs() <= tol,
                "{} -> {}: {g} vs {}",
                r.input_names[i],
                r.output_names[o],
                dc[(o, i)]
            );
        }
    }
}

#[test]
fn pade_models_agree_while_the_delay_is_short_against_the_period() {
    let m = Engine8::published();
    let ss = steady_state(&m, &point()).unwrap();
    let f = log_grid(0.01, 50.0, 60).unwrap();
    let exact = response(&f);
    let lin3 = linearize(
        &m,
        &ss.x,
        &ss.drive,
        &LinearizeOptions {
            pade_order: 3,
            ..LinearizeOptions::default()
        },
    )
    .unwrap();
    let pade = frequency_response_rational(&lin3, &f).unwrap();
    let undelayed = frequency_response_rational(
        &linearize(&m, &ss.x, &ss.drive, &LinearizeOptions::default()).unwrap(),
        &f,
    )
    .unwrap();
    let tau = exact.delays[1]; // u_vgt
    assert!(tau > 0.0);
    let e = exact.channel("u_vgt", "W_c").unwrap();
    let p = pade.channel("u_vgt", "W_c").unwrap();
    let u = undelayed.channel("u_vgt", "W_c").unwrap();
    for k in 0..f.len() {
        let wt = 2.0 * PI * f[k] * tau;
        let rel = (p[k] - e[k]).norm() / e[k].norm();
        // the undelayed system differs from the exact one by the factor e^(-j w tau) only
        let shifted = u[k] * Complex::from_polar(1.0, -2.0 * PI * f[k] * tau);
        assert!(
            (shifted - e[k]).norm() <= 1e-9 * e[k].norm(),
            "{} Hz: {shifted} vs {}",
            f[k],
            e[k]
        );
        if wt < 1.0 {
            // Padé (3, 3) of e^(-s tau): error about (w tau)^7 / 4.3e6
            assert!(
                rel < 1e-5,
                "{} Hz (w tau {wt:.3}): Padé 3 off by {rel}",
                f[k]
            );
        }
        // magnitudes equal at every frequency (the Padé approximant is all-pass)
        assert!(
            (p[k].norm() / e[k].norm() - 1.0).abs() < 1e-6,
            "{} Hz",
            f[k]
        );
    }
    // at w tau = 8 (31.8 Hz for 0.04 s) the phases differ (third order: at most 6 pi of lag)
    let k = f.iter().position(|&x| 2.0 * PI * x * tau > 8.0).unwrap();
    assert!((p[k] - e[k]).norm() / e[k].norm() > 0.1);
}

/// A command at a limit of its range (u_vgt 20 %, u_egr 0 %; `linearize` differences its column
/// on the inner side, `one_sided`) or within the difference stencil of it (20.001 %, 0.001 %)
/// goes wholly through its delay: nothing of it is undelayed, and the response is that of the
/// linearization with the exact delay, `C (jwI - A)^-1 b e^(-jw tau)` (in the 8-state model
/// the current commands drive nothing but the delayed copies). Before (QA), the delayed copy's
/// column was a central difference across the limit, half the inner slope; the other half was
/// left undelayed, and u_vgt -> W_c at 1200 rpm, 150 mg, u_egr 50 %, u_vgt 20 % was 21 % off
/// at 50 Hz (the sampled model of `--ts` and the loop margins are built from the same split).
#[test]
fn a_command_at_its_limit_goes_wholly_through_its_delay() {
    use mvem::analysis::discrete::delay_split;
    let m = Engine8::published();
    let f = [0.01, 0.5, 2.0, 10.0, 50.0];
    for (d, input, tau) in [
        (Drive::new(1200.0, 150.0, 50.0, 20.0), "u_vgt", 0.04),
        (Drive::new(1200.0, 150.0, 50.0, 20.001), "u_vgt", 0.04),
        (Drive::new(1200.0, 150.0, 50.0, 99.999), "u_vgt", 0.04),
        (Drive::new(1500.0, 150.0, 0.0, 40.0), "u_egr", 0.065),
        (Drive::new(1500.0, 150.0, 0.001, 40.0), "u_egr", 0.065),
    ] {
        let ss = steady_state(&m, &d).unwrap();
        let lin = linearize(&m, &ss.x, &ss.drive, &LinearizeOptions::default()).unwrap();
        let split = delay_split(&m, &ss.x, &ss.drive, &lin).unwrap();
        let k = lin.input_index(input).unwrap();
        let rest = split.b_now.column(k).amax();
        assert!(rest == 0.0, "{input} at {d:?}: undelayed part {rest}");
        let r = response_at(&d, &f);
        let n = lin.a.nrows();
        for out in ["p_im", "W_c", "x_egr", "lambda_O"] {
            let o = lin.output_index(out).unwrap();
            let want: Vec<Complex<f64>> = f
                .iter()
                .map(|&fk| {
                    let s = Complex::new(0.0, 2.0 * PI * fk);
                    let a = DMatrix::from_fn(n, n, |i, j| {
                        let eye = if i == j { s } else { Complex::new(0.0, 0.0) };
                        eye - Complex::new(lin.a[(i, j)], 0.0)
                    });
                    let b = DVector::from_fn(n, |i, _| Complex::new(lin.b[(i, k)], 0.0));
                    let x = a.lu().solve(&b).unwrap();
                    let y: Complex<f64> = (0..n).map(|i| x[i] * lin.c[(o, i)]).sum();
                    (y + lin.d[(o, k)]) * (-s * tau).exp()
                })
                .collect();
            let got = r.channel(input, out).unwrap();
            let scale = want.iter().map(|g| g.norm()).fold(0.0, f64::max);
            if scale == 0.0 {
                // (a channel without gain: u_vgt -> x_egr with the VGT wide open)
                assert!(
                    got.iter().all(|g| g.norm() == 0.0),
                    "{input}->{out}: {got:?}"
                );
                continue;
            }
            for (i, (x, y)) in got.iter().zip(&want).enumerate() {
                let e = (x - y).norm() / scale;
                assert!(
                    e < 1e-6,
                    "{input}->{out} at {d:?}, {} Hz: {x} vs {y} ({e:.2e})",
                    f[i]
                );
            }
        }
    }
}
