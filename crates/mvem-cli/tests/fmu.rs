//! `mvem fmu`: packaging, configuration in resources/, and usage errors. (The FMU itself is
//! run by FMPy in tests/python/test_fmu.py, which needs the real shared library.)

use mvem::model::{CylinderTemp, ModelOrder};
use mvem::params::Params;
use mvem_fmu::vars::{guid, FmuConfig};
use std::path::Path;
use std::process::{Command, Output};

fn mvem(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mvem"))
        .args(args)
        .current_dir(dir)
        .env_remove("MVEM_FMU_LIB")
        .output()
        .expect("run mvem")
}

/// The stored (uncompressed) entries of a zip archive written by `mvem fmu`: name -> bytes.
fn entries(zip: &[u8]) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut i = 0;
    while zip[i..].starts_with(&[0x50, 0x4b, 0x03, 0x04]) {
        let u16_at = |k: usize| u16::from_le_bytes([zip[i + k], zip[i + k + 1]]) as usize;
        let size = u32::from_le_bytes(zip[i + 18..i + 22].try_into().unwrap()) as usize;
        let (n, extra) = (u16_at(26), u16_at(28));
        let name = String::from_utf8(zip[i + 30..i + 30 + n].to_vec()).unwrap();
        let start = i + 30 + n + extra;
        out.push((name, zip[start..start + size].to_vec()));
        i = start + size;
    }
    out
}

#[test]
fn fmu_archive_holds_description_library_and_configuration() {
    let dir = tempfile::tempdir().unwrap();
    // a stand-in for libmvem_fmu.so: the packager only copies it
    let lib = dir.path().join("libfake.so");
    std::fs::write(&lib, b"\x7fELF fake shared library").unwrap();
    let o = mvem(
        dir.path(),
        &[
            "fmu",
            "--out",
            "m.fmu",
            "--model",
            "12",
            "--cylinder-temp",
            "one-iteration",
            "--lib",
            lib.to_str().unwrap(),
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let zip = std::fs::read(dir.path().join("m.fmu")).unwrap();
    let e = entries(&zip);
    let names: Vec<&str> = e.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(
        names,
        [
            "modelDescription.xml",
            "binaries/linux64/mvem.so",
            "resources/mvem.json"
        ]
    );
    assert_eq!(e[1].1, b"\x7fELF fake shared library");
    let cfg = FmuConfig::from_json(std::str::from_utf8(&e[2].1).unwrap()).unwrap();
    assert_eq!(cfg.order, ModelOrder::Twelve);
    assert_eq!(cfg.cylinder_temp, CylinderTemp::OneIteration);
    assert_eq!(cfg.params, Params::published());
    let xml = String::from_utf8(e[0].1.clone()).unwrap();
    assert!(xml.contains(&format!("guid=\"{}\"", guid(&cfg))));
    assert!(xml.contains(r#"name="der(T_ic)""#));
    assert!(
        !xml.contains("<ModelExchange"),
        "one-iteration: Co-Simulation only"
    );
}

#[test]
fn fmu_usage_errors_exit_2_without_output() {
    let dir = tempfile::tempdir().unwrap();
    let notelf = dir.path().join("lib.so");
    std::fs::write(&notelf, b"text").unwrap();
    for (args, msg) in [
        (
            vec!["--out", "x.fmu", "--lib", "/nonexistent/libmvem_fmu.so"],
            "not found",
        ),
        (
            vec!["--out", "x.fmu", "--lib", notelf.to_str().unwrap()],
            "not an ELF",
        ),
        (vec!["--out", "x.fmu", "--model", "9"], "invalid value '9'"),
        (vec!["--out", "nodir/x.fmu"], "does not exist"),
    ] {
        let mut a = vec!["fmu"];
        a.extend(args);
        let o = mvem(dir.path(), &a);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{a:?}: {err}");
        assert!(err.contains(msg), "{a:?}: {err}");
        assert!(!dir.path().join("x.fmu").exists());
    }
}
