//! `mvem campaign`: what a tuning campaign holds and which tuning steps it supports, before
//! any tuning (`mvem::tuning::summary`): the first command on a campaign made elsewhere.

use crate::common;
use anyhow::Result;
use mvem::tuning::data::load_campaign;
use mvem::tuning::draft::{write_draft, WriteDraftError};
use mvem::tuning::summary::summarize_for;
use std::path::PathBuf;

/// Arguments of `mvem campaign`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  mvem campaign --data campaign
  mvem campaign --data campaign --json
  mvem campaign --data my_test_cell_csvs --init   # draft manifest.toml, then the summary

Loads the campaign as `mvem tune` does (manifest, [columns] and [units], every file checked:
errors name the file, line and column) and prints the stationary points' ranges, one row per
dynamic set (kind, roles, samples, duration, the manifest's and the measured sample rate, the
command steps found, whether the actuator positions are there) and which of the tuning steps
1-5 the data support, with warnings: time bases that differ from the manifest's, and EGR or VGT
commands outside the parameter set's command ranges (--params, by default the published
parameters: input_saturation.u_egr = [0, 100] %, u_vgt = [20, 100] %), which the model would
run clamped: set this engine's ranges before tuning (tune and validate warn of both too, against
their parameter file). --json prints the same as one object. --init first drafts DIR/manifest.toml
from the CSV files in DIR (the stationary file, each set's kind, roles, sample rate and steps,
units guessed where values are out of range in mvem's unit; every guess listed as a comment
and on stderr; an existing manifest is kept unless --force). Format: docs/tuning-data.md.")]
pub struct Args {
    /// Campaign directory (manifest.toml).
    #[arg(long, value_name = "DIR")]
    pub data: PathBuf,
    /// Print one JSON object instead of the text.
    #[arg(long)]
    pub json: bool,
    /// First draft DIR/manifest.toml from the CSV files in DIR.
    #[arg(long)]
    pub init: bool,
    /// With --init: replace an existing manifest.toml.
    #[arg(long, requires = "init")]
    pub force: bool,
    /// Parameter file (TOML or JSON) whose command ranges ([input_saturation] u_egr, u_vgt)
    /// the campaign's commands are checked against [default: the published parameters].
    #[arg(long, value_name = "FILE")]
    pub params: Option<PathBuf>,
}

/// Run `mvem campaign`.
pub fn run(a: &Args) -> Result<()> {
    if a.init {
        let d = write_draft(&a.data, a.force).map_err(|e| match e {
            WriteDraftError::Exists(p) => {
                common::usage(format!("{}: exists; --force replaces it", p.display()))
            }
            WriteDraftError::Data(e) => common::usage(e.to_string()),
            WriteDraftError::Write(m) => anyhow::Error::msg(m),
        })?;
        let path = a.data.join("manifest.toml");
        eprintln!("wrote {} (check what was guessed):", path.display());
        for n in &d.notes {
            eprintln!("  {n}");
        }
    }
    let c = load_campaign(&a.data).map_err(|e| common::usage(e.to_string()))?;
    let (p, set) = match &a.params {
        Some(path) => (
            mvem::io::params::load_params(path).map_err(|e| common::usage(e.to_string()))?,
            path.display().to_string(),
        ),
        None => (
            mvem::params::Params::published(),
            "the published parameters".to_string(),
        ),
    };
    let s = summarize_for(&c, &p.input_saturation, &set);
    if a.json {
        println!("{}", serde_json::to_string_pretty(&s)?);
    } else {
        print!("{}", s.text());
    }
    Ok(())
}
