//! Every MLN benchmark program, evidence and query file in `../shared/data/mln` parses.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use mln::parse::{read_evidence, read_program, read_query, Program};
use std::path::PathBuf;

fn data(rel: &str) -> PathBuf {
    let p = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/mln"
    ))
    .join(rel);
    assert!(p.exists(), "missing benchmark file {}", p.display());
    p
}

fn load(dir: &str, prog: &str, evidence: &[&str], query: Option<&str>) -> Program {
    let program = read_program(&data(&format!("{dir}/{prog}"))).unwrap_or_else(|e| panic!("{e}"));
    assert!(!program.formulas.is_empty(), "{dir}: no formulas");
    for ev in evidence {
        let atoms = read_evidence(&data(&format!("{dir}/{ev}")), &program)
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(!atoms.is_empty(), "{dir}/{ev}: no evidence");
    }
    if let Some(q) = query {
        let atoms =
            read_query(&data(&format!("{dir}/{q}")), &program).unwrap_or_else(|e| panic!("{e}"));
        assert!(!atoms.is_empty(), "{dir}/{q}: no query atoms");
    }
    program
}

#[test]
fn smokers_variants() {
    let p = load(
        "smoke/tuffy",
        "prog.mln",
        &["evidence.db"],
        Some("query.db"),
    );
    assert_eq!(p.formulas.len(), 3);
    load(
        "smoke/pracmln",
        "smoking.mln",
        &["smoking-train.db", "smoking-test.db"],
        None,
    );
    load(
        "smoke/pracmln",
        "wts.pybpll.smoking-train-smoking.mln",
        &[],
        None,
    );
    load("smoke/lomrf", "smoking.mln", &["smoking-train.db"], None);
    load("smoke/alchemy2", "model.mln", &["evidence.db"], None);
}

#[test]
fn link_prediction() {
    let p = load("lp/tuffy", "prog.mln", &["evidence.db"], Some("query.db"));
    assert_eq!(p.predicates.len(), 22);
    load("lp/rockit", "prog.mln", &["evidence.db"], Some("query.db"));
}

#[test]
fn relational_classification() {
    load("rc/rockit", "prog.mln", &["evidence.db"], Some("query.db"));
    load(
        "rc/tuffy-class",
        "prog.mln",
        &["evidence.db"],
        Some("query.db"),
    );
    load(
        "rc/tuffy-rc1000",
        "prog.mln",
        &["evidence.db"],
        Some("query.db"),
    );
}

#[test]
fn web_kb() {
    load("kb/mlcnn", "prog.mln", &["evidence.db"], Some("query.db"));
    load("kb/alchemy2-toy", "webkb.mln", &[], None);
}

#[test]
fn information_extraction_entity_resolution_protein() {
    let ie = load("ie/tuffy", "prog.mln", &[], Some("query.db"));
    assert!(ie.formulas.len() > 900);
    load("ie/rockit", "prog.mln", &[], Some("query.db"));
    load("er/rockit", "prog.mln", &["evidence.db"], Some("query.db"));
    load("pr/rockit", "prog.mln", &["evidence.db"], Some("query.db"));
}
