//! MC-SAT marginals against exact enumeration: random ground problems (soft and hard
//! formulas, conjunctions of clauses, negative weights) and small MLN programs, with the
//! default options (issue 20: max abs. error ≤ 0.03 for ≤ 16 unknown atoms).

#![allow(clippy::unwrap_used, clippy::expect_used)]

use mln::ground::{ground, GroundAtom, GroundFactor, GroundOptions, GroundProblem};
use mln::marginal::{exact_marginals, mc_sat, MarginalError, McSatOptions};
use mln::parse::{parse_evidence, parse_program, parse_query};
use pbo::polynomial::{Literal, Polynomial};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn problem(n: usize, factors: Vec<GroundFactor>) -> GroundProblem {
    GroundProblem {
        constants: Vec::new(),
        atoms: (0..n)
            .map(|i| GroundAtom {
                predicate: 0,
                args: vec![i as u32].into_boxed_slice(),
            })
            .collect(),
        factors,
        cost: Polynomial::new(n),
        hard_weight: 100.0,
        constant_violated_weight: 0.0,
        constant_hard_violations: 0,
        inactive_predicates: Vec::new(),
    }
}

fn factor(weight: f64, hard: bool, clauses: Vec<Vec<Literal>>) -> GroundFactor {
    GroundFactor {
        weight,
        hard,
        formula: 0,
        clauses,
    }
}

/// A random problem: `n` atoms, soft formulas of one or two clauses of 1–3 literals with
/// weights in [−3, 3], and a few hard clauses that a random world satisfies (so it is
/// satisfiable).
fn random_problem(seed: u64, n: usize) -> GroundProblem {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let clause = |rng: &mut ChaCha8Rng| -> Vec<Literal> {
        (0..rng.gen_range(1..=3))
            .map(|_| Literal::new(rng.gen_range(0..n as u32), rng.gen_bool(0.5)))
            .collect()
    };
    let mut factors = Vec::new();
    for _ in 0..rng.gen_range(n..=2 * n) {
        let clauses = (0..rng.gen_range(1..=2))
            .map(|_| clause(&mut rng))
            .collect();
        factors.push(factor(rng.gen_range(-3.0..3.0), false, clauses));
    }
    let witness: Vec<bool> = (0..n).map(|_| rng.gen_bool(0.5)).collect();
    let mut hard = 0;
    while hard < n / 4 {
        let c = clause(&mut rng);
        if c.len() >= 2 && c.iter().any(|l| l.eval(witness[l.var() as usize])) {
            factors.push(factor(100.0, true, vec![c]));
            hard += 1;
        }
    }
    problem(n, factors)
}

fn max_error(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn mc_sat_matches_exact_marginals_on_random_problems() {
    let mut worst = 0.0f64;
    for seed in 0..24u64 {
        let n = 6 + (seed as usize % 11); // 6 … 16 atoms
        let p = random_problem(seed, n);
        let exact = exact_marginals(&p).unwrap();
        let m = mc_sat(
            &p,
            &McSatOptions {
                seed,
                ..McSatOptions::default()
            },
        )
        .unwrap();
        let e = max_error(&m.probabilities, &exact);
        assert!(
            e <= 0.03,
            "seed {seed}, {n} atoms: max error {e:.4}; exact {exact:?} vs {:?}",
            m.probabilities
        );
        worst = worst.max(e);
    }
    eprintln!("worst max error over 24 random problems: {worst:.4}");
}

#[test]
fn exactly_one_constraints_mix_through_paired_moves() {
    // Hard: exactly one of atoms 0..4 (at least one, and no two); soft preferences.
    let n = 6;
    let mut factors = vec![factor(
        100.0,
        true,
        vec![(0..4).map(Literal::pos).collect()],
    )];
    for a in 0..4u32 {
        for b in a + 1..4 {
            factors.push(factor(
                100.0,
                true,
                vec![vec![Literal::neg(a), Literal::neg(b)]],
            ));
        }
    }
    factors.push(factor(1.5, false, vec![vec![Literal::pos(2)]]));
    factors.push(factor(-0.7, false, vec![vec![Literal::pos(3)]]));
    factors.push(factor(
        2.0,
        false,
        vec![
            vec![Literal::neg(0), Literal::pos(4)],
            vec![Literal::pos(5)],
        ],
    ));
    let p = problem(n, factors);
    let exact = exact_marginals(&p).unwrap();
    let m = mc_sat(&p, &McSatOptions::default()).unwrap();
    let e = max_error(&m.probabilities, &exact);
    eprintln!("exactly-one constraint: max error {e:.4}");
    assert!(
        e <= 0.03,
        "max error {e}: {exact:?} vs {:?}",
        m.probabilities
    );
    // Exactly one of 0..4 in every world: the marginals sum to 1.
    let s: f64 = m.probabilities[..4].iter().sum();
    assert!((s - 1.0).abs() < 0.02, "sum {s}");
}

#[test]
fn hard_unit_clauses_fix_atoms_exactly_and_contradictions_are_errors() {
    // 0 must be true; 0 → 1 hard; 2 free with a soft weight; 3 in no formula.
    let p = problem(
        4,
        vec![
            factor(100.0, true, vec![vec![Literal::pos(0)]]),
            factor(100.0, true, vec![vec![Literal::neg(0), Literal::pos(1)]]),
            factor(1.0, false, vec![vec![Literal::pos(2)]]),
        ],
    );
    let m = mc_sat(&p, &McSatOptions::default()).unwrap();
    assert_eq!(m.fixed_atoms, 2);
    assert_eq!(m.probabilities[0], 1.0);
    assert_eq!(m.probabilities[1], 1.0);
    assert_eq!(m.probabilities[3], 0.5);
    let sigmoid1 = 1.0 / (1.0 + (-1.0f64).exp());
    // Atom 2 has no neighbours: its conditional is its marginal, every sample.
    assert!((m.probabilities[2] - sigmoid1).abs() < 1e-12);

    let bad = problem(
        2,
        vec![
            factor(100.0, true, vec![vec![Literal::pos(0)]]),
            factor(100.0, true, vec![vec![Literal::neg(0), Literal::pos(1)]]),
            factor(100.0, true, vec![vec![Literal::neg(1)]]),
        ],
    );
    assert!(matches!(
        mc_sat(&bad, &McSatOptions::default()),
        Err(MarginalError::HardConflict { .. })
    ));
    assert_eq!(exact_marginals(&bad), Err(MarginalError::Unsatisfiable));
    assert!(matches!(
        exact_marginals(&problem(30, Vec::new())),
        Err(MarginalError::TooManyAtoms { atoms: 30, .. })
    ));
}

#[test]
fn the_same_seed_gives_the_same_marginals_and_chains_agree() {
    let p = random_problem(7, 12);
    let a = mc_sat(&p, &McSatOptions::default()).unwrap();
    let b = mc_sat(&p, &McSatOptions::default()).unwrap();
    assert_eq!(
        a.probabilities
            .iter()
            .map(|x| x.to_bits())
            .collect::<Vec<_>>(),
        b.probabilities
            .iter()
            .map(|x| x.to_bits())
            .collect::<Vec<_>>()
    );
    assert_eq!(a.chains, 2);
    assert!(a.max_chain_spread < 0.05, "spread {}", a.max_chain_spread);
    assert!(a.acceptance > 0.0 && a.acceptance <= 1.0);
    let c = mc_sat(
        &p,
        &McSatOptions {
            seed: 1,
            ..McSatOptions::default()
        },
    )
    .unwrap();
    assert_ne!(a.probabilities, c.probabilities);
}

#[test]
fn friends_and_smokers_marginals_match_enumeration() {
    let program = parse_program(
        "Smokes(person)\nCancer(person)\nFriends(person, person)\n\
         1.5 Smokes(x) => Cancer(x)\n\
         1.1 Friends(x, y) => (Smokes(x) <=> Smokes(y))\n\
         -0.5 Cancer(x)\n",
        "fs.mln",
    )
    .unwrap();
    let evidence = parse_evidence(
        "Friends(Anna, Bob)\nFriends(Bob, Anna)\nFriends(Bob, Chris)\nFriends(Chris, Dora)\nSmokes(Anna)\n",
        "fs.db",
        &program,
    )
    .unwrap();
    let query = parse_query("Smokes(x)\nCancer(x)\n", "q.db", &program).unwrap();
    let p = ground(
        &program,
        &evidence,
        "fs.db",
        &query,
        &GroundOptions::default(),
    )
    .unwrap();
    assert!(
        p.atoms.len() <= 16 && p.atoms.len() >= 6,
        "{}",
        p.atoms.len()
    );
    let exact = exact_marginals(&p).unwrap();
    let m = mc_sat(&p, &McSatOptions::default()).unwrap();
    let e = max_error(&m.probabilities, &exact);
    eprintln!(
        "friends and smokers ({} atoms): max error {e:.4}",
        p.atoms.len()
    );
    assert!(e <= 0.03, "max error {e}");
}

#[test]
fn equal_formulas_merge_forced_atoms_drop_out_and_the_marginals_stay_exact() {
    let (p, n) = (Literal::pos, Literal::neg);
    // Atom 0 forced true. Over 1, 2, 3: the same clause three times in other literal
    // orders (with a repeated literal, and with ¬0 which is false), a weight pair that
    // cancels, a tautology, a conjunction written in two clause orders, and a clause
    // that atom 0 satisfies.
    let prob = problem(
        5,
        vec![
            factor(100.0, true, vec![vec![p(0)]]),
            factor(0.7, false, vec![vec![p(1), n(2)]]),
            factor(0.4, false, vec![vec![n(2), p(1), p(1)]]),
            factor(-1.5, false, vec![vec![n(0), n(2), p(1)]]),
            factor(0.8, false, vec![vec![p(2), p(3)]]),
            factor(-0.8, false, vec![vec![p(3), p(2)]]),
            factor(2.0, false, vec![vec![p(3), n(3), p(1)]]),
            factor(1.2, false, vec![vec![p(1)], vec![n(3)]]),
            factor(-0.5, false, vec![vec![n(3)], vec![p(1)]]),
            factor(3.0, false, vec![vec![p(0), p(2), p(3)]]),
            factor(-0.9, false, vec![vec![p(3)]]),
        ],
    );
    let m = mc_sat(&prob, &McSatOptions::default()).unwrap();
    // Left: (1 ∨ ¬2) with weight −0.4 and (1 ∧ ¬3) with 0.7; atom 4 is in no formula.
    assert_eq!(m.slice_formulas, 2);
    assert_eq!(m.fixed_atoms, 1);
    assert_eq!(m.independent_atoms, 1);
    assert_eq!(m.probabilities[4], 0.5);
    let exact = exact_marginals(&prob).unwrap();
    let e = max_error(&m.probabilities, &exact);
    eprintln!("merged and forced formulas: max error {e:.4}");
    assert!(
        e <= 0.03,
        "max error {e}: {:?} vs {exact:?}",
        m.probabilities
    );
}
