use mvem::model::Engine8;
use mvem::sim::{simulate, Method, SimOptions, Start};
fn main() {
    let m = Engine8::published();
    let sched =
        mvem::io::csv_inputs::load_inputs_csv(std::path::Path::new("data/whtc_inputs_10hz.csv"))
            .unwrap();
    let refopts = SimOptions {
        rtol: 1e-10,
        atol: 1e-12,
        dt_out: 0.1,
        method: Method::Dopri5,
        ..SimOptions::default()
    };
    let r = simulate(&m, &sched, 0.0, 1800.0, Start::SteadyState, &refopts).unwrap();
    for (method, rtol) in [
        (Method::Dopri5, 1e-6),
        (Method::Rosenbrock34, 1e-6),
        (Method::Rosenbrock34, 1e-5),
        (Method::Rosenbrock34, 1e-4),
        (Method::Rosenbrock34, 1e-10),
    ] {
        let atol: f64 = std::env::var("ATOLF")
            .map(|v| v.parse().unwrap())
            .unwrap_or(1e-2);
        let opts = SimOptions {
            rtol,
            atol: rtol * atol,
            dt_out: 0.1,
            method,
            ..SimOptions::default()
        };
        let t = std::time::Instant::now();
        let sol = simulate(&m, &sched, 0.0, 1800.0, Start::SteadyState, &opts);
        let el = t.elapsed();
        match sol {
            Ok(s) => {
                let mut dev: f64 = 0.0;
                for (n, sc) in [
                    ("p_im", 1e5),
                    ("p_em", 1e5),
                    ("X_Oim", 0.1),
                    ("X_Oem", 0.1),
                    ("omega_t", 1e4),
                ] {
                    let a = s.get(n).unwrap();
                    let b = r.get(n).unwrap();
                    for i in 0..a.len() {
                        dev = dev.max((a[i] - b[i]).abs() / sc);
                    }
                }
                println!(
                    "{method:?} rtol {rtol}: {:?} dev {dev:.2e} {:?}",
                    el, s.stats
                )
            }
            Err(e) => println!("err {e}"),
        }
    }
}
