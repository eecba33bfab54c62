//! Robustness sweep: random, seeded input sequences and start states; checks for panics, clear
//! errors, NaN/inf output and physical invariants at every output sample.
//!
//! `cargo run --release -p mvem --example robustness -- --runs 10000 --seed 1 --threads 2`
//! Options: `--runs N`, `--seed S`, `--threads T`, `--t-end SECONDS` (default 60),
//! `--orders 8,10,12`, `--methods rosenbrock34,dopri5`, `--semantics authors|paper`.
//! `--first-run K` starts at run K (`--first-run K --runs 1` replays run K alone);
//! `--rtol R` sets the solver tolerance (atol = R / 100).
//! `--chunk N --checkpoint FILE`: run the sweep in chunks of N runs and rewrite FILE with the
//! cumulative report after every chunk (the same runs as one sweep; a long sweep that is
//! stopped still leaves the results of its finished chunks, marked partial).
//! Exit status 1 if any panic, NaN/inf output, invariant violation or unlocated error occurred.

use mvem::analysis::robustness::{sweep, SweepConfig, SweepReport};
use mvem::components::Semantics;
use mvem::model::ModelOrder;
use mvem::params::Params;
use mvem::sim::Method;

fn main() {
    let mut cfg = SweepConfig::default();
    let mut chunk: u64 = 0;
    let mut checkpoint: Option<String> = None;
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut i = 0;
    while i < args.len() {
        let key = args[i].as_str();
        let Some(val) = args.get(i + 1) else {
            eprintln!("error: {key} needs a value");
            std::process::exit(2);
        };
        let bad = |what: &str| -> ! {
            eprintln!("error: {key} {val}: {what}");
            std::process::exit(2)
        };
        match key {
            "--runs" => cfg.runs = val.parse().unwrap_or_else(|_| bad("expected an integer")),
            "--chunk" => chunk = val.parse().unwrap_or_else(|_| bad("expected an integer")),
            "--checkpoint" => checkpoint = Some(val.clone()),
            "--first-run" => {
                cfg.first_run = val.parse().unwrap_or_else(|_| bad("expected an integer"))
            }
            "--rtol" => {
                cfg.sim.rtol = val.parse().unwrap_or_else(|_| bad("expected a number"));
                cfg.sim.atol = cfg.sim.rtol * 1e-2;
            }
            "--seed" => cfg.seed = val.parse().unwrap_or_else(|_| bad("expected an integer")),
            "--threads" => cfg.threads = val.parse().unwrap_or_else(|_| bad("expected an integer")),
            "--t-end" => {
                cfg.t_end = val.parse().unwrap_or_else(|_| bad("expected seconds"));
                if !(cfg.t_end.is_finite() && cfg.t_end > 0.0) {
                    bad("must be > 0");
                }
            }
            "--orders" => {
                cfg.orders = val
                    .split(',')
                    .map(|s| {
                        s.trim()
                            .parse()
                            .ok()
                            .and_then(ModelOrder::from_states)
                            .unwrap_or_else(|| bad("expected 8, 10 or 12"))
                    })
                    .collect()
            }
            "--methods" => {
                cfg.methods = val
                    .split(',')
                    .map(|s| match s.trim() {
                        "rosenbrock34" => Method::Rosenbrock34,
                        "dopri5" => Method::Dopri5,
                        _ => bad("expected rosenbrock34 or dopri5"),
                    })
                    .collect()
            }
            "--semantics" => {
                cfg.model.semantics = match val.as_str() {
                    "authors" => Semantics::Authors,
                    "paper" => Semantics::Paper,
                    _ => bad("expected authors or paper"),
                }
            }
            _ => bad("unknown option"),
        }
        i += 2;
    }
    let report = if chunk == 0 || chunk >= cfg.runs {
        sweep(&Params::published(), &cfg)
    } else {
        let mut total = SweepReport::default();
        let mut done = 0;
        while done < cfg.runs {
            let n = chunk.min(cfg.runs - done);
            let part = SweepConfig {
                first_run: cfg.first_run + done,
                runs: n,
                ..cfg.clone()
            };
            total.merge(sweep(&Params::published(), &part));
            done += n;
            if let Some(path) = &checkpoint {
                let text = format!(
                    "{} of {} runs (runs {}..{}){}\n{total}",
                    done,
                    cfg.runs,
                    cfg.first_run,
                    cfg.first_run + done,
                    if done < cfg.runs { ", PARTIAL" } else { "" }
                );
                if let Err(e) = mvem::io::output::write_atomic(path.as_ref(), text.as_bytes()) {
                    eprintln!("warning: {e}");
                }
            }
        }
        total
    };
    println!("{report}");
    if !report.clean() {
        std::process::exit(1);
    }
}
