//! One WHTC run with the default options and 0.1 s output (for instruction counting:
//! `valgrind --tool=callgrind target/release/examples/whtc_once`).
use mvem::model::Engine8;
use mvem::sim::{simulate, SimOptions, Start};
fn main() {
    let m = Engine8::published();
    let text = include_str!("../../../data/whtc_inputs_10hz.csv");
    let sched = mvem::io::csv_inputs::parse_inputs_csv(text, std::path::Path::new("whtc")).unwrap();
    let opts = SimOptions {
        dt_out: 0.1,
        ..SimOptions::default()
    };
    let t = std::time::Instant::now();
    let s = simulate(&m, &sched, 0.0, 1800.0, Start::SteadyState, &opts).unwrap();
    println!("{:?} {:?}", t.elapsed(), s.stats);
}
