//! One module per subcommand; each has an `Args` struct (clap) and a `run` function.

pub mod bench;
pub mod compare_models;
pub mod demo;
pub mod params;
pub mod simulate;
pub mod steady;
pub mod te_study;
