//! `mvem steady`: the equilibrium at constant inputs, with validity flags and eigenvalues.

use crate::common::{self, ModelArgs};
use anyhow::{Context, Result};
use mvem::analysis::steady::{steady_state, SteadyState};
use mvem::model::{Drive, Model, Signals};

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
    let d = a.point.drive(a.model.input_ranges()?.as_ref())?;
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
        println!(
            "{}",
            serde_json::to_string_pretty(&mvem::analysis::json::steady_json(m, &ss))?
        );
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
