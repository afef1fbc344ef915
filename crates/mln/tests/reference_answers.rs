//! Issue 7: our MAP answers cost no more than Tuffy's shipped MAP answers on every set that
//! ships one (LP, ER, KB), both scored by our evaluator on the same ground problem.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use mln::files::read_answer;
use mln::ground::{ground, GroundOptions};
use mln::infer::{map_inference, InferOptions};
use mln::parse::{read_evidence, read_program, read_query};
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

/// (our cost, the reference answer's cost, our hard violations, the reference's).
fn costs(dir: &str, program: &str, reference: &str) -> (f64, f64, usize, usize) {
    let program = read_program(&data(&format!("{dir}/{program}"))).unwrap();
    let evidence_path = data(&format!("{dir}/evidence.db"));
    let evidence = read_evidence(&evidence_path, &program).unwrap();
    let query = read_query(&data(&format!("{dir}/query.db")), &program).unwrap();
    let problem = ground(
        &program,
        &evidence,
        &evidence_path.display().to_string(),
        &query,
        &GroundOptions::default(),
    )
    .unwrap();
    let ours = map_inference(&problem, &InferOptions::default()).scores;
    let x = read_answer(&program, &problem, &data(reference))
        .unwrap()
        .assignment;
    let theirs = problem.score(&x);
    (
        ours.cost,
        theirs.cost,
        ours.hard_violations,
        theirs.hard_violations,
    )
}

fn check(dir: &str, program: &str, reference: &str) {
    let (ours, theirs, our_hard, their_hard) = costs(dir, program, reference);
    assert!(
        our_hard <= their_hard,
        "{dir}: {our_hard} hard violations vs {their_hard}"
    );
    assert!(
        ours <= theirs + 1e-6,
        "{dir}: our MAP cost {ours} is worse than Tuffy's answer {theirs}"
    );
}

#[test]
fn issue_7_link_prediction_beats_tuffy() {
    check(
        "lp/rockit",
        "prog.mln",
        "lp/reference_outputs/tuffy_map_output_from_xeggora.db",
    );
}

#[test]
fn issue_7_entity_resolution_beats_tuffy() {
    check(
        "er/rockit",
        "prog.mln",
        "er/reference_outputs/tuffy_map_output_from_xeggora.db",
    );
}

#[test]
fn issue_7_webkb_beats_tuffy() {
    check(
        "kb/mlcnn",
        "prog.mln",
        "kb/reference_outputs/tuffy_map_output_from_mlcnn.txt",
    );
}
