//! `mvem campaign`: what a tuning campaign holds and which tuning steps it supports, before
//! any tuning (`mvem::tuning::summary`): the first command on a campaign made elsewhere.

use crate::common;
use anyhow::Result;
use mvem::tuning::data::load_campaign;
use mvem::tuning::summary::summarize;
use std::path::PathBuf;

/// Arguments of `mvem campaign`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  mvem campaign --data campaign
  mvem campaign --data campaign --json

Loads the campaign as `mvem tune` does (manifest, [columns] and [units], every file checked:
errors name the file, line and column) and prints the stationary points' ranges, one row per
dynamic set (kind, roles, samples, duration, the manifest's and the measured sample rate, the
command steps found, whether the actuator positions are there) and which of the tuning steps
1-5 the data support. --json prints the same as one object. Format: docs/tuning-data.md.")]
pub struct Args {
    /// Campaign directory (manifest.toml).
    #[arg(long, value_name = "DIR")]
    pub data: PathBuf,
    /// Print one JSON object instead of the text.
    #[arg(long)]
    pub json: bool,
}

/// Run `mvem campaign`.
pub fn run(a: &Args) -> Result<()> {
    let c = load_campaign(&a.data).map_err(|e| common::usage(e.to_string()))?;
    let s = summarize(&c);
    if a.json {
        println!("{}", serde_json::to_string_pretty(&s)?);
    } else {
        print!("{}", s.text());
    }
    Ok(())
}
