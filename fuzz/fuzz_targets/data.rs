//! Fuzz the measurement data loaders of `mvem::tuning::data`: the stationary CSV, the dynamic
//! CSV (all three step kinds) and the campaign manifest (TOML). The first byte picks the loader,
//! the rest is the file. Any bytes must give data or a clear error, never a panic; accepted data
//! must round-trip through the writers (`stationary_csv`, `dynamic_csv`, TOML) exactly.
#![no_main]
use libfuzzer_sys::fuzz_target;
use mvem::tuning::data::{
    dynamic_csv, parse_dynamic_csv, parse_manifest, parse_stationary_csv, stationary_csv,
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
            if let Ok(p) = parse_stationary_csv(&text, Path::new("fuzz.csv")) {
                let back = parse_stationary_csv(&stationary_csv(&p), Path::new("rt.csv"))
                    .expect("stationary round trip");
                assert_eq!(back, p);
            }
        }
        1..=3 => {
            let kind = [StepKind::VgtEgr, StepKind::Fuel, StepKind::Actuator][sel as usize % 5 - 1];
            if let Ok(d) = parse_dynamic_csv(&text, Path::new("fuzz.csv"), "X", kind) {
                let back = parse_dynamic_csv(&dynamic_csv(&d), Path::new("rt.csv"), "X", kind)
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
