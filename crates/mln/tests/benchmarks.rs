//! Every MLN benchmark program, evidence and query file in `../shared/data/mln` parses, and
//! the two sets the project rebuilds from it (IE's evidence, KB3) ground and learn.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use mln::generate::{ie_evidence_from_mfoilp, kb3, Kb3Options};
use mln::ground::{ground, GroundOptions};
use mln::learn::{learn_weights, training_problem, LearnOptions};
use mln::parse::{
    parse_evidence, parse_program, parse_query, read_evidence, read_program, read_query, Program,
};
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

fn text(rel: &str) -> String {
    std::fs::read_to_string(data(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

#[test]
fn information_extraction_rebuilt_evidence_grounds_as_the_thesis_instance() {
    let dir = "ie/partial-evidence-mfoilp";
    let evidence = ie_evidence_from_mfoilp(
        &text(&format!("{dir}/tokens")),
        &text(&format!("{dir}/similartitles")),
        &text(&format!("{dir}/jntinfcandidates")),
    )
    .unwrap();
    let program = read_program(&data("ie/tuffy/prog.mln")).unwrap();
    let ev = parse_evidence(&evidence, "ie-evidence.db", &program).unwrap();
    let query = read_query(&data("ie/tuffy/query.db"), &program).unwrap();
    let p = ground(
        &program,
        &ev,
        "ie-evidence.db",
        &query,
        &GroundOptions::default(),
    )
    .unwrap();
    // Thesis Table 3.2: 336 670 = 514² SameBib + 514 citations · 3 fields · 47 positions.
    assert_eq!(p.atoms.len(), 336_670);
    assert_eq!(p.higher_order_factors(), 0);
}

#[test]
fn kb3_weights_learnt_on_the_labelled_pages_beat_zero_weights() {
    let k = kb3(
        &text("kb/mlcnn/evidence.db"),
        &text("kb/mlcnn/labels.db"),
        &Kb3Options::default(),
        0,
    )
    .unwrap();
    let program = parse_program(&k.files.program, "kb3.mln").unwrap();
    let db = parse_evidence(&k.training, "training.db", &program).unwrap();
    let query = parse_query(&k.files.query, "query.db", &program).unwrap();
    let t = training_problem(&program, &db, "training.db", &query).unwrap();
    assert_eq!(t.labels_unused, 0);
    assert!(t.problem.higher_order_factors() > 0);
    let learnt = learn_weights(&program, &t, &LearnOptions::default()).unwrap();
    let start = learnt.epochs[0].errors;
    assert!(
        (learnt.final_errors as f64) < 0.8 * start as f64,
        "{} -> {}",
        start,
        learnt.final_errors
    );
}

/// RockIt's protein interaction set (PR): refused by eager grounding (interaction's 3.1
/// million atoms times 42 functions), it grounds lazily to Tuffy's 69 887 atoms, and MAP
/// inference reaches the cost of Tuffy's answer (re-scored here) or better.
#[test]
fn protein_interaction_grounds_lazily_and_reaches_tuffys_cost() {
    use mln::files::{load_and_ground, read_answer, ProblemFiles, QuerySource};
    use mln::infer::{map_inference, InferOptions};
    let files = ProblemFiles {
        program: data("pr/rockit/prog.mln"),
        evidence: vec![data("pr/rockit/evidence.db")],
        query: QuerySource::File(data("pr/rockit/query.db")),
    };
    let loaded = load_and_ground(&files, &GroundOptions::map()).unwrap();
    let p = &loaded.problem;
    assert_eq!(p.atoms.len(), 69_887);
    let names: Vec<&str> = p
        .inactive_predicates
        .iter()
        .map(|&i| loaded.program.predicates[i].name.as_str())
        .collect();
    assert_eq!(names, ["interaction"]);
    let tuffy = read_answer(
        &loaded.program,
        p,
        &data("pr/reference_outputs/tuffy_map_output_from_xeggora.db"),
    )
    .unwrap();
    assert_eq!(tuffy.lazily_false, 0);
    let tuffy_cost = p.score(&tuffy.assignment).cost;
    let r = map_inference(p, &InferOptions::default());
    assert_eq!(r.scores.hard_violations, 0);
    assert!(
        r.scores.cost <= tuffy_cost + 1e-6,
        "{} vs Tuffy's {tuffy_cost}",
        r.scores.cost
    );
}
