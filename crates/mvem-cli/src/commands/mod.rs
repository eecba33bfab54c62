//! One module per subcommand; each has an `Args` struct (clap) and a `run` function.

pub mod bench;
pub mod campaign;
pub mod closed_loop;
pub mod compare_models;
pub mod components;
pub mod demo;
pub mod fmu;
pub mod lab;
pub mod linearize;
pub mod map;
pub mod margins;
pub mod params;
pub mod report;
pub mod robustness;
pub mod serve;
pub mod simulate;
pub mod steady;
pub mod step;
pub mod te_study;
pub mod tune;
pub mod validate;
