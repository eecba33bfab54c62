//! Benchmarks of the control-oriented analysis (targets: linearization at a given state
//! <= 50 us; a 100 x 100 steady-state map <= 10 s on 2 cores).
//!
//! `cargo bench -p mvem --bench analysis` runs the criterion benchmarks (linearization, zeros,
//! a 20 x 20 map) and then times two 100 x 100 maps once on 2 threads, printing the figures.
//! On a shared machine criterion's wall-clock figures include time the process waits for a
//! core; the "thread CPU time" entry measures the linearization's CPU time instead.

use criterion::{criterion_group, Criterion};
use mvem::analysis::linearize::{linearize_steady, LinearizeOptions};
use mvem::analysis::map::{dc_gain_map, steady_map, Axis, ChannelMapOptions, Grid, MapOptions};
use mvem::analysis::steady::steady_state;
use mvem::analysis::zeros::{channel, mimo_zeros, poles, ZeroOptions, MIMO_INPUTS, MIMO_OUTPUTS};
use mvem::model::{Drive, Engine8};
use std::hint::black_box;
use std::time::{Duration, Instant};

/// CPU time of this thread [ns] (Linux `/proc/thread-self/schedstat`), if available.
fn thread_cpu_ns() -> Option<u64> {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// Thread CPU time of `f` (wall-clock time where the CPU time is unavailable): on a shared
/// machine this excludes the time spent waiting for a core.
fn cpu_time(f: impl FnOnce()) -> Duration {
    let wall = Instant::now();
    let t0 = thread_cpu_ns();
    f();
    match (t0, thread_cpu_ns()) {
        (Some(a), Some(b)) if b > a => Duration::from_nanos(b - a),
        _ => wall.elapsed(),
    }
}

fn bench_linearize(c: &mut Criterion) {
    let m = Engine8::published();
    let ss = steady_state(&m, &Drive::new(1500.0, 110.0, 80.0, 75.0)).unwrap();
    let opts = LinearizeOptions::default();
    c.bench_function(
        "linearize 8 states, 7 outputs (Richardson L=1, 49 evals)",
        |b| b.iter(|| linearize_steady(&m, black_box(&ss), &opts).unwrap()),
    );
    c.bench_function("linearize, thread CPU time", |b| {
        b.iter_custom(|iters| {
            cpu_time(|| {
                for _ in 0..iters {
                    black_box(linearize_steady(&m, black_box(&ss), &opts).unwrap());
                }
            })
        })
    });
    let plain = LinearizeOptions {
        richardson: 0,
        ..LinearizeOptions::default()
    };
    c.bench_function("linearize, plain central differences (25 evals)", |b| {
        b.iter(|| linearize_steady(&m, black_box(&ss), &plain).unwrap())
    });
}

fn bench_zeros(c: &mut Criterion) {
    let m = Engine8::published();
    let ss = steady_state(&m, &Drive::new(1500.0, 110.0, 80.0, 75.0)).unwrap();
    let lin = linearize_steady(&m, &ss, &LinearizeOptions::default()).unwrap();
    let o = ZeroOptions::default();
    c.bench_function("poles (8 states)", |b| {
        b.iter(|| poles(black_box(&lin)).unwrap())
    });
    c.bench_function(
        "SISO channel u_vgt->W_c (minimal realization, zeros, DC gain)",
        |b| b.iter(|| channel(black_box(&lin), "u_vgt->W_c", &o).unwrap()),
    );
    c.bench_function("MIMO zeros 3x3", |b| {
        b.iter(|| mimo_zeros(black_box(&lin), &MIMO_INPUTS, &MIMO_OUTPUTS, &o).unwrap())
    });
}

fn grid_egr_vgt(n: usize) -> Grid {
    Grid::two(
        Drive::new(1500.0, 110.0, 0.0, 0.0),
        Axis::linspace("u_egr", 0.0, 100.0, n),
        Axis::linspace("u_vgt", 20.0, 100.0, n),
    )
    .unwrap()
}

fn grid_speed_load(n: usize) -> Grid {
    Grid::two(
        Drive::new(0.0, 0.0, 50.0, 50.0),
        Axis::linspace("n_e", 500.0, 2000.0, n),
        Axis::linspace("u_delta", 1.0, 250.0, n),
    )
    .unwrap()
}

fn bench_map(c: &mut Criterion) {
    let m = Engine8::published();
    let mut g = c.benchmark_group("maps");
    g.sample_size(10);
    let grid = grid_egr_vgt(20);
    let opts = MapOptions {
        threads: 2,
        ..MapOptions::default()
    };
    g.bench_function("steady-state map 20x20 (u_egr x u_vgt), 2 threads", |b| {
        b.iter(|| steady_map(&m, black_box(&grid), &opts, None).unwrap())
    });
    g.finish();
}

/// One timed run of the 100 x 100 maps (too long for criterion's repeated sampling).
fn maps_100() {
    let m = Engine8::published();
    let opts = MapOptions {
        threads: 2,
        ..MapOptions::default()
    };
    for (name, grid) in [
        ("u_egr x u_vgt at 1500 rpm, 110 mg", grid_egr_vgt(100)),
        (
            "n_e x u_delta at u_egr 50 %, u_vgt 50 %",
            grid_speed_load(100),
        ),
    ] {
        let t = Instant::now();
        let map = steady_map(&m, &grid, &opts, None).unwrap();
        let t_map = t.elapsed();
        let t = Instant::now();
        let gains = dc_gain_map(
            &m,
            &map,
            "u_vgt",
            "W_c",
            &ChannelMapOptions {
                threads: 2,
                ..ChannelMapOptions::default()
            },
            None,
        )
        .unwrap();
        let t_gain = t.elapsed();
        println!(
            "100x100 steady-state map ({name}), 2 threads: {:.2} s wall ({} of {} converged, {} warm-started); u_vgt->W_c DC-gain map: {:.2} s ({} points with a gain)",
            t_map.as_secs_f64(),
            map.converged(),
            map.points.len(),
            map.points.iter().filter(|p| p.warm).count(),
            t_gain.as_secs_f64(),
            gains.iter().filter(|r| r.is_ok()).count()
        );
    }
}

criterion_group!(benches, bench_linearize, bench_zeros, bench_map);

fn main() {
    benches();
    // only under `cargo bench` (criterion's test mode runs each benchmark once)
    if std::env::args().any(|a| a == "--bench") {
        maps_100();
    }
    Criterion::default().configure_from_args().final_summary();
}
