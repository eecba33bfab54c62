//! `mvem fmu`: package an FMI 2.0 FMU (Model Exchange + Co-Simulation, linux64).
//!
//! One shared library (`libmvem_fmu.so`, the cdylib of `crates/mvem-fmu`) serves every FMU:
//! the model variant, the cylinder-temperature mode and the parameter set are written to
//! `resources/mvem.json` inside the archive and read by the library at `fmi2Instantiate`;
//! `modelDescription.xml` lists the variables of that variant with the parameter file's values
//! as start values. The command therefore only needs the library once, not a compiler.

use crate::common::{self, CylinderTempArg, ModelArg};
use anyhow::{Context, Result};
use mvem::analysis::steady::steady_state;
use mvem::model::{AnyModel, CylinderTemp, Drive, ModelOptions, ModelOrder};
use mvem::params::Params;
use mvem_fmu::vars::{FmuConfig, INPUT_STARTS};
use std::path::{Path, PathBuf};

/// Arguments of `mvem fmu`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  mvem fmu --out mvem.fmu
  mvem fmu --out mvem10.fmu --model 10 --params my_params.toml
  mvem fmu --out mvem_cs.fmu --cylinder-temp one-iteration

The shared library is taken from --lib, else $MVEM_FMU_LIB, else libmvem_fmu.so next to the
mvem executable (`cargo build --release --workspace` puts both in target/release).
With --cylinder-temp one-iteration the FMU offers Co-Simulation only.")]
pub struct Args {
    /// Output FMU file.
    #[arg(long, value_name = "FILE.fmu")]
    pub out: PathBuf,
    /// Model variant (number of states).
    #[arg(long, value_enum, default_value = "8")]
    pub model: ModelArg,
    /// Parameter file (TOML, nested JSON or the authors' flat JSON): the parameters' start
    /// values [default: the built-in published set]
    #[arg(long, value_name = "FILE")]
    pub params: Option<PathBuf>,
    /// Cylinder-out temperature fixed point (eq. (24)); one-iteration: Co-Simulation only.
    #[arg(long = "cylinder-temp", value_enum, default_value = "converged")]
    pub cylinder_temp: CylinderTempArg,
    /// The FMU shared library libmvem_fmu.so [default: $MVEM_FMU_LIB, else next to mvem]
    #[arg(long, value_name = "FILE")]
    pub lib: Option<PathBuf>,
}

/// Where the shared library is: `--lib`, `$MVEM_FMU_LIB`, or next to the executable.
fn find_lib(arg: Option<&Path>) -> Result<PathBuf> {
    let (path, source) = match (arg, std::env::var_os("MVEM_FMU_LIB")) {
        (Some(p), _) => (p.to_path_buf(), "--lib"),
        (None, Some(p)) => (PathBuf::from(p), "$MVEM_FMU_LIB"),
        (None, None) => {
            let exe = std::env::current_exe().context("cannot locate the mvem executable")?;
            (
                exe.with_file_name("libmvem_fmu.so"),
                "the mvem executable's directory",
            )
        }
    };
    if !path.is_file() {
        return Err(common::usage(format!(
            "FMU shared library {} (from {source}) not found; build it with \
             `cargo build --release -p mvem-fmu` and pass --lib target/release/libmvem_fmu.so",
            path.display()
        )));
    }
    Ok(path)
}

/// Run `mvem fmu`.
pub fn run(a: &Args) -> Result<()> {
    common::check_output_path(&a.out, "--out")?;
    let lib = find_lib(a.lib.as_deref())?;
    let params = match &a.params {
        None => Params::published(),
        Some(p) => mvem::io::params::load_params(p)
            .with_context(|| format!("cannot use parameter file {}", p.display()))?,
    };
    let order = match a.model {
        ModelArg::Eight => ModelOrder::Eight,
        ModelArg::Ten => ModelOrder::Ten,
        ModelArg::Twelve => ModelOrder::Twelve,
    };
    let cylinder_temp = match a.cylinder_temp {
        CylinderTempArg::Converged => CylinderTemp::Converged,
        CylinderTempArg::OneIteration => CylinderTemp::OneIteration,
    };
    let cfg = FmuConfig {
        order,
        cylinder_temp,
        params,
    };
    // the FMU starts at the steady state of its start inputs: check now that there is one
    let model = AnyModel::new(
        order,
        cfg.params.clone(),
        ModelOptions {
            cylinder_temp,
            ..ModelOptions::default()
        },
    )
    .context("cannot build the model")?;
    let d = Drive::from_array(INPUT_STARTS);
    mvem::dispatch!(&model, m => steady_state(m, &d).map(|_| ())).with_context(|| {
        format!(
            "no steady state at the FMU's start inputs n_e = {} rpm, u_delta = {} mg/cycle, u_egr = {} %, u_vgt = {} %",
            d.n_e_rpm, d.u_delta_mg, d.u_egr_pct, d.u_vgt_pct
        )
    })?;
    mvem_fmu::build::build(&a.out, &lib, &cfg).map_err(common::usage)?;
    println!(
        "wrote {} ({} states, {} cylinder temperature, {}; library {})",
        a.out.display(),
        order.states(),
        match cylinder_temp {
            CylinderTemp::Converged => "converged",
            CylinderTemp::OneIteration => "one-iteration",
        },
        if cfg.model_exchange() {
            "Model Exchange + Co-Simulation"
        } else {
            "Co-Simulation only"
        },
        lib.display()
    );
    Ok(())
}
