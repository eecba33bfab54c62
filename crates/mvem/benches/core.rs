//! Core benchmarks: one model evaluation and the 1800 s WHTC drive cycle (rtol 1e-6, 0.1 s
//! output). Run: `cargo bench -p mvem --bench core`.

use criterion::{criterion_group, criterion_main, Criterion};
use mvem::analysis::steady::steady_state;
use mvem::components::cylinder::SeligerIterate;
use mvem::model::{Drive, Engine8, Model, ModelInput};
use mvem::sim::{simulate, SimOptions, Start};
use std::hint::black_box;

fn eval(c: &mut Criterion) {
    let m = Engine8::published();
    let d = Drive::new(1500.0, 110.0, 80.0, 75.0);
    let x = steady_state(&m, &d).unwrap().x;
    let u = ModelInput::constant(d);
    let mem = SeligerIterate {
        x_r: 0.0,
        t_1: 300.0,
    };
    c.bench_function("Model::eval (8 states, converged T_e)", |b| {
        b.iter(|| m.eval(black_box(&x), black_box(&u), mem))
    });
}

fn whtc(c: &mut Criterion) {
    let m = Engine8::published();
    let text = include_str!("../../../data/whtc_inputs_10hz.csv");
    let sched = mvem::io::csv_inputs::parse_inputs_csv(text, std::path::Path::new("whtc")).unwrap();
    let opts = SimOptions {
        dt_out: 0.1,
        ..SimOptions::default()
    };
    let mut g = c.benchmark_group("whtc");
    g.sample_size(10);
    g.bench_function("WHTC 1800 s, rtol 1e-6, default method", |b| {
        b.iter(|| simulate(&m, &sched, 0.0, 1800.0, Start::SteadyState, &opts).unwrap())
    });
    g.finish();
}

criterion_group!(benches, eval, whtc);
criterion_main!(benches);
