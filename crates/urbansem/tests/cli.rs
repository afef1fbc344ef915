//! The binary end to end: outputs, JSON keys scripts depend on, and exit codes on bad input.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::PathBuf;
use std::process::Command;

fn urbansem() -> Command {
    Command::new(env!("CARGO_BIN_EXE_urbansem"))
}

fn temp_file(name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("urbansem-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn pbo_solve_json_has_the_documented_keys() {
    let f = temp_file(
        "f.opb",
        "* #variable= 4 #constraint= 0\nmin: +3 x1 x2 -2 ~x3 -4 x1 x2 x3 +1 x2 +2 x1 x3 x4 -1 x4 ;\n",
    );
    let out = urbansem()
        .args(["pbo", "solve"])
        .arg(&f)
        .args([
            "--quadratize",
            "asm",
            "--probe",
            "--improve",
            "3",
            "--seed",
            "7",
            "--json",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for key in [
        "energy",
        "lower_bound",
        "labelled_fraction",
        "seconds",
        "assignment",
    ] {
        assert!(v.get(key).is_some(), "missing key {key}");
    }
    for key in ["parse", "quadratize", "solve", "total"] {
        assert!(v["seconds"].get(key).is_some(), "missing seconds.{key}");
    }
    let assignment = v["assignment"].as_object().unwrap();
    assert_eq!(assignment.len(), 4);
    // The energy is that of the returned assignment; with probing this instance is solved.
    let x: Vec<f64> = (1..=4)
        .map(|i| assignment[&format!("x{i}")].as_f64().unwrap())
        .collect();
    let e = 3.0 * x[0] * x[1] - 2.0 * (1.0 - x[2]) - 4.0 * x[0] * x[1] * x[2]
        + x[1]
        + 2.0 * x[0] * x[2] * x[3]
        - x[3];
    assert_eq!(v["energy"].as_f64().unwrap(), e);
    assert!(v["lower_bound"].as_f64().unwrap() <= e);
}

#[test]
fn bad_opb_input_exits_2_with_a_located_message() {
    let cases = [
        ("nan.opb", "min: +3 x1 x2\n +nan x3 ;\n", "nan.opb:2:2"),
        (
            "unknown.opb",
            "* #variable= 2\nmin: +1 x1 +1 x9 ;\n",
            "unknown variable \"x9\"",
        ),
        ("open.opb", "min: +3 x1 x2 x3\n", "not terminated"),
    ];
    for (name, text, expect) in cases {
        let f = temp_file(name, text);
        let out = urbansem().args(["pbo", "solve"]).arg(&f).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{name}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(expect), "{name}: {err}");
        assert!(!err.contains("panicked"), "{name}: {err}");
    }
    let out = urbansem()
        .args(["pbo", "solve", "/nonexistent/x.opb"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
}
