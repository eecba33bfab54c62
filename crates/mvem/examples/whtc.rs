use mvem::model::Engine8;
use mvem::sim::{simulate, SimOptions, Start};
fn main() {
    let m = Engine8::published();
    let sched =
        mvem::io::csv_inputs::load_inputs_csv(std::path::Path::new("data/whtc_inputs_10hz.csv"))
            .unwrap();
    for (rtol, stop) in [(1e-6, true), (1e-6, false), (1e-10, true)] {
        let opts = SimOptions {
            rtol,
            atol: rtol * 1e-2,
            dt_out: 0.1,
            stop_at_breakpoints: stop,
            h_max: if stop { f64::INFINITY } else { 0.1 },
            ..SimOptions::default()
        };
        let t = std::time::Instant::now();
        let sol = simulate(&m, &sched, 0.0, 1800.0, Start::SteadyState, &opts);
        let el = t.elapsed();
        match sol {
            Ok(s) => println!(
                "rtol {rtol} stop {stop}: {:?} {:?} lam_min {}",
                el,
                s.stats,
                s.get("lambda_O")
                    .unwrap()
                    .iter()
                    .cloned()
                    .fold(f64::INFINITY, f64::min)
            ),
            Err(e) => println!("err {e}"),
        }
    }
}
