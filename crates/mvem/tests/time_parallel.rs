//! Time-parallel integration of one open-loop simulation (`SimOptions::time_chunks`): against
//! the sequential run on the first 400 s of the WHTC (the same rows and columns, the states
//! within a tenth of a tolerance unit, chunk 0 bit for bit), a guess bad enough that the junction
//! check fails and the chunk is integrated again (the statistics say so, the result still
//! agrees), a chunk whose run fails, a model holding memory (sequential), a streamed
//! (deferred-signal) run, and a failure reported as the sequential run reports it.

use mvem::analysis::steady::{chunk_guess, simulate_from_steady, steady_state};
use mvem::model::{CylinderTemp, Engine10, Engine12, Engine8, Model, ModelOptions};
use mvem::sim::{
    simulate, simulate_into_with_guess, simulate_with_guess, Block, InputSchedule, SignalEvaluator,
    SimError, SimOptions, Solution, Start, JUNCTION_TOL,
};

const T_END: f64 = 400.0;

fn whtc() -> InputSchedule {
    let text = include_str!("../../../data/whtc_inputs_10hz.csv");
    mvem::io::csv_inputs::parse_inputs_csv(text, std::path::Path::new("whtc")).unwrap()
}

fn opts(chunks: usize) -> SimOptions {
    SimOptions {
        dt_out: 0.1,
        time_chunks: chunks,
        ..SimOptions::default()
    }
}

/// Largest difference of the states of `a` and `b` in tolerance units (|dy_i| / (atol scale_i
/// + rtol |y_i|)) over all samples, and the number of leading samples that are bitwise equal.
fn state_units<const N: usize, M: Model<N>>(
    m: &M,
    a: &Solution,
    b: &Solution,
    o: &SimOptions,
) -> (f64, usize) {
    assert_eq!(a.names, b.names);
    assert_eq!(a.len(), b.len());
    assert!(a.t() == b.t(), "output times differ");
    let scales = m.state_scales();
    let mut worst = 0.0f64;
    for (i, name) in m.state_names().iter().enumerate() {
        let (ya, yb) = (a.get(name).unwrap(), b.get(name).unwrap());
        for (p, q) in ya.iter().zip(yb) {
            let d = (p - q).abs() / (o.atol * scales[i] + o.rtol * p.abs().max(q.abs()));
            worst = worst.max(d);
        }
    }
    let same = (0..a.len())
        .take_while(|&r| a.columns.iter().zip(&b.columns).all(|(x, y)| x[r] == y[r]))
        .count();
    (worst, same)
}

fn agrees_with_sequential<const N: usize, M: Model<N>>(m: &M) {
    let sched = whtc();
    let seq = simulate_from_steady(m, &sched, 0.0, T_END, &opts(1)).unwrap();
    assert_eq!(seq.stats.chunks, 0);
    assert!(seq.junctions.is_empty());
    for k in [2, 3] {
        let o = opts(k);
        let par = simulate_from_steady(m, &sched, 0.0, T_END, &o).unwrap();
        let st = par.stats;
        assert_eq!(st.chunks, k, "{N} states, {k} chunks");
        assert_eq!(
            st.chunks_rerun, 0,
            "{N} states, {k} chunks: {:?}",
            par.junctions
        );
        assert_eq!(par.junctions.len(), k - 1);
        assert!(par
            .junctions
            .iter()
            .all(|j| j.accepted && j.diff <= JUNCTION_TOL));
        // measured: junctions below 1e-5 units on this stretch
        assert!(
            st.junction_max < 1e-3,
            "{N} states, {k} chunks: {:?}",
            par.junctions
        );
        assert_eq!(st.outputs, seq.len());
        // the warm-ups are extra work, about their share of the time (the cycle's density of
        // stops varies: up to 1.5 times that)
        assert!(st.rhs_evals > seq.stats.rhs_evals);
        let warm = (k - 1) as f64 * o.chunk_overlap / T_END;
        assert!(
            (st.rhs_evals as f64) < (1.0 + 1.5 * warm) * seq.stats.rhs_evals as f64,
            "{} against {}",
            st.rhs_evals,
            seq.stats.rhs_evals
        );
        let (units, same) = state_units(m, &seq, &par, &o);
        // chunk 0 is the sequential run: every sample before the first junction is the same
        let first = par.junctions[0].t;
        let before = seq.t().iter().filter(|t| **t < first - 1e-9).count();
        assert!(
            same >= before,
            "{same} equal rows, {before} before {first} s"
        );
        assert!(
            units <= 0.1,
            "{N} states, {k} chunks: {units} tolerance units"
        );
        // the signals follow the states (the same function of the same values to rounding)
        for name in ["W_c", "M_e", "lambda_O"] {
            let (a, b) = (seq.get(name).unwrap(), par.get(name).unwrap());
            let worst = a
                .iter()
                .zip(b)
                .map(|(x, y)| (x - y).abs() / x.abs().max(1e-3))
                .fold(0.0, f64::max);
            assert!(worst < 1e-5, "{name}: relative {worst:e}");
        }
        // deterministic: the chunks' results do not depend on the threads' timing
        let again = simulate_from_steady(m, &sched, 0.0, T_END, &o).unwrap();
        assert!(again == par);
    }
}

#[test]
fn time_parallel_agrees_with_sequential_8() {
    agrees_with_sequential(&Engine8::published());
}

#[test]
fn time_parallel_agrees_with_sequential_10_12() {
    agrees_with_sequential(&Engine10::published());
    agrees_with_sequential(&Engine12::published());
}

/// A guess far from the trajectory and a warm-up too short to forget it: the junction check
/// fails, the previous chunk's integrator goes on, and the result is the sequential one.
#[test]
fn bad_guess_fails_the_junction_and_is_rerun() {
    let m = Engine8::published();
    let sched = whtc();
    let x0 = steady_state(&m, &sched.at(0.0)).unwrap().x;
    let seq = simulate(&m, &sched, 0.0, T_END, Start::State(x0), &opts(1)).unwrap();
    let o = SimOptions {
        chunk_overlap: 0.5,
        ..opts(2)
    };
    // the steady state at full load: p_im about 3e5 Pa where the cycle has about 1e5
    let far = steady_state(&m, &mvem::model::Drive::new(1800.0, 220.0, 0.0, 30.0))
        .unwrap()
        .x;
    let bad = |_t: f64| Some(far);
    let par =
        simulate_with_guess(&m, &sched, 0.0, T_END, Start::State(x0), &o, Some(&bad)).unwrap();
    assert_eq!(par.stats.chunks, 2);
    assert_eq!(par.stats.chunks_rerun, 1);
    let j = par.junctions[0];
    assert!(!j.accepted && j.diff > 100.0 * JUNCTION_TOL, "{j:?}");
    assert_eq!(par.stats.junction_max, j.diff);
    assert_eq!(par.stats.outputs, seq.len());
    let (units, _) = state_units(&m, &seq, &par, &o);
    assert!(units <= 0.1, "{units} tolerance units");

    // the same split with the steady-state guess and the default 30 s warm-up passes
    let guess = chunk_guess(&m, &sched);
    let good = simulate_with_guess(
        &m,
        &sched,
        0.0,
        T_END,
        Start::State(x0),
        &opts(2),
        Some(&guess),
    )
    .unwrap();
    assert_eq!(good.stats.chunks_rerun, 0);
    assert!(good.junctions[0].diff <= JUNCTION_TOL);

    // a guess the integrator refuses (not finite): the chunk's run fails, it is rerun
    let nan = |_t: f64| Some([f64::NAN; 8]);
    let par =
        simulate_with_guess(&m, &sched, 0.0, T_END, Start::State(x0), &o, Some(&nan)).unwrap();
    assert_eq!(par.stats.chunks_rerun, 1);
    assert_eq!(par.junctions[0].diff, f64::INFINITY);
    assert_eq!(par.stats.junction_max, f64::INFINITY);
    let (units, _) = state_units(&m, &seq, &par, &o);
    assert!(units <= 0.1, "{units} tolerance units");
}

/// The 8-state engine with the one-iteration cylinder temperature (a model holding memory).
fn one_iteration_engine() -> Engine8 {
    Engine8::new(
        Engine8::published().params().clone(),
        ModelOptions {
            cylinder_temp: CylinderTemp::OneIteration,
            ..ModelOptions::default()
        },
    )
    .unwrap()
}

/// A model holding memory between steps (one-iteration cylinder temperature) is integrated
/// sequentially: bit for bit the run without chunks.
#[test]
fn memory_holding_model_is_sequential() {
    let m = one_iteration_engine();
    assert!(Model::holds_memory(&m));
    let sched = whtc();
    let seq = simulate_from_steady(&m, &sched, 0.0, 100.0, &opts(1)).unwrap();
    let par = simulate_from_steady(&m, &sched, 0.0, 100.0, &opts(4)).unwrap();
    assert_eq!(par.stats.chunks, 0);
    assert!(par.junctions.is_empty());
    assert!(par == seq, "not the sequential run");
}

/// Streamed with the signals evaluated by the receiver (`Solution::streaming_deferred`, the
/// CLI's path): the same columns and bits as the kept time-parallel solution.
#[test]
fn streamed_time_parallel_equals_kept() {
    let m = Engine8::published();
    let sched = whtc();
    let o = opts(2);
    let x0 = steady_state(&m, &sched.at(0.0)).unwrap().x;
    let guess = chunk_guess(&m, &sched);
    let kept =
        simulate_with_guess(&m, &sched, 0.0, T_END, Start::State(x0), &o, Some(&guess)).unwrap();
    assert_eq!(kept.stats.chunks, 2);
    let (tx, rx) = std::sync::mpsc::sync_channel::<Block>(2);
    let mut eval = SignalEvaluator::new(&m);
    let (streamed, columns) = std::thread::scope(|s| {
        let writer = s.spawn(|| {
            let mut cols: Vec<Vec<f64>> = vec![Vec::new(); kept.names.len()];
            let mut sizes = Vec::new();
            for raw in rx {
                let b = eval.block(raw);
                sizes.push(b[0].len());
                for (c, v) in cols.iter_mut().zip(b) {
                    c.extend(v);
                }
            }
            (cols, sizes)
        });
        let into = Solution::streaming_deferred(&m, 300, tx);
        let sol = simulate_into_with_guess(
            &m,
            &sched,
            0.0,
            T_END,
            Start::State(x0),
            &o,
            into,
            Some(&guess),
        )
        .unwrap();
        (sol, writer.join().unwrap())
    });
    let (cols, sizes) = columns;
    assert_eq!(streamed.stats, kept.stats);
    assert_eq!(streamed.junctions, kept.junctions);
    assert!(streamed.is_empty() && !streamed.is_streaming());
    // full blocks but the last, also across the junction
    assert!(
        sizes[..sizes.len() - 1].iter().all(|n| *n == 300),
        "{sizes:?}"
    );
    assert!(
        cols == kept.columns,
        "streamed columns differ from the kept ones"
    );
    assert_eq!(eval.guards_seen(), kept.guards_seen);
}

/// A failure in chunk 0 is the sequential run's failure: the same error, time and state.
#[test]
fn failure_is_reported_as_sequential() {
    let m = Engine8::published();
    let sched = whtc();
    let few = |k| SimOptions {
        max_steps: 3000,
        ..opts(k)
    };
    let seq = simulate_from_steady(&m, &sched, 0.0, T_END, &few(1)).unwrap_err();
    let par = simulate_from_steady(&m, &sched, 0.0, T_END, &few(2)).unwrap_err();
    assert_eq!(seq, par);
    let text = par.to_string();
    assert!(text.contains("3000"), "{text}");
    // bad options are refused before anything runs
    let bad = SimOptions {
        time_chunks: 0,
        ..opts(1)
    };
    assert!(matches!(
        simulate(&m, &sched, 0.0, 10.0, Start::State([1e5; 8]), &bad),
        Err(SimError::BadOption {
            field: "time_chunks",
            ..
        })
    ));
}

/// Kept with the signals evaluated after the run (`Solution::deferred`, what `mvem bench`
/// times, as the CVODE peer stores only its states): the same columns, bits, statistics and
/// guards as `simulate`, sequential and in 2 chunks; before `with_signals` only `t` and the
/// states can be read. A model holding memory gets the ordinary solution.
#[test]
fn deferred_signals_equal_simulate() {
    let m = Engine8::published();
    let sched = whtc();
    let x0 = steady_state(&m, &sched.at(0.0)).unwrap().x;
    let guess = chunk_guess(&m, &sched);
    for chunks in [1, 2] {
        let o = opts(chunks);
        let kept = simulate_with_guess(&m, &sched, 0.0, T_END, Start::State(x0), &o, Some(&guess))
            .unwrap();
        let raw = simulate_into_with_guess(
            &m,
            &sched,
            0.0,
            T_END,
            Start::State(x0),
            &o,
            Solution::deferred(&m),
            Some(&guess),
        )
        .unwrap();
        assert_eq!(raw.len(), kept.len());
        assert_eq!(raw.get("p_em"), kept.get("p_em"));
        assert!(raw.get("W_c").is_none() && raw.get("M_e").is_none());
        assert_eq!(raw.row(7).len(), 1 + 8);
        let full = raw.with_signals(&m);
        assert!(full == kept, "{chunks} chunks: not the kept solution");
        assert_eq!(full.stats.chunks, kept.stats.chunks);
        assert!(full.get("W_c").is_some());
    }
    let mem = one_iteration_engine();
    let d = Solution::deferred(&mem);
    assert!(
        d.get("W_c").is_some(),
        "a memory-holding model keeps its signal columns"
    );
}
