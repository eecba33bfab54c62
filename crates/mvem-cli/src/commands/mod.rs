//! One module per subcommand; each has an `Args` struct (clap) and a `run` function.

pub mod bench;
pub mod demo;
pub mod lab;
pub mod params;
pub mod simulate;
pub mod steady;
pub mod tune;
pub mod validate;
