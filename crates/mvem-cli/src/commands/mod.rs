//! One module per subcommand; each has an `Args` struct (clap) and a `run` function.

pub mod bench;
pub mod demo;
pub mod params;
pub mod robustness;
pub mod simulate;
pub mod steady;
