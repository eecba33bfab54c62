//! Package the 8-state FMU with the published parameters: `mvem-fmu-build --out FILE.fmu [--so PATH]`.
//! `mvem fmu` (the CLI) offers the other variants and parameter files.
//!
//! Without `--so`, the shared library is taken from next to this executable
//! (`target/release/libmvem_fmu.so` when run as
//! `cargo run --release -p mvem-fmu --bin mvem-fmu-build -- --out mvem.fmu`, which builds it).

use std::path::PathBuf;
use std::process::ExitCode;

fn main() -> ExitCode {
    let mut out: Option<PathBuf> = None;
    let mut so: Option<PathBuf> = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--out" => out = args.next().map(PathBuf::from),
            "--so" => so = args.next().map(PathBuf::from),
            "-h" | "--help" => {
                println!("usage: mvem-fmu-build --out FILE.fmu [--so libmvem_fmu.so]");
                return ExitCode::SUCCESS;
            }
            other => {
                eprintln!("error: unknown argument {other:?} (usage: mvem-fmu-build --out FILE.fmu [--so PATH])");
                return ExitCode::from(2);
            }
        }
    }
    let Some(out) = out else {
        eprintln!("error: --out FILE.fmu is required");
        return ExitCode::from(2);
    };
    let so = so.unwrap_or_else(|| {
        let exe = std::env::current_exe().unwrap_or_default();
        exe.with_file_name("libmvem_fmu.so")
    });
    if !so.exists() {
        eprintln!(
            "error: shared library {} not found; build it with `cargo build --release -p mvem-fmu` or pass --so",
            so.display()
        );
        return ExitCode::FAILURE;
    }
    match mvem_fmu::build::build(&out, &so, &mvem_fmu::vars::FmuConfig::default()) {
        Ok(()) => {
            println!("wrote {}", out.display());
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
