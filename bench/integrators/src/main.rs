//! Integrator comparison for mvem: mvem's own simulator against diffsol's explicit (tsit45),
//! BDF and SDIRK (TR-BDF2, ESDIRK34) methods on the same 8-state model, inputs and stop times,
//! on the WHTC drive cycle and on the demo step.
//!
//! Run: `cargo run --release --manifest-path bench/integrators/Cargo.toml [-- --quick]`
//!
//! Writes the result tables into `docs/integrator.md` (between the `results` markers) and the
//! work-precision figure `docs/integrator_work_precision.png`, and prints the tables.
//! `--quick` runs only rtol 1e-6 with one repetition and writes nothing (for trying changes).

mod cases;
mod plot;
mod runners;
mod stiffness;

use anyhow::{anyhow, Context, Result};
use cases::{max_dev, Case, COMPARED};
use runners::{Method, RunOutput, Stats};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Relative tolerance of the main table.
const RTOL_MAIN: f64 = 1e-6;
/// Absolute tolerance relative to the state scales, as a fraction of rtol (1e-8 at rtol 1e-6).
const ATOL_OVER_RTOL: f64 = 1e-2;
/// Tolerances of the work-precision sweep.
const RTOL_SWEEP: [f64; 5] = [1e-4, 1e-5, 1e-6, 1e-7, 1e-8];
/// Reference tolerance.
const RTOL_REF: f64 = 1e-10;
/// Repetitions for the wall time (the minimum is reported).
const REPEATS: usize = 3;

/// One measured point.
pub struct Point {
    /// Method.
    pub method: Method,
    /// Relative tolerance.
    pub rtol: f64,
    /// Minimum wall time over the repetitions [s].
    pub wall_s: f64,
    /// Minimum process CPU time over the repetitions [s] (less sensitive to other load).
    pub cpu_s: f64,
    /// Work counters.
    pub stats: Stats,
    /// Maximum scaled deviation from the reference per compared state.
    pub dev: [f64; 5],
    /// Time of the overall maximum deviation [s].
    pub t_worst: f64,
}

impl Point {
    /// Maximum over the compared states.
    pub fn dev_max(&self) -> f64 {
        self.dev.iter().copied().fold(0.0, f64::max)
    }
}

/// CPU time of this process [s].
fn cpu_time() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes into the timespec we own; CLOCK_PROCESS_CPUTIME_ID exists on
    // Linux.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return f64::NAN;
    }
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

/// Run `repeats` times; minimum wall and CPU times [s] and the last output.
fn timed(
    method: Method,
    case: &Case,
    rtol: f64,
    repeats: usize,
) -> Result<(f64, f64, RunOutput), String> {
    let (mut wall, mut cpu) = (f64::INFINITY, f64::INFINITY);
    let mut last = None;
    for _ in 0..repeats {
        let (t, c) = (Instant::now(), cpu_time());
        let out = method
            .run(case, rtol, rtol * ATOL_OVER_RTOL)
            .map_err(|e| format!("{e:#}"))?;
        wall = wall.min(t.elapsed().as_secs_f64());
        cpu = cpu.min(cpu_time() - c);
        last = Some(out);
    }
    Ok((wall, cpu, last.expect("repeats >= 1")))
}

/// Results of one case.
pub struct CaseResult {
    /// Case name.
    pub name: &'static str,
    /// Description.
    pub description: String,
    /// Number of stop times (input breakpoints, shifted by the delays) in the interval.
    pub n_stops: usize,
    /// Of which jumps.
    pub n_jumps: usize,
    /// Reference run (mvem DOPRI5 at RTOL_REF): wall time, stats.
    pub reference: (f64, Stats),
    /// Cross-checks of the reference: (method, wall time, stats, deviation from the reference).
    pub ref_checks: Vec<(Method, f64, Stats, [f64; 5])>,
    /// Measured points.
    pub points: Vec<Point>,
    /// Failed runs: (method, rtol, message).
    pub failures: Vec<(Method, f64, String)>,
    /// Fastest eigenvalues along the reference trajectory.
    pub stiffness: stiffness::Stiffness,
    /// Samples between eigenvalue evaluations.
    pub stiffness_every: usize,
    /// Integration interval length [s].
    pub span: f64,
}

fn run_case(case: &Case, rtols: &[f64], repeats: usize) -> Result<CaseResult> {
    let stops = mvem::sim::stop_times(&case.model, &case.sched, case.t0, case.t_end);
    eprintln!(
        "== {}: {} stop times ({} jumps)",
        case.name,
        stops.len(),
        stops.iter().filter(|s| s.1).count()
    );
    let (ref_wall, _, reference) = timed(Method::MvemDopri5, case, RTOL_REF, 1)
        .map_err(|e| anyhow!("reference run failed: {e}"))?;
    let times = case.out_times();
    if reference.times.len() != times.len()
        || reference
            .times
            .iter()
            .zip(&times)
            .any(|(a, b)| (a - b).abs() > 1e-9)
    {
        return Err(anyhow!(
            "mvem output grid ({} samples) differs from the expected 0.1 s grid ({} samples)",
            reference.times.len(),
            times.len()
        ));
    }
    eprintln!("   reference mvem DOPRI5 rtol {RTOL_REF:e}: {ref_wall:.3} s");
    // eigenvalues every 1 s along the reference
    let every = ((1.0 / cases::DT_OUT).round() as usize).max(1);
    let stiff = stiffness::along(case, &reference.full, &times, every);
    eprintln!(
        "   fastest eigenvalue: start {:.1} 1/s, median {:.1}, most negative {:.1} at {:.1} s; max Re {:.2}",
        stiff.start, stiff.median, stiff.worst, stiff.t_worst, stiff.max_re
    );
    let mut ref_checks = Vec::new();
    for m in [Method::Tsit45, Method::Esdirk34] {
        match timed(m, case, RTOL_REF, 1) {
            Ok((w, _, out)) => {
                let (dev, _) = max_dev(&out.samples, &reference.samples, &times);
                eprintln!(
                    "   check {} rtol {RTOL_REF:e}: {w:.3} s, max dev {:.2e}",
                    m.label(),
                    dev.iter().copied().fold(0.0, f64::max)
                );
                ref_checks.push((m, w, out.stats, dev));
            }
            Err(e) => eprintln!("   check {} rtol {RTOL_REF:e} FAILED: {e}", m.label()),
        }
    }
    let mut points = Vec::new();
    let mut failures = Vec::new();
    for &rtol in rtols {
        for m in Method::ALL {
            match timed(m, case, rtol, repeats) {
                Ok((wall_s, cpu_s, out)) => {
                    let (dev, t_worst) = max_dev(&out.samples, &reference.samples, &times);
                    let p = Point {
                        method: m,
                        rtol,
                        wall_s,
                        cpu_s,
                        stats: out.stats,
                        dev,
                        t_worst,
                    };
                    eprintln!(
                        "   {:<17} rtol {rtol:.0e}: {:8.4} s  steps {:7} rhs {:8}  max dev {:.2e} at {:.1} s",
                        m.label(),
                        wall_s,
                        p.stats.steps,
                        p.stats.rhs_evals,
                        p.dev_max(),
                        t_worst
                    );
                    points.push(p);
                }
                Err(e) => {
                    eprintln!("   {:<17} rtol {rtol:.0e}: FAILED: {e}", m.label());
                    failures.push((m, rtol, e));
                }
            }
        }
    }
    Ok(CaseResult {
        name: case.name,
        description: case.description.clone(),
        n_stops: stops.len(),
        n_jumps: stops.iter().filter(|s| s.1).count(),
        reference: (ref_wall, reference.stats),
        ref_checks,
        points,
        failures,
        stiffness: stiff,
        stiffness_every: every,
        span: case.t_end - case.t0,
    })
}

fn opt(v: Option<usize>) -> String {
    v.map_or("-".into(), |n| n.to_string())
}

fn machine() -> String {
    let nproc = std::thread::available_parallelism().map_or(0, |n| n.get());
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| "unknown".into());
    let load = std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| s.split_whitespace().next().map(str::to_string))
        .unwrap_or_else(|| "?".into());
    format!("nproc {nproc}, CPU: {cpu}, 1-min load average at the end of the run {load}")
}

fn table(res: &CaseResult, rtol: f64) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "| method | wall [ms] | CPU [ms] | steps | rejected | RHS evals (FD Jacobian) | Jacobians | LU | Newton its (fails) | max dev | p_im | p_em | X_Oim | X_Oem | omega_t |"
    );
    let _ = writeln!(
        s,
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    );
    for p in res.points.iter().filter(|p| p.rtol == rtol) {
        let st = &p.stats;
        let rhs = if p.method.implicit() {
            format!("{} ({})", st.rhs_evals, st.rhs_evals_jac)
        } else {
            st.rhs_evals.to_string()
        };
        let _ = write!(
            s,
            "| {} | {:.1} | {:.1} | {} | {} | {} | {} | {} | {} | **{:.1e}** |",
            p.method.label(),
            p.wall_s * 1e3,
            p.cpu_s * 1e3,
            st.steps,
            st.rejected,
            rhs,
            opt(st.jac_evals),
            opt(st.lu),
            match (st.newton_iters, st.newton_fails) {
                (Some(i), Some(f)) => format!("{i} ({f})"),
                _ => "-".into(),
            },
            p.dev_max()
        );
        for d in p.dev {
            let _ = write!(s, " {d:.1e} |");
        }
        s.push('\n');
    }
    for (m, r, e) in res.failures.iter().filter(|f| f.1 == rtol) {
        let _ = writeln!(
            s,
            "| {} | failed at rtol {r:e}: {} |",
            m.label(),
            e.replace('|', "/")
        );
    }
    s
}

fn sweep_table(res: &CaseResult) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "| method | rtol | wall [ms] | CPU [ms] | steps | RHS evals | max dev |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|---:|---:|---:|");
    for m in Method::ALL {
        for p in res.points.iter().filter(|p| p.method == m) {
            let _ = writeln!(
                s,
                "| {} | {:.0e} | {:.1} | {:.1} | {} | {} | {:.1e} |",
                m.label(),
                p.rtol,
                p.wall_s * 1e3,
                p.cpu_s * 1e3,
                p.stats.steps,
                p.stats.rhs_evals,
                p.dev_max()
            );
        }
        for (_, r, e) in res.failures.iter().filter(|f| f.0 == m) {
            let _ = writeln!(
                s,
                "| {} | {r:.0e} | failed: {} | | | | |",
                m.label(),
                e.replace('|', "/")
            );
        }
    }
    s
}

fn report(results: &[CaseResult]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Generated by `cargo run --release --manifest-path bench/integrators/Cargo.toml` \
         (diffsol {}); machine: {}.\n",
        DIFFSOL_VERSION,
        machine()
    );
    let names: Vec<&str> = COMPARED.iter().map(|c| c.1).collect();
    let _ = writeln!(
        s,
        "Deviation = max over the 0.1 s samples of |x - x_ref| / scale for {} (scales 1e5 Pa, \
         1e5 Pa, 0.1, 0.1, 1e4 rad/s); \"max dev\" is the largest of the five. Wall and CPU time: \
         minimum of {REPEATS} runs each, including problem setup and output. atol = {:.0e} x rtol x state scale.\n",
        names.join(", "),
        ATOL_OVER_RTOL
    );
    for r in results {
        let _ = writeln!(s, "### {} (rtol {RTOL_MAIN:.0e})\n", r.name);
        let _ = writeln!(
            s,
            "{}; {} stop times ({} of them jumps). Reference: mvem DOPRI5 at rtol {RTOL_REF:.0e} \
             ({:.2} s, {} steps).",
            r.description, r.n_stops, r.n_jumps, r.reference.0, r.reference.1.steps
        );
        for (m, w, st, dev) in &r.ref_checks {
            let _ = write!(
                s,
                " Cross-check: {} at rtol {RTOL_REF:.0e} ({w:.2} s, {} steps) deviates from it \
                 by at most {:.1e}.",
                m.label(),
                st.steps,
                dev.iter().copied().fold(0.0, f64::max)
            );
        }
        let st = &r.stiffness;
        let _ = write!(
            s,
            "\n\nStiffness: the most negative real part of the eigenvalues of the 8-state Jacobian \
             is {:.0} 1/s at the start; along the reference (every {:.1} s, {} points) its median \
             is {:.0} 1/s and its minimum {:.0} 1/s (at t = {:.1} s); the largest real part seen is \
             {:.2} 1/s (at t = {:.1} s). An explicit 5(4) pair is stable on the negative real axis up to about \
             h |lambda| = 3.3, i.e. h <= {:.0} ms at the median and {:.0} ms at the minimum.",
            st.start,
            r.stiffness_every as f64 * cases::DT_OUT,
            st.n,
            st.median,
            st.worst,
            st.t_worst,
            st.max_re,
            st.t_max_re,
            3.3 / st.median.abs() * 1e3,
            3.3 / st.worst.abs() * 1e3,
        );
        if let Some(p) = r
            .points
            .iter()
            .find(|p| p.method == Method::MvemDopri5 && p.rtol == RTOL_MAIN)
        {
            let _ = write!(
                s,
                " mvem DOPRI5 at rtol {RTOL_MAIN:.0e} averages {:.1} ms per step.",
                r.span / p.stats.steps as f64 * 1e3
            );
        }
        let _ = writeln!(s, "\n");
        s.push_str(&table(r, RTOL_MAIN));
        s.push('\n');
    }
    let _ = writeln!(s, "### Tolerance sweep (data of the figure)\n");
    for r in results {
        let _ = writeln!(s, "{}:\n", r.name);
        s.push_str(&sweep_table(r));
        s.push('\n');
    }
    s
}

const DIFFSOL_VERSION: &str = "0.18";
const BEGIN: &str = "<!-- results:begin (written by bench/integrators) -->";
const END: &str = "<!-- results:end -->";

fn write_into_doc(doc: &Path, body: &str) -> Result<()> {
    let text =
        std::fs::read_to_string(doc).with_context(|| format!("reading {}", doc.display()))?;
    let (Some(i), Some(j)) = (text.find(BEGIN), text.find(END)) else {
        return Err(anyhow!(
            "{} has no `{BEGIN}` ... `{END}` markers",
            doc.display()
        ));
    };
    let new = format!("{}{BEGIN}\n{body}{}", &text[..i], &text[j..]);
    let tmp = doc.with_extension("md.tmp");
    std::fs::write(&tmp, new)?;
    std::fs::rename(&tmp, doc)?;
    Ok(())
}

fn main() -> Result<()> {
    let quick = std::env::args().any(|a| a == "--quick");
    let repo: PathBuf = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let (rtols, repeats): (&[f64], usize) = if quick {
        (&[RTOL_MAIN], 1)
    } else {
        (&RTOL_SWEEP, REPEATS)
    };
    let cases = [Case::whtc(&repo)?, Case::step()?];
    let mut results = Vec::new();
    for c in &cases {
        results.push(run_case(c, rtols, repeats)?);
    }
    let body = report(&results);
    println!("{body}");
    if !quick {
        let fig = repo.join("docs/integrator_work_precision.png");
        plot::work_precision(&fig, &results, RTOL_MAIN)?;
        eprintln!("wrote {}", fig.display());
        let doc = repo.join("docs/integrator.md");
        write_into_doc(&doc, &body)?;
        eprintln!("updated {}", doc.display());
    }
    Ok(())
}
