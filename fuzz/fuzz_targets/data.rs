//! Fuzz the measurement data loaders of `mvem::tuning::data`: the stationary CSV, the dynamic
//! CSV (all three step kinds) and the campaign manifest (TOML). The first byte picks the loader,
//! the rest is the file. Any bytes must give data or a clear error, never a panic; accepted data
//! must round-trip through the writers (`stationary_csv`, `dynamic_csv`, TOML) exactly.
#![no_main]
use libfuzzer_sys::fuzz_target;
use mvem::tuning::data::{
    dynamic_csv, parse_dynamic_csv, parse_manifest, parse_stationary_csv, stationary_csv, Layout,
    StepKind,
};
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let Some((&sel, rest)) = data.split_first() else {
        return;
    };
    let text = String::from_utf8_lossy(rest);
    match sel % 5 {
        0 => {
            let l = Layout::default();
            if let Ok(p) = parse_stationary_csv(&text, Path::new("fuzz.csv"), &l) {
                let back = parse_stationary_csv(&stationary_csv(&p), Path::new("rt.csv"), &l)
                    .expect("stationary round trip");
                // the same values; a missing (optional) T_t is NaN in both
                assert_eq!(back.len(), p.len());
                for (a, b) in back.iter().zip(&p) {
                    for (x, y) in a.values().iter().zip(b.values()) {
                        assert!(x == &y || (x.is_nan() && y.is_nan()), "{x} vs {y}");
                    }
                }
            }
        }
        1..=3 => {
            let kind = [StepKind::VgtEgr, StepKind::Fuel, StepKind::Actuator][sel as usize % 5 - 1];
            let l = Layout::default();
            if let Ok(d) = parse_dynamic_csv(&text, Path::new("fuzz.csv"), "X", kind, &l) {
                let back = parse_dynamic_csv(&dynamic_csv(&d), Path::new("rt.csv"), "X", kind, &l)
                    .expect("dynamic round trip");
                assert_eq!(back, d);
            }
        }
        _ => {
            if let Ok(m) = parse_manifest(&text, Path::new("manifest.toml")) {
                let s = toml::to_string(&m).expect("manifest serializes");
                let back = parse_manifest(&s, Path::new("rt.toml")).expect("manifest round trip");
                assert_eq!(back, m);
            }
        }
    }
});
