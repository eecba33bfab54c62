//! `mvem steady`: the equilibrium at constant inputs, with validity flags and eigenvalues.

use crate::common::{self, ModelArgs};
use anyhow::{Context, Result};
use mvem::analysis::steady::{steady_state, SteadyState};
use mvem::model::{Drive, Model, Signals};
use serde_json::{json, Map, Value};

/// Arguments of `mvem steady`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  mvem steady --n-e 1500 --u-delta 110 --u-egr 80 --u-vgt 75
  mvem steady --n-e 1200 --u-delta 50 --u-egr 0 --u-vgt 25 --json > point.json
  mvem steady --n-e 1500 --u-delta 180 --u-egr 80 --u-vgt 100 --strict

With --json, stdout holds one JSON object: every state and signal by name (\"p_im\", \"W_c\",
\"lambda_O\", ...), \"physically_valid\", \"flags\", \"eigenvalues\" [{re, im}], \"inputs\".")]
pub struct Args {
    /// The operating point (--n-e, --u-delta, --u-egr, --u-vgt).
    #[command(flatten)]
    pub point: common::PointArgs,
    /// Print one JSON object on stdout instead of tables.
    #[arg(long)]
    pub json: bool,
    /// Exit with code 1 if the equilibrium is not physically valid (see the flags).
    #[arg(long)]
    pub strict: bool,
    #[command(flatten)]
    pub model: ModelArgs,
}

/// Run `mvem steady`.
pub fn run(a: &Args) -> Result<()> {
    let d = a.point.drive()?;
    let model = a.model.build()?;
    let valid = mvem::dispatch!(&model, m => report(m, &d, a.json))?;
    if !valid && a.strict {
        anyhow::bail!("--strict: the equilibrium is not physically valid");
    }
    Ok(())
}

/// Solve, print, and return whether the point is physically valid.
fn report<const N: usize, M: Model<N>>(m: &M, d: &Drive, json: bool) -> Result<bool> {
    let ss = steady_state(m, d).context("steady state")?;
    let valid = ss.physically_valid();
    if json {
        println!("{}", serde_json::to_string_pretty(&to_json(m, &ss))?);
    } else {
        print_tables(m, &ss);
    }
    if !valid {
        eprintln!(
            "warning: the equilibrium is not physically valid; flags: {}",
            ss.flags.join(", ")
        );
    }
    Ok(valid)
}

/// The flat JSON object of a steady state.
pub fn to_json<const N: usize, M: Model<N>>(m: &M, ss: &SteadyState<N>) -> Value {
    let mut o = Map::new();
    for (n, v) in m.state_names().iter().zip(ss.x) {
        o.insert(n.to_string(), json!(v));
    }
    // T_im, T_em, p_c are states of the 10/12-state models: keep the state value
    for (n, v) in Signals::NAMES.iter().zip(ss.signals.values()) {
        o.entry(n.to_string()).or_insert(json!(v));
    }
    o.insert("physically_valid".into(), json!(ss.physically_valid()));
    o.insert("flags".into(), json!(ss.flags));
    o.insert(
        "eigenvalues".into(),
        Value::Array(
            ss.eigenvalues
                .iter()
                .map(|(re, im)| json!({"re": re, "im": im}))
                .collect(),
        ),
    );
    o.insert(
        "inputs".into(),
        json!({
            "n_e_rpm": ss.drive.n_e_rpm,
            "u_delta_mg": ss.drive.u_delta_mg,
            "u_egr_pct": ss.drive.u_egr_pct,
            "u_vgt_pct": ss.drive.u_vgt_pct,
        }),
    );
    o.insert("residual".into(), json!(ss.residual));
    Value::Object(o)
}

fn print_tables<const N: usize, M: Model<N>>(m: &M, ss: &SteadyState<N>) {
    let d = ss.drive;
    println!(
        "Steady state at n_e = {} rpm, u_delta = {} mg/cycle, u_egr = {} %, u_vgt = {} %",
        d.n_e_rpm, d.u_delta_mg, d.u_egr_pct, d.u_vgt_pct
    );
    println!(
        "(residual {:.1e} 1/s, {} Newton iterations{})\n",
        ss.residual,
        ss.iterations,
        if ss.settled {
            ", after a settling simulation"
        } else {
            ""
        }
    );
    println!("States");
    for (n, v) in m.state_names().iter().zip(ss.x) {
        println!(
            "  {n:<14} {:>18}  {}",
            common::fmt_value(v),
            common::unit(n)
        );
    }
    println!("\nSignals");
    let names = m.state_names();
    for (n, v) in Signals::NAMES
        .iter()
        .zip(ss.signals.values())
        .filter(|(n, _)| !names.contains(n))
    {
        println!(
            "  {n:<14} {:>18}  {}",
            common::fmt_value(v),
            common::unit(n)
        );
    }
    println!(
        "\nPhysically valid: {}",
        if ss.physically_valid() { "yes" } else { "NO" }
    );
    if ss.flags.is_empty() {
        println!("Flags: none");
    } else {
        println!("Flags:");
        for f in &ss.flags {
            println!("  {f}");
        }
    }
    println!("\nEigenvalues of the linearization (non-actuator states) [1/s]");
    for (re, im) in &ss.eigenvalues {
        if *im == 0.0 {
            println!("  {re:>12.4}");
        } else {
            println!(
                "  {re:>12.4} {} {:.4}i",
                if *im < 0.0 { '-' } else { '+' },
                im.abs()
            );
        }
    }
}
