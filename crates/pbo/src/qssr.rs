//! QSSR: quadratize → solve (QPBO, optional probing) → simplify → repeat (thesis §3.2,
//! "Quadratize-Solve-Simplify-Repeat"), then QPBO-I on what is left.
//!
//! Each round quadratizes the *current higher-order* function, runs QPBO on the quadratic
//! form, and fixes every original variable QPBO (or probing) labels persistently in the
//! higher-order function itself. Weak persistencies of the quadratization are weak
//! persistencies of the original (a minimiser (x*, w*) of ρ gives a minimiser x* of φ), and
//! fixing them keeps the minimum unchanged, so rounds compose. The loop ends when a round
//! fixes nothing new; the residue is then improved from the all-zero start by QPBO-I.
//!
//! ```
//! use pbo::polynomial::{Literal, Polynomial};
//! use pbo::qssr::{solve, QssrOptions};
//! // f = −x0·x1·x2 + 2·x̄0: submodular after reduction, solved completely.
//! let mut f = Polynomial::new(3);
//! f.add_term(-1.0, &[Literal::pos(0), Literal::pos(1), Literal::pos(2)]);
//! f.add_term(2.0, &[Literal::neg(0)]);
//! let r = solve(&f, &QssrOptions::default());
//! assert_eq!(r.energy, -1.0);
//! assert_eq!(r.labelled_fraction, 1.0);
//! ```

use crate::polynomial::{Literal, Polynomial};
use crate::qpbo::{ImproveOptions, Label, ProbeOptions, Qpbo};
use crate::quadratize::{quadratize, Quadratization, Quadratizer};
use crate::tabu::{enumerate_minimum, tabu_search, TabuOptions};
use rayon::prelude::*;
use std::borrow::Cow;
use std::time::Instant;

/// Options of [`solve`].
#[derive(Debug, Clone)]
pub struct QssrOptions {
    /// Order reduction used in every round.
    pub quadratizer: Quadratizer,
    /// Run QPBO-P (probing) on each round's quadratic function.
    pub probe: bool,
    /// Label more variables with weak persistency (strongly connected components).
    pub weak_persistencies: bool,
    /// QPBO-I iterations on the residue (0: unlabelled variables stay 0).
    pub improve_rounds: usize,
    /// Seed of the random choices in QPBO-I.
    pub seed: u64,
    /// At most this many QSSR rounds.
    pub max_rounds: usize,
    /// Enumerate a connected component of the residue exactly when it has at most this
    /// many variables (at most 30).
    pub exact_residue_vars: usize,
    /// Tabu search on each larger component of the residue after QPBO-I (`moves` 0: off).
    pub tabu: TabuOptions,
}

impl Default for QssrOptions {
    fn default() -> Self {
        QssrOptions {
            quadratizer: Quadratizer::Ish,
            probe: false,
            weak_persistencies: true,
            improve_rounds: 0,
            seed: 0,
            max_rounds: 100,
            exact_residue_vars: 20,
            tabu: TabuOptions {
                moves: 0,
                ..TabuOptions::default()
            },
        }
    }
}

/// What one QSSR round did.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct QssrRound {
    /// Unfixed variables occurring in the function at the start of the round.
    pub free_variables: usize,
    /// Higher-order terms at the start of the round.
    pub higher_order_terms: usize,
    /// Slack variables of this round's quadratization.
    pub slacks: usize,
    /// Variables fixed by QPBO in this round.
    pub fixed_by_qpbo: usize,
    /// Additional variables fixed by probing in this round.
    pub fixed_by_probe: usize,
    /// Roof-dual lower bound of this round's quadratic function.
    pub lower_bound: f64,
    /// Energy of the persistent values with every free variable at 0.
    pub energy: f64,
    /// Seconds spent quadratizing.
    pub seconds_quadratize: f64,
    /// Seconds spent in QPBO and probing.
    pub seconds_solve: f64,
}

/// Seconds per phase of [`solve`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PhaseSeconds {
    /// Order reduction, all rounds.
    pub quadratize: f64,
    /// QPBO (and probing), all rounds.
    pub solve: f64,
    /// QPBO-I on the residue.
    pub improve: f64,
}

/// The outcome of [`solve`].
#[derive(Debug, Clone)]
pub struct QssrResult {
    /// A complete assignment: persistent values, the rest from QPBO-I (or 0).
    pub assignment: Vec<bool>,
    /// Persistent values (extendable jointly to a global minimiser); `None` if unknown.
    pub persistent: Vec<Option<bool>>,
    /// Energy of `assignment`.
    pub energy: f64,
    /// Best roof-dual lower bound on the minimum over all rounds.
    pub lower_bound: f64,
    /// Persistent share of the variables that occur in the function (1 if none occur).
    pub labelled_fraction: f64,
    /// One record per round.
    pub rounds: Vec<QssrRound>,
    /// Time per phase.
    pub seconds: PhaseSeconds,
    /// Whether `assignment` is a proven global minimiser (persistencies + enumeration).
    pub exact: bool,
}

/// A QPBO instance built from a quadratic polynomial over its occurring variables.
pub struct QuadraticInstance {
    /// The QPBO solver with the function loaded.
    pub qpbo: Qpbo<f64>,
    /// Polynomial variable → QPBO node, `None` if the variable does not occur.
    pub node_of_var: Vec<Option<usize>>,
    /// QPBO node → polynomial variable.
    pub var_of_node: Vec<u32>,
}

/// Loads a quadratic polynomial (degree ≤ 2) into QPBO, numbering only occurring variables.
pub fn build_qpbo(q: &Polynomial) -> QuadraticInstance {
    assert!(q.degree() <= 2, "build_qpbo needs a quadratic function");
    let occurring = q.occurring_vars();
    let mut node_of_var = vec![None; q.num_vars()];
    let mut var_of_node = Vec::new();
    for (v, &occ) in occurring.iter().enumerate() {
        if occ {
            node_of_var[v] = Some(var_of_node.len());
            var_of_node.push(v as u32);
        }
    }
    let num_pairs = q.terms().filter(|(l, _)| l.len() == 2).count();
    let mut qpbo = Qpbo::<f64>::new(var_of_node.len(), num_pairs);
    qpbo.add_constant(q.constant());
    for (lits, a) in q.terms() {
        match lits {
            [l] => {
                let Some(i) = node_of_var[l.var() as usize] else {
                    continue;
                };
                let (e0, e1) = if l.is_negated() { (a, 0.0) } else { (0.0, a) };
                qpbo.add_unary(i, e0, e1);
            }
            [l1, l2] => {
                let (Some(i), Some(j)) = (
                    node_of_var[l1.var() as usize],
                    node_of_var[l2.var() as usize],
                ) else {
                    continue;
                };
                let e = |b1: bool, b2: bool| {
                    if l1.eval(b1) && l2.eval(b2) {
                        a
                    } else {
                        0.0
                    }
                };
                qpbo.add_pairwise(
                    i,
                    j,
                    e(false, false),
                    e(false, true),
                    e(true, false),
                    e(true, true),
                );
            }
            _ => unreachable!("degree checked above"),
        }
    }
    QuadraticInstance {
        qpbo,
        node_of_var,
        var_of_node,
    }
}

/// Minimises `f` by QSSR and QPBO-I; see the module documentation.
pub fn solve(f: &Polynomial, options: &QssrOptions) -> QssrResult {
    let n = f.num_vars();
    let occurring = f.occurring_vars();
    let num_occurring = occurring.iter().filter(|&&o| o).count();
    let mut persistent: Vec<Option<bool>> = vec![None; n];
    // Borrowed until the first fixing: a quadratic input is never copied.
    let mut residual: Cow<'_, Polynomial> = Cow::Borrowed(f);
    let mut rounds = Vec::new();
    let mut seconds = PhaseSeconds::default();
    let mut lower_bound = f64::NEG_INFINITY;

    for _ in 0..options.max_rounds {
        if residual.num_terms() == 0 {
            lower_bound = lower_bound.max(residual.constant());
            break;
        }
        let free_variables = residual.occurring_vars().iter().filter(|&&o| o).count();
        let t0 = Instant::now();
        // A quadratic residual goes to QPBO as it is (no slack, no copy).
        let quad = (residual.num_higher_order_terms() > 0)
            .then(|| quadratize(&residual, options.quadratizer));
        let quad_poly: &Polynomial = quad.as_ref().map_or(&*residual, |q| &q.poly);
        let seconds_quadratize = t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        let mut inst = build_qpbo(quad_poly);
        inst.qpbo.solve();
        if options.weak_persistencies {
            inst.qpbo.compute_weak_persistencies();
        }
        let bound = inst.qpbo.lower_bound();
        let mut newly: Vec<Option<bool>> = vec![None; n];
        let mut fixed_by_qpbo = 0;
        for (node, &v) in inst.var_of_node.iter().enumerate() {
            let v = v as usize;
            if v >= n {
                continue; // a slack
            }
            let value = match inst.qpbo.label(node) {
                Label::Zero => false,
                Label::One => true,
                Label::Unlabelled => continue,
            };
            newly[v] = Some(value);
            fixed_by_qpbo += 1;
        }
        let mut fixed_by_probe = 0;
        if options.probe && fixed_by_qpbo < free_variables {
            let probed = inst.qpbo.probe(&ProbeOptions::default());
            for (node, &v) in inst.var_of_node.iter().enumerate() {
                let v = v as usize;
                if v < n && newly[v].is_none() {
                    if let Some(Some(value)) = probed.fixed.get(node) {
                        newly[v] = Some(*value);
                        fixed_by_probe += 1;
                    }
                }
            }
        }
        let seconds_solve = t1.elapsed().as_secs_f64();
        seconds.quadratize += seconds_quadratize;
        seconds.solve += seconds_solve;
        lower_bound = lower_bound.max(bound);
        for (p, nv) in persistent.iter_mut().zip(&newly) {
            if nv.is_some() {
                *p = *nv;
            }
        }
        let zero_filled: Vec<bool> = persistent.iter().map(|p| p.unwrap_or(false)).collect();
        rounds.push(QssrRound {
            free_variables,
            higher_order_terms: residual.num_higher_order_terms(),
            slacks: quad.as_ref().map_or(0, Quadratization::num_slacks),
            fixed_by_qpbo,
            fixed_by_probe,
            lower_bound: bound,
            energy: f.evaluate(&zero_filled),
            seconds_quadratize,
            seconds_solve,
        });
        if fixed_by_qpbo + fixed_by_probe == 0 {
            break;
        }
        residual = Cow::Owned(residual.fix(&newly));
    }

    let t2 = Instant::now();
    let mut assignment: Vec<bool> = persistent.iter().map(|p| p.unwrap_or(false)).collect();
    let free: Vec<usize> = residual
        .occurring_vars()
        .iter()
        .enumerate()
        .filter_map(|(v, &o)| o.then_some(v))
        .collect();
    let components = split_components(&residual, &free);
    let max_exact = options.exact_residue_vars.min(30);
    let exact = components.iter().all(|c| c.vars.len() <= max_exact);
    if !exact && options.improve_rounds > 0 {
        let quad = quadratize(&residual, options.quadratizer);
        improve_residue(&quad, &mut assignment, options);
    }
    solve_components(&components, max_exact, &options.tabu, &mut assignment);
    if exact {
        lower_bound = residual.evaluate(&assignment);
    }
    seconds.improve = t2.elapsed().as_secs_f64();

    let labelled = persistent
        .iter()
        .zip(&occurring)
        .filter(|(p, &o)| o && p.is_some())
        .count();
    let energy = f.evaluate(&assignment);
    QssrResult {
        assignment,
        persistent,
        energy,
        lower_bound: lower_bound.min(energy),
        labelled_fraction: if num_occurring == 0 {
            1.0
        } else {
            labelled as f64 / num_occurring as f64
        },
        rounds,
        seconds,
        exact,
    }
}

/// Improves `assignment` on the residue of `f` after fixing `persistent` (as returned by
/// [`solve`]): each connected component of the residue with at most `exact_vars` (≤ 30)
/// variables is set to its minimum by enumeration, each larger one is improved by tabu
/// search (if `tabu.moves` > 0) from its values in `assignment`. Components run in
/// parallel; the result is never worse than `assignment`.
pub fn search_residue(
    f: &Polynomial,
    persistent: &[Option<bool>],
    assignment: &mut [bool],
    exact_vars: usize,
    tabu: &TabuOptions,
) {
    let residual = f.fix(persistent);
    let free: Vec<usize> = residual
        .occurring_vars()
        .iter()
        .enumerate()
        .filter_map(|(v, &o)| o.then_some(v))
        .collect();
    let components = split_components(&residual, &free);
    solve_components(&components, exact_vars.min(30), tabu, assignment);
}

/// Enumerates the small components and runs tabu search on the others, in parallel.
fn solve_components(
    components: &[Component],
    max_exact: usize,
    tabu: &TabuOptions,
    assignment: &mut [bool],
) {
    let solved: Vec<Vec<bool>> = components
        .par_iter()
        .map(|c| {
            let mut x: Vec<bool> = c.vars.iter().map(|&v| assignment[v]).collect();
            if c.vars.len() <= max_exact {
                let all: Vec<usize> = (0..c.vars.len()).collect();
                enumerate_minimum(&c.poly, &all, &mut x);
            } else if tabu.moves > 0 {
                x = tabu_search(&c.poly, &x, tabu);
            }
            x
        })
        .collect();
    for (c, x) in components.iter().zip(solved) {
        for (&v, b) in c.vars.iter().zip(x) {
            assignment[v] = b;
        }
    }
}

/// A connected component of the residue: its variables and its terms over local indices.
struct Component {
    /// Residue variables; local variable i is `vars[i]`.
    vars: Vec<usize>,
    /// The component's terms (no constant) over local variables.
    poly: Polynomial,
}

/// Splits `f` (whose occurring variables are `free`) into connected components of its
/// variable–term graph, in order of their smallest variable.
fn split_components(f: &Polynomial, free: &[usize]) -> Vec<Component> {
    let n = f.num_vars();
    let mut parent: Vec<usize> = (0..n).collect();
    fn root(parent: &mut [usize], mut v: usize) -> usize {
        while parent[v] != v {
            parent[v] = parent[parent[v]];
            v = parent[v];
        }
        v
    }
    for (lits, _) in f.terms() {
        let a = root(&mut parent, lits[0].var() as usize);
        for l in &lits[1..] {
            let b = root(&mut parent, l.var() as usize);
            if a != b {
                parent[b] = a;
            }
        }
    }
    let mut component_of = vec![usize::MAX; n];
    let mut local = vec![0u32; n];
    let mut components: Vec<Component> = Vec::new();
    for &v in free {
        let r = root(&mut parent, v);
        if component_of[r] == usize::MAX {
            component_of[r] = components.len();
            components.push(Component {
                vars: Vec::new(),
                poly: Polynomial::new(0),
            });
        }
        let c = &mut components[component_of[r]];
        local[v] = c.vars.len() as u32;
        c.vars.push(v);
    }
    let mut buffer = Vec::new();
    for (lits, a) in f.terms() {
        let c = component_of[root(&mut parent, lits[0].var() as usize)];
        buffer.clear();
        buffer.extend(
            lits.iter()
                .map(|l| Literal::new(local[l.var() as usize], !l.is_negated())),
        );
        components[c].poly.add_term(a, &buffer);
    }
    components
}

/// Runs QPBO-I on the quadratized residue, starting from `assignment`, and writes the
/// improved values of the residue's variables back.
fn improve_residue(quad: &Quadratization, assignment: &mut [bool], options: &QssrOptions) {
    let mut inst = build_qpbo(&quad.poly);
    let start = quad.complete_slacks(assignment);
    let mut x: Vec<bool> = inst
        .var_of_node
        .iter()
        .map(|&v| start[v as usize])
        .collect();
    inst.qpbo.improve(
        &mut x,
        &ImproveOptions {
            rounds: options.improve_rounds,
            seed: options.seed,
            ..ImproveOptions::default()
        },
    );
    for (node, &v) in inst.var_of_node.iter().enumerate() {
        if (v as usize) < assignment.len() {
            assignment[v as usize] = x[node];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quadratize::tests::arb_higher_order;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]
        /// QSSR never fixes a variable wrongly: the persistent values extend to a global
        /// minimiser, and the bound is below the minimum, for every quadratizer.
        #[test]
        fn qssr_persistencies_are_correct(f in arb_higher_order(10), probe in any::<bool>()) {
            let (min, _) = f.brute_force_minimum();
            for quadratizer in Quadratizer::ALL {
                let r = solve(&f, &QssrOptions { quadratizer, probe, improve_rounds: 3, exact_residue_vars: 0, ..QssrOptions::default() });
                prop_assert!(r.lower_bound <= min + 1e-9, "{quadratizer}: bound {} > min {min}", r.lower_bound);
                prop_assert!(r.energy >= min - 1e-9);
                prop_assert!((r.energy - f.evaluate(&r.assignment)).abs() < 1e-9);
                let restricted = f.fix(&r.persistent);
                let (rmin, _) = restricted.brute_force_minimum();
                prop_assert!((rmin - min).abs() < 1e-9,
                    "{quadratizer}: fixing {:?} raises the minimum {min} to {rmin}", r.persistent);
                for (p, a) in r.persistent.iter().zip(&r.assignment) {
                    if let Some(v) = p { prop_assert_eq!(v, a); }
                }
            }
        }
    }

    proptest! {
        /// With an exact residue, QSSR returns a global minimiser whose energy is the bound.
        #[test]
        fn exact_residue_gives_the_optimum(f in arb_higher_order(10)) {
            let (min, _) = f.brute_force_minimum();
            let r = solve(&f, &QssrOptions::default());
            prop_assert!(r.exact);
            prop_assert!((r.energy - min).abs() < 1e-9, "energy {} vs min {min}", r.energy);
            prop_assert!((r.lower_bound - min).abs() < 1e-9);
        }
    }

    proptest! {
        /// Components are solved separately: small ones exactly, larger ones by tabu search,
        /// which never loses to QPBO-I alone (how often it reaches the optimum:
        /// [`tabu_reaches_the_optimum_of_nearly_every_small_residue`]).
        #[test]
        fn residue_components_are_solved(f in arb_higher_order(10), seed in any::<u64>()) {
            let (min, _) = f.brute_force_minimum();
            let base = QssrOptions { exact_residue_vars: 3, improve_rounds: 5, seed, ..QssrOptions::default() };
            let plain = solve(&f, &base);
            let tabu = TabuOptions { moves: 2_000, seed, ..TabuOptions::default() };
            let r = solve(&f, &QssrOptions { tabu, ..base });
            prop_assert!(r.energy <= plain.energy + 1e-9);
            prop_assert!(r.energy >= min - 1e-9);
            prop_assert!((r.energy - f.evaluate(&r.assignment)).abs() < 1e-9);
            prop_assert!(r.lower_bound <= min + 1e-9);
        }
    }

    /// Tabu search is a heuristic: on 500 random residues of up to 10 variables (fixed
    /// seed) it must reach the brute-force optimum on nearly all of them.
    #[test]
    fn tabu_reaches_the_optimum_of_nearly_every_small_residue() {
        use proptest::strategy::{Strategy, ValueTree};
        use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};
        let mut runner = TestRunner::new_with_rng(
            Config::default(),
            TestRng::from_seed(RngAlgorithm::ChaCha, &[7; 32]),
        );
        let (mut optimal, total) = (0usize, 500usize);
        for i in 0..total {
            let f = arb_higher_order(10)
                .new_tree(&mut runner)
                .expect("a polynomial")
                .current();
            let (min, _) = f.brute_force_minimum();
            let base = QssrOptions {
                exact_residue_vars: 3,
                improve_rounds: 5,
                seed: i as u64,
                ..QssrOptions::default()
            };
            let tabu = TabuOptions {
                moves: 2_000,
                seed: i as u64,
                ..TabuOptions::default()
            };
            let r = solve(&f, &QssrOptions { tabu, ..base });
            optimal += usize::from((r.energy - min).abs() < 1e-9);
        }
        eprintln!("tabu reached the optimum on {optimal} of {total}");
        assert!(optimal * 100 >= 98 * total, "{optimal} of {total}");
    }

    #[test]
    fn residue_of_proptest_case_2721767268274004636_is_solved() {
        use crate::polynomial::Literal as L;
        let lit = |code: u32| {
            if code % 2 == 0 {
                L::pos(code / 2)
            } else {
                L::neg(code / 2)
            }
        };
        let mut f = Polynomial::new(5);
        for (coeff, codes) in [
            (4.0, &[5, 6][..]),
            (3.0, &[5, 7]),
            (3.0, &[4]),
            (1.0, &[2]),
            (-4.0, &[3, 9]),
            (2.0, &[0, 2, 5]),
            (-2.0, &[1, 4, 9]),
            (5.0, &[9]),
        ] {
            let lits: Vec<L> = codes.iter().map(|&c| lit(c)).collect();
            f.add_term(coeff, &lits);
        }
        let (min, _) = f.brute_force_minimum();
        let seed = 2721767268274004636;
        let base = QssrOptions {
            exact_residue_vars: 3,
            improve_rounds: 5,
            seed,
            ..QssrOptions::default()
        };
        let tabu = TabuOptions {
            moves: 2_000,
            seed,
            ..TabuOptions::default()
        };
        let r = solve(&f, &QssrOptions { tabu, ..base });
        assert!(
            (r.energy - min).abs() < 1e-9,
            "energy {} vs min {min}: {r:?}",
            r.energy
        );
    }

    #[test]
    fn components_partition_the_residue() {
        use crate::polynomial::Literal as L;
        let mut f = Polynomial::new(7);
        f.add_term(1.0, &[L::pos(0), L::neg(3)]);
        f.add_term(-2.0, &[L::pos(1), L::pos(5), L::neg(6)]);
        f.add_term(0.5, &[L::neg(3)]);
        f.add_term(4.0, &[L::pos(6)]);
        let free = [0, 1, 3, 5, 6];
        let cs = split_components(&f, &free);
        assert_eq!(cs.len(), 2);
        assert_eq!(cs[0].vars, vec![0, 3]);
        assert_eq!(cs[1].vars, vec![1, 5, 6]);
        for m in 0u32..128 {
            let x: Vec<bool> = (0..7).map(|i| m >> i & 1 == 1).collect();
            let sum: f64 = cs
                .iter()
                .map(|c| {
                    c.poly
                        .evaluate(&c.vars.iter().map(|&v| x[v]).collect::<Vec<_>>())
                })
                .sum();
            assert_eq!(sum, f.evaluate(&x));
        }
    }

    #[test]
    fn fully_labelled_problem_is_optimal() {
        // Negative terms only: submodular after the single-slack reduction.
        let mut f = Polynomial::new(4);
        use crate::polynomial::Literal as L;
        f.add_term(-3.0, &[L::pos(0), L::pos(1), L::pos(2)]);
        f.add_term(-1.0, &[L::pos(1), L::pos(2), L::pos(3)]);
        f.add_term(1.5, &[L::pos(1)]);
        f.add_term(0.5, &[L::pos(3)]);
        let r = solve(&f, &QssrOptions::default());
        assert_eq!(r.labelled_fraction, 1.0);
        assert_eq!(r.energy, f.brute_force_minimum().0);
        assert!((r.lower_bound - r.energy).abs() < 1e-9);
    }
}
