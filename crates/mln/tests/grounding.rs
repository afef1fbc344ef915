//! Grounding against a naive reference: every binding of every formula enumerated over the
//! domains and evaluated directly, on random small programs and random assignments.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use mln::ground::{ground, GroundOptions, GroundProblem};
use mln::parse::{
    parse_evidence, parse_program, parse_query, Atom, Formula, Program, Term, Weight,
};
use proptest::prelude::*;
use rustc_hash::FxHashMap;

/// The naive world: evidence, open predicates, the unknown atoms' values.
struct Naive<'a> {
    program: &'a Program,
    problem: &'a GroundProblem,
    evidence: FxHashMap<(usize, Vec<String>), bool>,
    open: Vec<bool>,
    canopy: Vec<Option<Vec<Vec<String>>>>,
    atom_index: FxHashMap<(usize, Vec<String>), usize>,
    domains: FxHashMap<String, Vec<String>>,
}

impl Naive<'_> {
    fn truth(&self, pred: usize, args: &[String], x: &[bool]) -> bool {
        if let Some(&v) = self.evidence.get(&(pred, args.to_vec())) {
            return v;
        }
        if !self.open[pred] {
            return false;
        }
        if let Some(c) = &self.canopy[pred] {
            if !c.iter().any(|a| a == args) {
                return false;
            }
        }
        // Unknown: its variable if grounding kept it, else any value (false) must do.
        self.atom_index
            .get(&(pred, args.to_vec()))
            .is_some_and(|&i| x[i])
    }

    fn eval(&self, f: &Formula, b: &FxHashMap<String, String>, x: &[bool]) -> bool {
        let term = |t: &Term| match t {
            Term::Var(v) => b[v.as_str()].clone(),
            Term::Const(c) => c.to_string(),
        };
        match f {
            Formula::Atom(a) => {
                let args: Vec<String> = a.args.iter().map(term).collect();
                self.truth(a.predicate, &args, x)
            }
            Formula::Equal(pair) => term(&pair.0) == term(&pair.1),
            Formula::Not(g) => !self.eval(g, b, x),
            Formula::And(v) => v.iter().all(|g| self.eval(g, b, x)),
            Formula::Or(v) => v.iter().any(|g| self.eval(g, b, x)),
            Formula::Implies(p, q) => !self.eval(p, b, x) || self.eval(q, b, x),
            Formula::Iff(p, q) => self.eval(p, b, x) == self.eval(q, b, x),
            Formula::Exists(vs, g) | Formula::Forall(vs, g) => {
                let exists = matches!(f, Formula::Exists(..));
                let mut results = Vec::new();
                self.bind_all(vs, g, b.clone(), &mut |bb| {
                    results.push(self.eval(g, bb, x))
                });
                if exists {
                    results.iter().any(|&r| r)
                } else {
                    results.iter().all(|&r| r)
                }
            }
        }
    }

    fn type_of(&self, f: &Formula, var: &str) -> String {
        let mut found = None;
        visit_atoms(f, &mut |a: &Atom| {
            for (t, ty) in a
                .args
                .iter()
                .zip(&self.program.predicates[a.predicate].arg_types)
            {
                if matches!(t, Term::Var(v) if v == var) && found.is_none() {
                    found = Some(ty.to_string());
                }
            }
        });
        found.expect("typed variable")
    }

    fn bind_all(
        &self,
        vars: &[String],
        scope: &Formula,
        b: FxHashMap<String, String>,
        emit: &mut dyn FnMut(&FxHashMap<String, String>),
    ) {
        let Some((v, rest)) = vars.split_first() else {
            emit(&b);
            return;
        };
        let ty = self.type_of(scope, v);
        for c in &self.domains[&ty] {
            let mut bb = b.clone();
            bb.insert(v.clone(), c.clone());
            self.bind_all(rest, scope, bb, emit);
        }
    }

    /// (violated soft weight, hard violations, −Σ w·[F] over all soft groundings).
    fn scores(&self, x: &[bool]) -> (f64, usize) {
        let mut violated = 0.0;
        let mut hard = 0;
        for wf in &self.program.formulas {
            let mut free = Vec::new();
            free_vars(&wf.formula, &mut Vec::new(), &mut free);
            self.bind_all(&free, &wf.formula, FxHashMap::default(), &mut |b| {
                let t = self.eval(&wf.formula, b, x);
                match wf.weight {
                    Weight::Hard => hard += usize::from(!t),
                    Weight::Soft(w) => {
                        if (w > 0.0 && !t) || (w < 0.0 && t) {
                            violated += w.abs();
                        }
                    }
                }
            });
        }
        (violated, hard)
    }
}

fn visit_atoms(f: &Formula, visit: &mut dyn FnMut(&Atom)) {
    match f {
        Formula::Atom(a) => visit(a),
        Formula::Equal(..) => {}
        Formula::Not(g) | Formula::Exists(_, g) | Formula::Forall(_, g) => visit_atoms(g, visit),
        Formula::And(v) | Formula::Or(v) => v.iter().for_each(|g| visit_atoms(g, visit)),
        Formula::Implies(a, b) | Formula::Iff(a, b) => {
            visit_atoms(a, visit);
            visit_atoms(b, visit);
        }
    }
}

fn free_vars(f: &Formula, bound: &mut Vec<String>, out: &mut Vec<String>) {
    let note = |t: &Term, bound: &[String], out: &mut Vec<String>| {
        if let Term::Var(v) = t {
            if !bound.iter().any(|b| b == v) && !out.iter().any(|o| o == v) {
                out.push(v.to_string());
            }
        }
    };
    match f {
        Formula::Atom(a) => a.args.iter().for_each(|t| note(t, bound, out)),
        Formula::Equal(pair) => {
            note(&pair.0, bound, out);
            note(&pair.1, bound, out);
        }
        Formula::Not(g) => free_vars(g, bound, out),
        Formula::Exists(vs, g) | Formula::Forall(vs, g) => {
            let n = bound.len();
            bound.extend(vs.iter().cloned());
            free_vars(g, bound, out);
            bound.truncate(n);
        }
        Formula::And(v) | Formula::Or(v) => v.iter().for_each(|g| free_vars(g, bound, out)),
        Formula::Implies(a, b) | Formula::Iff(a, b) => {
            free_vars(a, bound, out);
            free_vars(b, bound, out);
        }
    }
}

const PERSONS: [&str; 3] = ["Ann", "Bob", "Cy"];

/// A random small program over `person`: *Friends(person,person) closed, Smokes and Cancer
/// open (queried), with a few formula shapes and random weights, evidence and canopy.
fn arb_case() -> impl Strategy<Value = (String, String, String)> {
    let shapes = proptest::collection::vec((0usize..8, -3i32..=3, any::<bool>()), 1..5);
    let evidence =
        proptest::collection::vec((0usize..3, 0usize..3, 0usize..3, any::<bool>()), 0..8);
    (shapes, evidence, any::<bool>()).prop_map(|(shapes, evidence, canopy)| {
        let mut prog = String::from(
            "person = { Ann, Bob, Cy }\n*Friends(person, person)\nSmokes(person)\nCancer(person)\n",
        );
        let bodies = [
            "Smokes(x) => Cancer(x)",
            "Friends(x, y) => (Smokes(x) <=> Smokes(y))",
            "!Friends(x,y) v !Smokes(x) v Smokes(y)",
            "Smokes(x) ^ Friends(x,y) ^ x != y => Cancer(y)",
            "EXIST y Friends(x, y) ^ Smokes(y)",
            "Cancer(Ann) v !Smokes(x)",
            "Smokes(x) ^ Smokes(y) ^ Cancer(z)",
            "Cancer(Ann) v !Smokes(Bob)",
        ];
        for (shape, w, hard) in shapes {
            if hard && w == 0 {
                prog.push_str(&format!("{}.\n", bodies[shape]));
            } else {
                prog.push_str(&format!("{} {}\n", w, bodies[shape]));
            }
        }
        let mut ev = String::new();
        for (p, a, b, v) in evidence {
            let neg = if v { "" } else { "!" };
            match p {
                0 => ev.push_str(&format!("{neg}Friends({}, {})\n", PERSONS[a], PERSONS[b])),
                1 => ev.push_str(&format!("{neg}Smokes({})\n", PERSONS[a])),
                _ => ev.push_str(&format!("{neg}Cancer({})\n", PERSONS[b])),
            }
        }
        let query = if canopy {
            "Smokes(x)\nCancer(Bob)\nCancer(Cy)\n".to_owned()
        } else {
            "Smokes(x)\nCancer(x)\n".to_owned()
        };
        (prog, ev, query)
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]
    #[test]
    fn grounding_matches_naive_reference((prog, ev, query) in arb_case(), seed in any::<u64>()) {
        let program = parse_program(&prog, "p.mln").unwrap();
        let evidence = parse_evidence(&ev, "e.db", &program).unwrap();
        let query_atoms = parse_query(&query, "q.db", &program).unwrap();
        let problem = ground(&program, &evidence, "e.db", &query_atoms, &GroundOptions::default()).unwrap();

        let mut naive = Naive {
            program: &program,
            problem: &problem,
            evidence: evidence.iter().map(|e| ((e.predicate, e.args.iter().map(|a| a.to_string()).collect()), e.value)).collect(),
            open: vec![false, true, true],
            canopy: vec![None, None, None],
            atom_index: FxHashMap::default(),
            domains: [("person".to_owned(), PERSONS.iter().map(|s| s.to_string()).collect())].into_iter().collect(),
        };
        if query.contains("Cancer(Bob)") {
            naive.canopy[2] = Some(vec![vec!["Bob".into()], vec!["Cy".into()]]);
        }
        for (i, a) in naive.problem.atoms.iter().enumerate() {
            let args: Vec<String> = a.args.iter().map(|&c| naive.problem.constants[c as usize].clone()).collect();
            naive.atom_index.insert((a.predicate, args), i);
        }
        let n = problem.atoms.len();
        prop_assert!(n <= 6, "{n} unknown atoms");
        for k in 0..8u64 {
            let bits = seed.rotate_left(k as u32 * 7) ^ k;
            let x: Vec<bool> = (0..n).map(|i| bits >> i & 1 == 1).collect();
            let s = problem.score(&x);
            let (violated, hard) = naive.scores(&x);
            prop_assert!((s.violated_weight - violated).abs() < 1e-9,
                "violated weight {} vs naive {violated}\n{prog}\n{ev}", s.violated_weight);
            prop_assert_eq!(s.hard_violations, hard);
            // The polynomial is the factor sum −Σ w·[F] (hard factors included).
            let direct: f64 = problem.factors.iter().filter(|f| f.is_true(&x)).map(|f| -f.weight).sum();
            prop_assert!((problem.cost.evaluate(&x) - direct).abs() < 1e-6);
            let soft_direct: f64 = problem.factors.iter().filter(|f| !f.hard && f.is_true(&x)).map(|f| -f.weight).sum();
            prop_assert!((s.cost - soft_direct).abs() < 1e-9);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(150))]
    /// MAP by every method reaches the brute-force minimum of cost + hard violations on
    /// small random MLNs; the QPBO method's bound is below it.
    #[test]
    fn map_equals_brute_force((prog, ev, query) in arb_case(), seed in any::<u64>()) {
        use mln::infer::{map_inference, InferOptions, Method};
        let program = parse_program(&prog, "p.mln").unwrap();
        let evidence = parse_evidence(&ev, "e.db", &program).unwrap();
        let query_atoms = parse_query(&query, "q.db", &program).unwrap();
        let problem = ground(&program, &evidence, "e.db", &query_atoms, &GroundOptions::default()).unwrap();
        let n = problem.atoms.len();
        prop_assume!(n <= 14);
        let total = |x: &[bool]| problem.cost.evaluate(x);
        let mut best = f64::INFINITY;
        for m in 0u32..(1 << n) {
            let x: Vec<bool> = (0..n).map(|i| m >> i & 1 == 1).collect();
            best = best.min(total(&x));
        }
        for method in [Method::Qpbo, Method::MaxWalkSat, Method::MaxWalkSatMonomials] {
            let mut o = InferOptions { method, ..InferOptions::default() };
            o.walksat.seed = seed;
            o.walksat.max_flips = 20_000;
            let r = map_inference(&problem, &o);
            let got = total(&r.assignment);
            prop_assert!((got - best).abs() < 1e-6, "{:?}: {got} vs optimum {best}", method);
            if let Some(lb) = r.lower_bound {
                prop_assert!(lb <= best + 1e-6);
            }
        }
    }
}

#[test]
fn smokers_example_by_hand() {
    // Thesis Example 3.2.1/3.2.2: two persons, Friends(A,B), Friends(B,A) unknown here.
    let program = parse_program(
        "Friends(person, person)\nSmokes(person)\n1.0 Friends(x, y) ^ Smokes(x) => Smokes(y)\n",
        "toy.mln",
    )
    .unwrap();
    let evidence = parse_evidence(
        "Friends(A, B)\nFriends(B, A)\n!Friends(A, A)\n!Friends(B, B)\n",
        "toy.db",
        &program,
    )
    .unwrap();
    let query = parse_query("Smokes(x)\n", "q", &program).unwrap();
    let p = ground(
        &program,
        &evidence,
        "toy.db",
        &query,
        &GroundOptions::default(),
    )
    .unwrap();
    assert_eq!(p.atoms.len(), 2);
    assert_eq!(p.factors.len(), 2);
    // Groundings x = y are decided by evidence (Friends false): true, not violated.
    assert_eq!(p.constant_violated_weight, 0.0);
    // Smokes(A) = 1, Smokes(B) = 0 violates Friends(A,B) ^ Smokes(A) => Smokes(B).
    let s = p.score(&[true, false]);
    assert_eq!(s.violated_weight, 1.0);
    assert_eq!(s.cost, -1.0);
}

#[test]
fn zero_weight_formulas_change_nothing() {
    // ER has 6 444 formulas of weight 0 among 7 709; they are not grounded at all.
    let decls = "Friends(person, person)\nSmokes(person)\nCancer(person)\n";
    let rules = "1.5 Friends(x, y) ^ Smokes(x) => Smokes(y)\n-0.5 Smokes(x) => Cancer(x)\n";
    let zero = "0 Friends(x, y) => Cancer(y)\n0 Smokes(x) ^ Smokes(y) => Cancer(x)\n";
    let run = |text: &str| {
        let program = parse_program(text, "z.mln").unwrap();
        let evidence = parse_evidence("Friends(A, B)\nSmokes(A)\n", "z.db", &program).unwrap();
        let query = parse_query("Smokes(x)\nCancer(x)\n", "q", &program).unwrap();
        ground(
            &program,
            &evidence,
            "z.db",
            &query,
            &GroundOptions::default(),
        )
        .unwrap()
    };
    let plain = run(&format!("{decls}{rules}"));
    let with_zero = run(&format!("{decls}{zero}{rules}"));
    assert_eq!(plain.atoms, with_zero.atoms);
    assert_eq!(plain.factors.len(), with_zero.factors.len());
    assert_eq!(
        plain.constant_violated_weight,
        with_zero.constant_violated_weight
    );
    let n = plain.atoms.len();
    for m in 0u32..(1 << n) {
        let x: Vec<bool> = (0..n).map(|i| m >> i & 1 == 1).collect();
        assert_eq!(plain.score(&x), with_zero.score(&x));
    }
}
