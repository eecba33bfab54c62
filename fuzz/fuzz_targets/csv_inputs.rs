//! Fuzz the input-CSV reader: any bytes must give a schedule or a clear error, never a panic;
//! an accepted schedule must be usable (evaluation, breakpoints, range warnings).
#![no_main]
use libfuzzer_sys::fuzz_target;
use mvem::io::csv_inputs::{parse_inputs_csv, range_warnings, INPUT_RANGES};
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    if let Ok(s) = parse_inputs_csv(&text, Path::new("fuzz.csv")) {
        let (a, b) = (s.t_first(), s.t_last());
        for k in 0..=4 {
            let t = a + (b - a) * k as f64 / 4.0;
            let d = s.at(t);
            assert!(d.to_array().iter().all(|v| v.is_finite()));
        }
        for c in 0..4 {
            let _ = s.breakpoints(c);
        }
        let _ = range_warnings(&s, &INPUT_RANGES);
    }
});
