//! `mvem linearize`: the linear model (A, B, C, D) at the steady state of an operating point,
//! its poles, the transmission zeros of every SISO channel and of the square MIMO system, and
//! the DC-gain matrix.

use crate::common::{self, ModelArgs, PointArgs};
use anyhow::{Context, Result};
use mvem::analysis::discrete::{check_ts, discretize_linear, TS_MAX, TS_MIN};
use mvem::analysis::linearize::{linearize_steady, LinearModel, LinearizeOptions};
use mvem::analysis::steady::{steady_state, SteadyState};
use mvem::model::Model;
use serde_json::Value;

/// Arguments of `mvem linearize`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  mvem linearize --n-e 1500 --u-delta 110 --u-egr 80 --u-vgt 75
  mvem linearize --n-e 1500 --u-delta 110 --u-egr 80 --u-vgt 75 --json > lin.json
  mvem linearize --n-e 1200 --u-delta 200 --u-egr 50 --u-vgt 40 --pade 2
  mvem linearize --n-e 1500 --u-delta 110 --u-egr 80 --u-vgt 30 --outputs W_c,p_im,T_em
  mvem linearize --n-e 1500 --u-delta 130 --u-egr 80 --u-vgt 75 --state x.json --json
  mvem linearize --n-e 1500 --u-delta 110 --u-egr 40 --u-vgt 75 --ts 0.01 --json > mpc.json
  mvem linearize --n-e 1500 --u-delta 110 --u-egr 50 --u-vgt 60 --bode 0.01:100:300 --plot bode.png --bode-out bode.csv

The linear model is dx' = A dx + B du, dy = C dx + D du in deviations from the steady state,
in SI units (states Pa, -, rad/s, %), inputs (u_delta, u_egr, u_vgt, n_e) in mg/cycle, %, %,
rpm, outputs in their signal units. Derivatives: Richardson-extrapolated central differences.
Without --pade the actuator delays are left out (the undelayed system); --pade K replaces them
by order-K Pade approximants (extra states; their all-pass zeros then appear in the zeros).
--state x.json linearizes at that state (every state name -> value) with the inputs held,
e.g. a point of a transient: not an equilibrium, so the JSON's \"dx0\" (the derivatives there) is
not zero and the poles and zeros are those of the frozen linear model.
--ts S also samples the model with a zero-order hold at S seconds (1e-3 to 100), the actuator
delays exact (dx(k+1) = Phi dx(k) + Gamma du(k), dy(k) = C dx(k) + D du(k); the past commands
u_egr(k-1), ... are extra states): for MPC and discrete observers. Not with --pade.
--bode FMIN:FMAX:N also the frequency response G(jw) = C (jwI - A)^-1 B + D of every channel
with the delays exact (the delayed commands' columns times e^(-jw tau); no Pade approximation),
at N log-spaced frequencies; the phase continuous from its value in (-180, 180] at FMIN (followed
on an internal grid fine enough for the delays, whatever N). --bode-out writes it (CSV or Parquet), --plot
draws the --channels, and the text output tabulates them; --json adds \"frequency_response\".
Not with --pade (the printed model would not be the one of the response).

With --json, stdout holds one JSON object with the keys \"eigenvalues\" [{re, im}], \"zeros\"
(object keyed \"u_vgt->W_c\", ..., one entry per SISO channel plus \"MIMO\" for
(u_delta, u_egr, u_vgt) -> (M_e, x_egr, lambda_O); each a list of {re, im}, null where the
channel passes a kink of the model, with the reason in \"zero_errors\"), \"dc_gain\" (outputs x
inputs), \"A\", \"B\", \"C\", \"D\" (lists of rows), \"state_names\", \"input_names\",
\"output_names\", \"units\", \"operating_point\", \"x0\", \"y0\", \"physically_valid\", \"flags\",
\"kinks\", \"pade_order\", \"delays_s\", \"dx0\", \"steady_state\"; with --ts also \"discrete\": {\"ts\",
\"Phi\", \"Gamma\", \"C\", \"D\", \"state_names\", \"state_units\", \"input_names\", \"output_names\",
\"delays_s\", \"delay_samples\" {u_egr, u_vgt: {whole, remainder_s}}, \"poles\" (eigenvalues of Phi)};
with --bode also \"frequency_response\": {\"f_hz\", \"delays_s\", \"channels\": {\"u_vgt->W_c\": {\"mag\",
\"phase_deg\", \"re\", \"im\"}, ...}}.")]
pub struct Args {
    #[command(flatten)]
    pub point: PointArgs,
    /// Print one JSON object on stdout instead of tables.
    #[arg(long)]
    pub json: bool,
    /// Replace the actuator delays by Pade approximants of this order (1-3; 2 if given without a value).
    #[arg(long, value_name = "K", num_args = 0..=1, default_missing_value = "2", default_value = "0",
          value_parser = clap::value_parser!(u8).range(0..=3))]
    pub pade: u8,
    /// Outputs (comma separated state or signal names) [default: p_im,p_em,W_c,n_t,x_egr,lambda_O,M_e]
    #[arg(long, value_name = "LIST", value_delimiter = ',')]
    pub outputs: Vec<String>,
    /// Linearize at this state instead of the steady state: a JSON object of every state name
    /// -> value (as `simulate --initial-state`), the inputs held at the operating point's.
    #[arg(long, value_name = "FILE.json")]
    pub state: Option<std::path::PathBuf>,
    /// Also the model sampled with a zero-order hold at this sample time [s] (1e-3 to 100), the
    /// actuator delays exact: Phi, Gamma, C, D with the past commands as extra states.
    #[arg(long, value_name = "S")]
    pub ts: Option<f64>,
    /// Frequency response (Bode) of every channel with the actuator delays exact: N frequencies
    /// from FMIN to FMAX [Hz], evenly spaced in log scale (e.g. 0.01:100:200). Not with --pade.
    #[arg(long, value_name = "FMIN:FMAX:N")]
    pub bode: Option<String>,
    /// Write the frequency response to this CSV (or .parquet) file: f_hz, then per channel
    /// `<input>-><output> mag` (output unit per input unit) and `<input>-><output> phase_deg`.
    #[arg(long, value_name = "FILE", requires = "bode")]
    pub bode_out: Option<std::path::PathBuf>,
    /// Bode plot (.png or .svg) of the --channels: magnitude [dB] and phase [deg] over log f.
    #[arg(long, value_name = "FILE.png|svg", requires = "bode")]
    pub plot: Option<std::path::PathBuf>,
    /// Channels (`input->output`, comma separated) of the Bode plot and the printed table
    /// [default: u_vgt->W_c, u_egr->p_im, u_vgt->p_im, u_egr->x_egr, those among the outputs].
    #[arg(long, value_name = "LIST", value_delimiter = ',', requires = "bode")]
    pub channels: Vec<String>,
    #[command(flatten)]
    pub model: ModelArgs,
}

/// Run `mvem linearize`.
pub fn run(a: &Args) -> Result<()> {
    let d = a.point.drive(a.model.input_ranges()?.as_ref())?;
    let opts = options(&a.outputs, a.pade as usize)?;
    if let Some(ts) = a.ts {
        if a.pade > 0 {
            return Err(common::usage(
                "--ts with --pade: the sampled model has the delays exact; leave out --pade",
            ));
        }
        if check_ts(ts).is_err() {
            return Err(common::usage(format!(
                "--ts {}: must lie in [{TS_MIN}, {TS_MAX}] s",
                mvem::numerics::Num(ts)
            )));
        }
    }
    let bode = match &a.bode {
        None => None,
        Some(spec) => {
            if a.pade > 0 {
                return Err(common::usage(
                    "--bode with --pade: the frequency response has the delays exact; leave out --pade",
                ));
            }
            Some(bode_grid(spec)?)
        }
    };
    for (p, what) in [(&a.bode_out, "--bode-out"), (&a.plot, "--plot")] {
        if let Some(p) = p {
            common::check_output_path(p, what)?;
        }
    }
    let plot_format = a.plot.as_deref().map(crate::plot::Format::of).transpose()?;
    let model = a.model.build()?;
    let state = match &a.state {
        Some(p) => Some((super::simulate::read_initial_state(p)?, p.as_path())),
        None => None,
    };
    let v = mvem::dispatch!(&model, m => {
        let (x, (lin, mut v)) = match &state {
            None => {
                let ss = steady_state(m, &d).context("steady state")?;
                (ss.x, analyse(m, &ss, &opts)?)
            }
            Some((values, path)) => {
                let x = super::simulate::state_from_map(
                    m,
                    values,
                    path,
                    mvem::model::EVALUATED_AT,
                )?;
                (x, analyse_at(m, &x, &d, &opts)?)
            }
        };
        if let Some(ts) = a.ts {
            let dm = discretize_linear(m, &x, &d, &lin, ts).map_err(|e| match e {
                e @ mvem::analysis::linearize::LinearizeError::BadOption { .. } => {
                    common::usage(format!("--ts: {e}"))
                }
                other => anyhow::Error::new(other).context("sampled model"),
            })?;
            v["discrete"] = mvem::analysis::json::discrete_model_json(&dm);
        }
        let fr = match &bode {
            None => None,
            Some(f) => Some(
                mvem::analysis::frequency::frequency_response_linear(m, &x, &d, &lin, f)
                    .context("frequency response")?,
            ),
        };
        (v, fr)
    });
    let (mut v, fr) = v;
    let channels = match &fr {
        Some(fr) => bode_channels(fr, &a.channels)?,
        None => Vec::new(),
    };
    if let Some(fr) = &fr {
        // everything rendered before anything is written (a failure leaves no file behind)
        let figure = match (&a.plot, plot_format) {
            (Some(_), Some(fmt)) => Some(crate::plot::render(&bode_figure(fr, &channels), fmt)?),
            _ => None,
        };
        if let Some(path) = &a.bode_out {
            write_bode(fr, path)?;
        }
        if let (Some(path), Some(bytes)) = (&a.plot, figure) {
            mvem::io::output::write_atomic(path, &bytes)
                .with_context(|| format!("cannot write {}", path.display()))?;
        }
        if a.json {
            v["frequency_response"] = mvem::analysis::json::frequency_response_json(fr);
        }
    }
    if let Some(w) = v.get("physically_valid").and_then(Value::as_bool) {
        if !w {
            // (--state: the given state, which is no equilibrium in general)
            let what = if v["steady_state"].as_bool() == Some(false) {
                "the given state"
            } else {
                "the equilibrium"
            };
            eprintln!(
                "warning: {what} is not physically valid; flags: {}",
                v["flags"]
                    .as_array()
                    .map(|f| f
                        .iter()
                        .filter_map(Value::as_str)
                        .collect::<Vec<_>>()
                        .join(", "))
                    .unwrap_or_default()
            );
        }
    }
    for k in v["kinks"].as_array().into_iter().flatten() {
        eprintln!(
            "warning: {}; the slopes on the two sides differ there, and the central difference is their average: channels through it have no zeros (see zero_errors), and their DC gains are those of the averaged slopes",
            k.as_str().unwrap_or_default()
        );
    }
    for k in v["one_sided"].as_array().into_iter().flatten() {
        eprintln!("note: {}", k.as_str().unwrap_or_default());
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        print_text(&v);
        if let Some(fr) = &fr {
            print_bode(fr, &channels);
        }
    }
    for (what, p) in [("frequency response", &a.bode_out), ("Bode plot", &a.plot)] {
        if let Some(p) = p {
            eprintln!("Wrote the {what} to {}", p.display());
        }
    }
    Ok(())
}

/// The frequencies of `--bode FMIN:FMAX:N`.
fn bode_grid(spec: &str) -> Result<Vec<f64>> {
    use mvem::analysis::frequency::{parse_grid, MAX_POINTS};
    parse_grid(spec, MAX_POINTS).map_err(|e| common::usage(format!("--bode {spec}: {e}")))
}

/// The channels of the plot and the table: `--channels`, each checked against the response's
/// inputs and outputs, or the default ones among its outputs.
fn bode_channels(
    fr: &mvem::analysis::frequency::FrequencyResponse,
    given: &[String],
) -> Result<Vec<(String, String)>> {
    let split = |c: &str| -> Option<(String, String)> {
        let (i, o) = c.split_once("->")?;
        Some((i.trim().to_string(), o.trim().to_string()))
    };
    if given.is_empty() {
        let mut out: Vec<(String, String)> =
            ["u_vgt->W_c", "u_egr->p_im", "u_vgt->p_im", "u_egr->x_egr"]
                .iter()
                .filter_map(|c| split(c))
                .filter(|(_, o)| fr.output_names.contains(o))
                .collect();
        if out.is_empty() {
            out = fr
                .output_names
                .iter()
                .take(4)
                .map(|o| ("u_vgt".to_string(), o.clone()))
                .collect();
        }
        return Ok(out);
    }
    given
        .iter()
        .map(|c| {
            let (i, o) = split(c).ok_or_else(|| {
                common::usage(format!(
                    "--channels: '{c}' is not input->output (e.g. u_vgt->W_c)"
                ))
            })?;
            if !fr.input_names.contains(&i) {
                return Err(common::usage(format!(
                    "--channels {c}: no input {i} (inputs: {})",
                    fr.input_names.join(", ")
                )));
            }
            if !fr.output_names.contains(&o) {
                return Err(common::usage(format!(
                    "--channels {c}: no output {o} (outputs: {}; add it with --outputs)",
                    fr.output_names.join(", ")
                )));
            }
            Ok((i, o))
        })
        .collect()
}

/// Write every channel's magnitude and phase (CSV or Parquet by the extension).
fn write_bode(
    fr: &mvem::analysis::frequency::FrequencyResponse,
    path: &std::path::Path,
) -> Result<()> {
    let mut names: Vec<String> = vec!["f_hz".into()];
    let mut cols: Vec<Vec<f64>> = vec![fr.f_hz.clone()];
    for i in &fr.input_names {
        for o in &fr.output_names {
            if let Some((mag, phase)) = fr.magnitude_phase(i, o) {
                names.push(format!("{i}->{o} mag"));
                cols.push(mag);
                names.push(format!("{i}->{o} phase_deg"));
                cols.push(phase);
            }
        }
    }
    let table: Vec<(&str, &[f64])> = names
        .iter()
        .map(String::as_str)
        .zip(cols.iter().map(Vec::as_slice))
        .collect();
    mvem::io::output::write_columns(&table, path)
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Magnitude [dB re 1 output unit per input unit] and phase panels of each channel, over log f.
fn bode_figure(
    fr: &mvem::analysis::frequency::FrequencyResponse,
    channels: &[(String, String)],
) -> crate::plot::Figure {
    use crate::plot::{Figure, Panel, Series};
    let lf: Vec<f64> = fr.f_hz.iter().map(|f| f.max(1e-300).log10()).collect();
    let mut fig = Figure::new(2);
    fig.title = Some(format!(
        "frequency response, delays exact (u_egr {} s, u_vgt {} s)",
        mvem::numerics::Num(fr.delays[0]),
        mvem::numerics::Num(fr.delays[1])
    ));
    for (k, (i, o)) in channels.iter().enumerate() {
        let Some((mag, phase)) = fr.magnitude_phase(i, o) else {
            continue;
        };
        let db: Vec<f64> = mag.iter().map(|m| 20.0 * m.max(1e-300).log10()).collect();
        let unit = format!("{} per {}", common::unit(o), common::unit(i));
        fig.panels.push(
            Panel::new("f [Hz]", format!("|G| [dB re 1 {unit}]"))
                .title(format!("{i} -> {o}: magnitude"))
                .with(Series::line("", &lf, &db, k))
                .log_x(),
        );
        fig.panels.push(
            Panel::new("f [Hz]", "phase [deg]")
                .title(format!("{i} -> {o}: phase"))
                .with(Series::line("", &lf, &phase, k))
                .log_x(),
        );
    }
    fig
}

/// A table per channel at up to nine frequencies of the grid (evenly spaced in log f).
fn print_bode(fr: &mvem::analysis::frequency::FrequencyResponse, channels: &[(String, String)]) {
    println!(
        "\nFrequency response ({} points, {} to {} Hz; delays exact: u_egr {} s, u_vgt {} s)",
        fr.f_hz.len(),
        mvem::numerics::Num(fr.f_hz[0]),
        mvem::numerics::Num(*fr.f_hz.last().unwrap_or(&f64::NAN)),
        mvem::numerics::Num(fr.delays[0]),
        mvem::numerics::Num(fr.delays[1])
    );
    let n = fr.f_hz.len();
    let rows: Vec<usize> = if n <= 9 {
        (0..n).collect()
    } else {
        let mut r: Vec<usize> = (0..9).map(|k| k * (n - 1) / 8).collect();
        r.dedup();
        r
    };
    for (i, o) in channels {
        let Some((mag, phase)) = fr.magnitude_phase(i, o) else {
            continue;
        };
        println!(
            "\n  {i} -> {o}   |G| [{} per {}], phase [deg]",
            common::unit(o),
            common::unit(i)
        );
        for &k in &rows {
            println!(
                "    {:>10.4} Hz  {:>12.4e}  {:>9.2}",
                fr.f_hz[k], mag[k], phase[k]
            );
        }
    }
}

/// Linearization options from `--outputs` and `--pade` (non-strict: kinks are judged per
/// channel).
pub fn options(outputs: &[String], pade: usize) -> Result<LinearizeOptions> {
    let mut o = LinearizeOptions {
        pade_order: pade,
        strict: false,
        ..LinearizeOptions::default()
    };
    if !outputs.is_empty() {
        o.outputs = outputs.iter().map(|s| s.trim().to_string()).collect();
    }
    Ok(o)
}

/// The whole analysis of the steady state `ss` as the JSON object of the contract, with the
/// linear model it shows.
pub fn analyse<const N: usize, M: Model<N>>(
    m: &M,
    ss: &SteadyState<N>,
    opts: &LinearizeOptions,
) -> Result<(LinearModel, Value)> {
    let lin = linearize_steady(m, ss, opts).map_err(|e| match e {
        mvem::analysis::linearize::LinearizeError::UnknownOutput { .. } => {
            common::usage(format!("--outputs: {e}"))
        }
        other => anyhow::Error::new(other).context("linearization"),
    })?;
    let v = mvem::analysis::json::linear_model_json(&lin, ss);
    Ok((lin, v))
}

/// The analysis at the state `x` with the inputs `d` held (not an equilibrium in general: the
/// JSON's `"dx0"` is the derivatives there, `"steady_state"` false; poles and zeros are those
/// of the frozen linear model).
pub fn analyse_at<const N: usize, M: Model<N>>(
    m: &M,
    x: &[f64; N],
    d: &mvem::model::Drive,
    opts: &LinearizeOptions,
) -> Result<(LinearModel, Value)> {
    let lin = mvem::analysis::linearize::linearize(m, x, d, opts).map_err(|e| match e {
        mvem::analysis::linearize::LinearizeError::UnknownOutput { .. } => {
            common::usage(format!("--outputs: {e}"))
        }
        e @ mvem::analysis::linearize::LinearizeError::NonFinite { .. } => {
            common::usage(format!("--state: {e}"))
        }
        other => anyhow::Error::new(other).context("linearization"),
    })?;
    let u = mvem::model::ModelInput::constant(*d);
    let signals = m.eval(x, &u, m.memory_start(x, &u)).signals;
    let active: Vec<&mvem::model::Guard> = mvem::model::Guard::ALL
        .iter()
        .filter(|g| signals.has(**g))
        .collect();
    let flags: Vec<String> = active.iter().map(|g| g.label().to_string()).collect();
    let valid = !active.iter().any(|g| g.invalidates());
    let v = mvem::analysis::json::linear_model_json_at(&lin, d, valid, &flags);
    Ok((lin, v))
}

fn fmt_c(z: &Value) -> String {
    let re = z["re"].as_f64().unwrap_or(f64::NAN);
    let im = z["im"].as_f64().unwrap_or(f64::NAN);
    if im == 0.0 {
        format!("{re:.4}")
    } else {
        format!(
            "{re:.4} {} {:.4}i",
            if im < 0.0 { '-' } else { '+' },
            im.abs()
        )
    }
}

fn names(v: &Value) -> Vec<String> {
    v.as_array()
        .into_iter()
        .flatten()
        .filter_map(|s| s.as_str().map(str::to_string))
        .collect()
}

fn print_matrix(title: &str, m: &Value, row_names: &[String], col_names: &[String]) {
    println!("\n{title}");
    print!("  {:<12}", "");
    for c in col_names {
        print!(" {c:>12}");
    }
    println!();
    for (r, row) in row_names.iter().zip(m.as_array().into_iter().flatten()) {
        print!("  {r:<12}");
        for v in row.as_array().into_iter().flatten() {
            print!(" {:>12.4e}", v.as_f64().unwrap_or(f64::NAN));
        }
        println!();
    }
}

fn print_text(v: &Value) {
    let op = &v["operating_point"];
    println!(
        "Linearization at n_e = {} rpm, u_delta = {} mg/cycle, u_egr = {} %, u_vgt = {} % ({}{})",
        op["n_e_rpm"],
        op["u_delta_mg"],
        op["u_egr_pct"],
        op["u_vgt_pct"],
        if v["steady_state"].as_bool() == Some(false) {
            "the given state, not an equilibrium: dx0 below, poles and zeros frozen"
        } else {
            "steady state"
        },
        if v["physically_valid"].as_bool() == Some(true) {
            ""
        } else {
            ", NOT physically valid"
        }
    );
    if v["steady_state"].as_bool() == Some(false) {
        let states = names(&v["state_names"]);
        let dx0: Vec<String> = v["dx0"]
            .as_array()
            .into_iter()
            .flatten()
            .zip(&states)
            .map(|(d, s)| format!("d{s}/dt = {:.4e}", d.as_f64().unwrap_or(f64::NAN)))
            .collect();
        println!("dx0: {}", dx0.join(", "));
    }
    let pade = v["pade_order"].as_u64().unwrap_or(0);
    if pade == 0 {
        println!(
            "Actuator delays (u_egr {} s, u_vgt {} s) left out: the undelayed system; use --pade K to include them.",
            v["delays_s"]["u_egr"], v["delays_s"]["u_vgt"]
        );
    } else {
        // a channel with a zero delay has no Padé states (its delayed copy is the command)
        let zero: Vec<&str> = ["u_egr", "u_vgt"]
            .into_iter()
            .filter(|c| v["delays_s"][c].as_f64() == Some(0.0))
            .collect();
        let note = if zero.is_empty() {
            String::new()
        } else {
            format!(" ({}: delay 0, no states)", zero.join(", "))
        };
        println!("Actuator delays replaced by order-{pade} Pade approximants{note}.");
    }
    let states = names(&v["state_names"]);
    let inputs = names(&v["input_names"]);
    let outputs = names(&v["output_names"]);
    let su: Vec<String> = names(&v["units"]["states"]);
    let ou: Vec<String> = names(&v["units"]["outputs"]);
    println!(
        "\nStates [unit]: {}",
        states
            .iter()
            .zip(&su)
            .map(|(s, u)| format!("{s} [{u}]"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    println!("Inputs [unit]: u_delta [mg/cycle], u_egr [%], u_vgt [%], n_e [rpm]");
    println!(
        "Outputs [unit]: {}",
        outputs
            .iter()
            .zip(&ou)
            .map(|(s, u)| format!("{s} [{u}]"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    println!("\nPoles (eigenvalues of A) [1/s]");
    for z in v["eigenvalues"].as_array().into_iter().flatten() {
        println!("  {}", fmt_c(z));
    }
    print_matrix(
        "DC gain (output unit per input unit)",
        &v["dc_gain"],
        &outputs,
        &inputs,
    );
    println!("\nTransmission zeros [1/s] (RHP = right half plane: non-minimum phase)");
    for (k, zs) in v["zeros"].as_object().into_iter().flatten() {
        match zs.as_array() {
            None => println!(
                "  {k:<20} not computed: {}",
                v["zero_errors"][k].as_str().unwrap_or("")
            ),
            Some(list) => {
                let rhp = list.iter().any(|z| {
                    let re = z["re"].as_f64().unwrap_or(0.0);
                    let im = z["im"].as_f64().unwrap_or(0.0);
                    re > 1e-9 * (1.0 + re.hypot(im))
                });
                let s: Vec<String> = list.iter().map(fmt_c).collect();
                println!(
                    "  {k:<20} {}{}",
                    if s.is_empty() {
                        "none".to_string()
                    } else {
                        s.join(", ")
                    },
                    if rhp { "   <- RHP zero" } else { "" }
                );
            }
        }
    }
    println!(
        "  (MIMO = ({}) -> ({}))",
        names(&v["mimo"]["inputs"]).join(", "),
        names(&v["mimo"]["outputs"]).join(", ")
    );
    print_matrix(
        "A (d(row state)/dt per unit of the column state)",
        &v["A"],
        &states,
        &states,
    );
    print_matrix("B", &v["B"], &states, &inputs);
    print_matrix("C", &v["C"], &outputs, &states);
    print_matrix("D", &v["D"], &outputs, &inputs);
    if v["discrete"].is_object() {
        print_discrete(&v["discrete"], &inputs, &outputs);
    }
}

/// The sampled model of `--ts`.
fn print_discrete(dv: &Value, inputs: &[String], outputs: &[String]) {
    let states = names(&dv["state_names"]);
    let ds = |k: &str| {
        let w = dv["delay_samples"][k]["whole"].as_u64().unwrap_or(0);
        let r = dv["delay_samples"][k]["remainder_s"]
            .as_f64()
            .unwrap_or(0.0);
        // the remainder in ms, rounded to 1 ns (0.065 - 3 x 0.02 is 0.0050000000000000044)
        format!(
            "{} s = {w} samples + {} ms",
            dv["delays_s"][k],
            (r * 1e9).round() / 1e6
        )
    };
    println!(
        "\nSampled with a zero-order hold at ts = {} s, delays exact: u_egr {}, u_vgt {}",
        dv["ts"],
        ds("u_egr"),
        ds("u_vgt")
    );
    println!(
        "  dx(k+1) = Phi dx(k) + Gamma du(k), dy(k) = C dx(k) + D du(k); {} states: {}",
        states.len(),
        states.join(", ")
    );
    println!("\nPoles of the sampled model (eigenvalues of Phi; |z| < 1 stable)");
    for z in dv["poles"].as_array().into_iter().flatten() {
        let (re, im) = (
            z["re"].as_f64().unwrap_or(f64::NAN),
            z["im"].as_f64().unwrap_or(f64::NAN),
        );
        println!("  {}   |z| = {:.6}", fmt_c(z), re.hypot(im));
    }
    print_matrix("Phi", &dv["Phi"], &states, &states);
    print_matrix("Gamma", &dv["Gamma"], &states, inputs);
    print_matrix("C (sampled)", &dv["C"], outputs, &states);
    print_matrix("D (sampled)", &dv["D"], outputs, inputs);
}
