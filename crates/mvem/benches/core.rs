//! Core benchmarks: one model evaluation and the 1800 s WHTC drive cycle (rtol 1e-6, 0.1 s
//! output), for the 8-state model and the 10- and 12-state extensions (section 9).
//! Run: `cargo bench -p mvem --bench core` (or `-- "12 states"` for one model).

use criterion::{criterion_group, criterion_main, Criterion};
use mvem::analysis::steady::{simulate_from_steady, steady_state};
use mvem::model::{Drive, Engine10, Engine12, Engine8, Model, ModelInput};
use mvem::sim::{InputSchedule, SimOptions};
use std::hint::black_box;

fn eval_one<const N: usize, M: Model<N>>(c: &mut Criterion, m: &M) {
    let d = Drive::new(1500.0, 110.0, 80.0, 75.0);
    let x = steady_state(m, &d).unwrap().x;
    let u = ModelInput::constant(d);
    let mem = m.memory_start(&x, &u);
    c.bench_function(&format!("Model::eval ({N} states, converged T_e)"), |b| {
        b.iter(|| m.eval(black_box(&x), black_box(&u), mem))
    });
}

fn eval(c: &mut Criterion) {
    eval_one(c, &Engine8::published());
    eval_one(c, &Engine10::published());
    eval_one(c, &Engine12::published());
}

fn whtc_one<const N: usize, M: Model<N>>(c: &mut Criterion, m: &M, sched: &InputSchedule) {
    let opts = SimOptions {
        dt_out: 0.1,
        ..SimOptions::default()
    };
    let mut g = c.benchmark_group("whtc");
    g.sample_size(10);
    let name = if N == 8 {
        // the name of the 8-state benchmark before the extensions were added
        "WHTC 1800 s, rtol 1e-6, default method".to_string()
    } else {
        format!("WHTC 1800 s, rtol 1e-6, default method, {N} states")
    };
    g.bench_function(&name, |b| {
        b.iter(|| simulate_from_steady(m, sched, 0.0, 1800.0, &opts).unwrap())
    });
    g.finish();
}

fn whtc(c: &mut Criterion) {
    let text = include_str!("../../../data/whtc_inputs_10hz.csv");
    let sched = mvem::io::csv_inputs::parse_inputs_csv(text, std::path::Path::new("whtc")).unwrap();
    whtc_one(c, &Engine8::published(), &sched);
    whtc_one(c, &Engine10::published(), &sched);
    whtc_one(c, &Engine12::published(), &sched);
}

criterion_group!(benches, eval, whtc);
criterion_main!(benches);
