use mvem::analysis::steady::steady_state;
use mvem::components::cylinder::SeligerIterate;
use mvem::model::{Drive, Engine8, Model, ModelInput};
use mvem::sim::{simulate, InputSchedule, SimOptions, Start};
fn main() {
    let m = Engine8::published();
    let d = Drive::new(1500.0, 110.0, 80.0, 75.0);
    let s = steady_state(&m, &d).unwrap();
    let u = ModelInput::constant(d);
    let mem = SeligerIterate {
        x_r: 0.0,
        t_1: 300.0,
    };
    let n = 2_000_000;
    let t = std::time::Instant::now();
    let mut acc = 0.0;
    let mut x = s.x;
    for i in 0..n {
        x[0] = s.x[0] * (1.0 + (i % 7) as f64 * 1e-9);
        let e = m.eval(std::hint::black_box(&x), &u, mem);
        acc += e.dx[0];
    }
    println!("eval {:?} per call ({acc})", t.elapsed() / n);
    for d in [
        Drive::new(500.0, 1.0, 50.0, 65.0),
        Drive::new(1500.0, 110.0, 80.0, 75.0),
    ] {
        let sched = InputSchedule::constant(d);
        let opts = SimOptions {
            rtol: 1e-6,
            atol: 1e-8,
            dt_out: 1.0,
            ..SimOptions::default()
        };
        let mut x0 = steady_state(&m, &d).unwrap().x;
        x0[0] *= 1.05;
        let sol = simulate(&m, &sched, 0.0, 100.0, Start::State(x0), &opts).unwrap();
        println!("{:?}: {:?}", d.to_array(), sol.stats);
    }
}
