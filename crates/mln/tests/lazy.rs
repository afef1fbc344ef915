//! Lazy grounding is MAP-exact: on random small programs the minimum over the lazily
//! grounded problem equals the minimum over the eagerly grounded one (both by brute force),
//! and the lazy optimum, its left-out atoms false, scores the same on the eager problem.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use mln::ground::{ground, GroundOptions, GroundProblem};
use mln::parse::{parse_evidence, parse_program, parse_query_predicates, Program};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::HashMap;

/// Predicates: three unary, two binary over `t = {A, B}` (14 atoms).
const PREDICATES: [(&str, usize); 5] = [("P", 1), ("Q", 1), ("R", 1), ("S", 2), ("T", 2)];

fn literal(rng: &mut ChaCha8Rng) -> String {
    let (name, arity) = PREDICATES[rng.gen_range(0..PREDICATES.len())];
    let args = if arity == 1 {
        ["x", "y"][rng.gen_range(0..2)].to_owned()
    } else {
        ["x, y", "y, x", "x, x"][rng.gen_range(0..3)].to_owned()
    };
    format!("{}{name}({args})", if rng.gen_bool(0.5) { "!" } else { "" })
}

/// A random program (clauses, implications and conjunctions; soft weights of both signs,
/// some hard) with random evidence.
fn random_case(seed: u64) -> (String, String) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut program = String::from("t = { A, B }\nP(t)\nQ(t)\nR(t)\nS(t, t)\nT(t, t)\n");
    for _ in 0..rng.gen_range(3..=7) {
        let k = rng.gen_range(1..=3);
        let lits: Vec<String> = (0..k).map(|_| literal(&mut rng)).collect();
        let body = match rng.gen_range(0..6) {
            0 if k >= 2 => format!("{} => {}", lits[0], lits[1..].join(" v ")),
            1 if k >= 2 => lits.join(" ^ "),
            _ => lits.join(" v "),
        };
        if rng.gen_bool(0.1) {
            program += &format!("{body}.\n");
        } else {
            let w: f64 = rng.gen_range(-2.0..2.0);
            program += &format!("{w:.3} {body}\n");
        }
    }
    let mut evidence = String::new();
    for _ in 0..rng.gen_range(0..3) {
        let (name, arity) = PREDICATES[rng.gen_range(0..PREDICATES.len())];
        let c = |rng: &mut ChaCha8Rng| ["A", "B"][rng.gen_range(0..2)];
        let args = if arity == 1 {
            c(&mut rng).to_owned()
        } else {
            format!("{}, {}", c(&mut rng), c(&mut rng))
        };
        let neg = if rng.gen_bool(0.3) { "!" } else { "" };
        evidence += &format!("{neg}{name}({args})\n");
    }
    (program, evidence)
}

fn grounded(program: &Program, evidence: &str, lazy: bool) -> GroundProblem {
    let e = parse_evidence(evidence, "e.db", program).unwrap();
    let q = parse_query_predicates("P,Q,R,S,T", program).unwrap();
    let options = GroundOptions {
        lazy,
        ..GroundOptions::default()
    };
    ground(program, &e, "e.db", &q, &options).unwrap()
}

/// (hard violations, violated weight) of the best assignment, and the assignment.
fn brute_force(p: &GroundProblem) -> ((usize, f64), Vec<bool>) {
    let n = p.atoms.len();
    assert!(n <= 16, "{n} atoms");
    let mut best = ((usize::MAX, f64::INFINITY), Vec::new());
    for bits in 0..1u32 << n {
        let x: Vec<bool> = (0..n).map(|i| bits >> i & 1 == 1).collect();
        let s = p.score(&x);
        let key = (s.hard_violations, s.violated_weight);
        if key.0 < best.0 .0 || (key.0 == best.0 .0 && key.1 < best.0 .1 - 1e-9) {
            best = (key, x);
        }
    }
    best
}

#[test]
fn lazy_grounding_keeps_the_map_optimum_of_random_programs() {
    let mut lazier = 0;
    for seed in 0..200u64 {
        let (text, evidence) = random_case(seed);
        let program = parse_program(&text, "r.mln").unwrap();
        let eager = grounded(&program, &evidence, false);
        let lazy = grounded(&program, &evidence, true);
        let (eager_best, _) = brute_force(&eager);
        let (lazy_best, x) = brute_force(&lazy);
        assert_eq!(eager_best.0, lazy_best.0, "seed {seed}\n{text}{evidence}");
        assert!(
            (eager_best.1 - lazy_best.1).abs() < 1e-9,
            "seed {seed}: eager {eager_best:?} lazy {lazy_best:?}\n{text}{evidence}"
        );
        // The lazy optimum with the left-out atoms false scores the same on the eager problem.
        let by_name: HashMap<String, bool> = (0..lazy.atoms.len())
            .map(|i| (lazy.atom_name(&program, i), x[i]))
            .collect();
        let full: Vec<bool> = (0..eager.atoms.len())
            .map(|i| by_name.get(&eager.atom_name(&program, i)).copied() == Some(true))
            .collect();
        let s = eager.score(&full);
        assert_eq!(s.hard_violations, lazy_best.0, "seed {seed}");
        assert!(
            (s.violated_weight - lazy_best.1).abs() < 1e-9,
            "seed {seed}"
        );
        if !lazy.inactive_predicates.is_empty() {
            lazier += 1;
        }
    }
    // The closure leaves predicates out often enough for the comparison to mean something.
    assert!(
        lazier >= 50,
        "{lazier} of 200 programs had inactive predicates"
    );
}
