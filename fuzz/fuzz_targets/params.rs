//! Fuzz the parameter reader (TOML, nested JSON, the authors' flat JSON): any bytes must give
//! validated parameters or a clear error, never a panic; accepted parameters must round-trip.
#![no_main]
use libfuzzer_sys::fuzz_target;
use mvem::io::params::{parse_params, to_json, to_toml};
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    if let Ok(p) = parse_params(&text, Path::new("fuzz.toml")) {
        let back = parse_params(&to_toml(&p), Path::new("rt.toml")).expect("TOML round trip");
        assert_eq!(back, p);
        let back = parse_params(&to_json(&p), Path::new("rt.json")).expect("JSON round trip");
        assert_eq!(back, p);
    }
});
