//! GRD: generalized roof duality restricted to the diagonal (Kahl & Strandmark,
//! "Generalized roof duality for pseudo-Boolean optimization", ICCV 2011; and
//! "Generalized roof duality", Discrete Applied Mathematics 160(16–17):2419–2434, 2012;
//! reference code PetterS/submodular).
//!
//! GRD relaxes f(x) to a symmetric submodular g(x, y) with g(x, x̄) = f(x). Following the
//! authors' code (PetterS/submodular, `PseudoBoolean_create_g.cpp`), each cubic or quartic
//! multilinear monomial a·x_S is split over 2^{|S|−1} sign-restricted types φ ⊂ S:
//! a·x_S = Σ_φ w_φ·Π_{S∖φ} x·Π_φ (1 − x̄), every w_φ of the sign of a. On the diagonal
//! y = x̄ each type expands into the literal monomials w·(−1)^{|T|}·Π_{S∖φ} x·Π_T x̄
//! (T ⊆ φ), which are reduced like ISH does (Freedman for negative, Ishikawa for positive
//! coefficients). The weights come from the paper's LP: maximise g(0, 0) subject to the
//! submodularity of the doubled quadratic graph, one pair of rows per variable pair.
//! With b_P, c_P eliminated it reads
//! max Σ_P t_P + Σ_S w_{S,∅} s.t. t_P ≤ −β_P(w), t_P ≤ a_P + γ_P(w), Σ_φ w_{S,φ} = a_S,
//! where β_P, γ_P are the same-side and cross contributions of the types to pair P.
//!
//! What is simplified against the paper:
//! - Route (b) of the design notes: we emit the exact quadratization ρ(x, w) on the
//!   diagonal instead of the doubled graph g; QPBO on ρ is the roof dual of ρ, which is at
//!   least min g (quadratic case of the paper's theorem). ρ does not depend on b_P, c_P.
//! - Terms are coupled only through shared pairs, so the LP is solved per connected group
//!   of terms; a group with more than [`LP_MAX_TERMS`] terms is solved term by term
//!   instead (each term's LP sees the pair rows left by the terms before it, in
//!   lexicographic order), which replaces the authors' greedy heuristic. LPs are cached
//!   by their data (a group's with its variables renamed), so repeated patterns cost
//!   nothing.
//! - The LP's objective is the paper's proxy g(0, 0), not min g; ties are resolved by
//!   microlp's deterministic simplex on a fixed variable order.
//! - No iteration (label, substitute, re-solve): QSSR's rounds do that outside.
//! - Terms of degree > 4 (as literal monomials) are reduced by ISH and take no part in
//!   the LP. Terms of degree ≤ 4 are expanded into positive literals (≤ 16 monomials).
//!
//! - ρ is returned with every quadratic term expanded into positive literals, so each
//!   variable pair is one QPBO edge: QPBO keeps x_u·x_v and x̄_u·x_v as two parallel edges
//!   and its bound on that form is weaker (−4 instead of the tight −2 on the paper's cubic
//!   example).
//!
//! Cost: one LP with 4 variables per cubic, 8 per quartic and one per pair, plus
//! O(2^d·d²) output terms per monomial.

use super::{ish, Quadratization};
use crate::polynomial::{Literal, Polynomial};
use microlp::{ComparisonOp, OptimizationDirection, Problem};
use rustc_hash::FxHashMap;

/// Groups with more higher-order terms than this are solved one term at a time.
pub const LP_MAX_TERMS: usize = 2_000;

type Pair = (u32, u32);

/// A sparse LP row: (variable, coefficient).
type Row = Vec<(microlp::Variable, f64)>;

/// A multilinear monomial of degree 3 or 4 with its coefficient.
#[derive(Debug, Clone)]
struct Term {
    vars: Vec<u32>,
    a: f64,
}

/// The type masks φ (bit p = position p of S flipped), one per pair {φ, S∖φ}, b = ∅ first.
fn type_masks(d: usize) -> Vec<u32> {
    (0u32..1 << d)
        .filter(|&m| {
            let k = m.count_ones() as usize;
            2 * k < d || (2 * k == d && m & 1 == 0)
        })
        .collect()
}

/// Same-side (β) and cross (γ) contributions to each pair of one unit of type `mask` in a
/// monomial of degree `d` and sign `sign` (rule R of the design: degree-2 node monomials
/// count as they are, positive ones of degree ≥ 3 (Ishikawa) add to every inner pair,
/// negative ones (Freedman) add nothing). Pairs are position pairs (p, q), p < q; values
/// are per unit of w.
fn contributions(d: usize, mask: u32, sign: f64) -> Vec<((usize, usize), f64, f64)> {
    let mut out: Vec<((usize, usize), f64, f64)> = Vec::new();
    let mut add = |p: usize, q: usize, beta: f64, gamma: f64| {
        let key = (p.min(q), p.max(q));
        if let Some(e) = out.iter_mut().find(|e| e.0 == key) {
            e.1 += beta;
            e.2 += gamma;
        } else {
            out.push((key, beta, gamma));
        }
    };
    // Every T ⊆ φ: node monomial Π_{S∖φ} x · Π_T y with coefficient (−1)^{|T|}.
    let mut t = mask;
    loop {
        let parity = if t.count_ones() % 2 == 1 { -1.0 } else { 1.0 };
        // Nodes: (position, is_y).
        let nodes: Vec<(usize, bool)> = (0..d)
            .filter(|&p| mask >> p & 1 == 0 || t >> p & 1 == 1)
            .map(|p| (p, t >> p & 1 == 1))
            .collect();
        if nodes.len() == 2 || (nodes.len() >= 3 && sign * parity > 0.0) {
            for (i, &(p, py)) in nodes.iter().enumerate() {
                for &(q, qy) in &nodes[i + 1..] {
                    if py == qy {
                        add(p, q, parity, 0.0);
                    } else {
                        add(p, q, 0.0, -parity);
                    }
                }
            }
        }
        if t == 0 {
            break;
        }
        t = (t - 1) & mask;
    }
    out
}

/// Quadratizes `f`: degree-3/4 monomials by GRD with LP-chosen types, the rest by ISH.
pub fn quadratize(f: &Polynomial) -> Quadratization {
    quadratize_with_lp_limit(f, LP_MAX_TERMS)
}

/// [`quadratize`] with groups of more than `lp_max_terms` terms solved term by term.
fn quadratize_with_lp_limit(f: &Polynomial, lp_max_terms: usize) -> Quadratization {
    let mut low = Polynomial::new(f.num_vars());
    low.add_constant(f.constant());
    let mut pool = Polynomial::new(f.num_vars());
    for (lits, a) in f.terms() {
        if lits.len() <= 4 {
            low.add_term(a, lits);
        } else {
            pool.add_term(a, lits);
        }
    }
    let multi = low.to_multinomial_partial(4);
    pool.add_constant(multi.constant());
    let mut pair_coeff: FxHashMap<Pair, f64> = FxHashMap::default();
    let mut terms: Vec<Term> = Vec::new();
    for (lits, a) in multi.terms() {
        match lits.len() {
            0..=2 => {
                if let [l1, l2] = lits {
                    *pair_coeff.entry(pair_key(l1.var(), l2.var())).or_default() += a;
                }
                pool.add_term(a, lits);
            }
            _ => {
                let mut vars: Vec<u32> = lits.iter().map(|l| l.var()).collect();
                vars.sort_unstable();
                terms.push(Term { vars, a });
            }
        }
    }
    terms.sort_by(|x, y| x.vars.cmp(&y.vars));
    let weights = choose_weights(&terms, &pair_coeff, lp_max_terms);
    for (term, w) in terms.iter().zip(&weights) {
        emit(&mut pool, term, w);
    }
    pool.simplify(0.0);
    let q = ish::quadratize(&pool);
    // One monomial per variable pair: QPBO keeps x_u·x_v and x̄_u·x_v as two parallel edges
    // (one non-submodular, one submodular) whose roof dual is weaker than that of their sum
    // (on the paper's cubic example −4 instead of −2).
    let mut poly = q.poly.to_multinomial_partial(2);
    poly.simplify(0.0);
    Quadratization {
        poly,
        num_original_vars: f.num_vars(),
    }
}

fn pair_key(u: u32, v: u32) -> Pair {
    (u.min(v), u.max(v))
}

/// Adds Σ_φ Σ_{T⊆φ} w_φ·(−1)^{|T|}·Π_{S∖φ} x·Π_T x̄ for one term.
fn emit(pool: &mut Polynomial, term: &Term, weights: &[f64]) {
    let d = term.vars.len();
    for (&mask, &w) in type_masks(d).iter().zip(weights) {
        if w == 0.0 {
            continue;
        }
        let mut t = mask;
        loop {
            let parity = if t.count_ones() % 2 == 1 { -1.0 } else { 1.0 };
            let lits: Vec<Literal> = (0..d)
                .filter(|&p| mask >> p & 1 == 0 || t >> p & 1 == 1)
                .map(|p| Literal::new(term.vars[p], t >> p & 1 == 0))
                .collect();
            pool.add_term(parity * w, &lits);
            if t == 0 {
                break;
            }
            t = (t - 1) & mask;
        }
    }
}

/// The weights w_φ of every term (in [`type_masks`] order), summing to the term's a.
fn choose_weights(
    terms: &[Term],
    pair_coeff: &FxHashMap<Pair, f64>,
    lp_max_terms: usize,
) -> Vec<Vec<f64>> {
    // Connected groups: terms sharing a pair.
    let mut parent: Vec<usize> = (0..terms.len()).collect();
    fn root(parent: &mut [usize], mut v: usize) -> usize {
        while parent[v] != v {
            parent[v] = parent[parent[v]];
            v = parent[v];
        }
        v
    }
    let mut owner: FxHashMap<Pair, usize> = FxHashMap::default();
    for (t, term) in terms.iter().enumerate() {
        for (i, &u) in term.vars.iter().enumerate() {
            for &v in &term.vars[i + 1..] {
                let o = *owner.entry((u, v)).or_insert(t);
                let (ra, rb) = (root(&mut parent, o), root(&mut parent, t));
                if ra != rb {
                    parent[ra.max(rb)] = ra.min(rb);
                }
            }
        }
    }
    let mut groups: FxHashMap<usize, Vec<usize>> = FxHashMap::default();
    for t in 0..terms.len() {
        let r = root(&mut parent, t);
        groups.entry(r).or_default().push(t);
    }
    let mut groups: Vec<Vec<usize>> = groups.into_values().collect();
    groups.sort_unstable();
    let mut weights: Vec<Vec<f64>> = vec![Vec::new(); terms.len()];
    let mut cache: FxHashMap<Vec<u64>, Vec<f64>> = FxHashMap::default();
    let no_offsets: FxHashMap<Pair, (f64, f64)> = FxHashMap::default();
    let mut group_cache: FxHashMap<Vec<u64>, Vec<Vec<f64>>> = FxHashMap::default();
    for group in groups {
        if group.len() == 1 || group.len() > lp_max_terms {
            // Term by term, each seeing the rows its predecessors used.
            let mut used: FxHashMap<Pair, (f64, f64)> = FxHashMap::default();
            for &t in &group {
                let term = &terms[t];
                let key = cache_key(term, pair_coeff, &used);
                let w = match cache.get(&key) {
                    Some(w) => w.clone(),
                    None => {
                        let w = solve_lp(&[term], pair_coeff, &used).swap_remove(0);
                        cache.insert(key, w.clone());
                        w
                    }
                };
                add_used(&mut used, term, &w);
                weights[t] = w;
            }
        } else {
            let refs: Vec<&Term> = group.iter().map(|&t| &terms[t]).collect();
            let key = group_key(&refs, pair_coeff);
            let ws = match group_cache.get(&key) {
                Some(ws) => ws.clone(),
                None => {
                    let ws = solve_lp(&refs, pair_coeff, &no_offsets);
                    group_cache.insert(key, ws.clone());
                    ws
                }
            };
            for (&t, w) in group.iter().zip(ws) {
                weights[t] = w;
            }
        }
    }
    weights
}

/// The LP data of a single term: a, and per inner pair its coefficient and used rows.
fn cache_key(
    term: &Term,
    pair_coeff: &FxHashMap<Pair, f64>,
    used: &FxHashMap<Pair, (f64, f64)>,
) -> Vec<u64> {
    let mut key = vec![term.vars.len() as u64, term.a.to_bits()];
    for (i, &u) in term.vars.iter().enumerate() {
        for &v in &term.vars[i + 1..] {
            let (b, g) = used.get(&(u, v)).copied().unwrap_or((0.0, 0.0));
            let a = pair_coeff.get(&(u, v)).copied().unwrap_or(0.0);
            key.extend([a.to_bits(), b.to_bits(), g.to_bits()]);
        }
    }
    key
}

/// The LP data of a group with its variables renamed by first appearance: two groups with
/// the same key have the same LP (up to the renaming), hence the same solution.
fn group_key(group: &[&Term], pair_coeff: &FxHashMap<Pair, f64>) -> Vec<u64> {
    let mut rename: FxHashMap<u32, u64> = FxHashMap::default();
    let mut key = Vec::new();
    for term in group {
        key.extend([term.vars.len() as u64, term.a.to_bits()]);
        for &v in &term.vars {
            let next = rename.len() as u64;
            key.push(*rename.entry(v).or_insert(next));
        }
        for (i, &u) in term.vars.iter().enumerate() {
            for &v in &term.vars[i + 1..] {
                key.push(pair_coeff.get(&(u, v)).copied().unwrap_or(0.0).to_bits());
            }
        }
    }
    key
}

/// Adds a term's β and γ contributions (at weights `w`) to `used`.
fn add_used(used: &mut FxHashMap<Pair, (f64, f64)>, term: &Term, w: &[f64]) {
    let d = term.vars.len();
    for (&mask, &wt) in type_masks(d).iter().zip(w) {
        for ((p, q), beta, gamma) in contributions(d, mask, term.a.signum()) {
            let e = used.entry((term.vars[p], term.vars[q])).or_default();
            e.0 += wt * beta;
            e.1 += wt * gamma;
        }
    }
}

/// Solves the GRD LP for `terms` jointly; `offsets` are β, γ already used per pair.
/// Returns the weights of each term in [`type_masks`] order.
fn solve_lp(
    terms: &[&Term],
    pair_coeff: &FxHashMap<Pair, f64>,
    offsets: &FxHashMap<Pair, (f64, f64)>,
) -> Vec<Vec<f64>> {
    let mut lp = Problem::new(OptimizationDirection::Maximize);
    // u_φ ≥ 0 with w_φ = a·u_φ and Σ u_φ = 1.
    let mut rows: FxHashMap<Pair, (Row, Row)> = FxHashMap::default();
    let mut pair_order: Vec<Pair> = Vec::new();
    let mut vars: Vec<Vec<microlp::Variable>> = Vec::with_capacity(terms.len());
    for term in terms {
        let d = term.vars.len();
        let masks = type_masks(d);
        let mut us = Vec::with_capacity(masks.len());
        for &mask in &masks {
            let obj = if mask == 0 { term.a } else { 0.0 };
            let u = lp.add_var(obj, (0.0, f64::INFINITY));
            us.push(u);
            for ((p, q), beta, gamma) in contributions(d, mask, term.a.signum()) {
                let key = (term.vars[p], term.vars[q]);
                let entry = rows.entry(key).or_insert_with(|| {
                    pair_order.push(key);
                    (Vec::new(), Vec::new())
                });
                if beta != 0.0 {
                    entry.0.push((u, term.a * beta));
                }
                if gamma != 0.0 {
                    entry.1.push((u, term.a * gamma));
                }
            }
        }
        let sum: Vec<(microlp::Variable, f64)> = us.iter().map(|&u| (u, 1.0)).collect();
        lp.add_constraint(sum.as_slice(), ComparisonOp::Eq, 1.0);
        vars.push(us);
    }
    for key in &pair_order {
        let (beta, gamma) = &rows[key];
        let (b0, g0) = offsets.get(key).copied().unwrap_or((0.0, 0.0));
        let a = pair_coeff.get(key).copied().unwrap_or(0.0);
        let t = lp.add_var(1.0, (f64::NEG_INFINITY, f64::INFINITY));
        // t + β₀ + β(u) ≤ 0
        let mut row = vec![(t, 1.0)];
        row.extend(beta.iter().copied());
        lp.add_constraint(row.as_slice(), ComparisonOp::Le, -b0);
        // t − γ₀ − γ(u) ≤ a
        let mut row = vec![(t, 1.0)];
        row.extend(gamma.iter().map(|&(u, c)| (u, -c)));
        lp.add_constraint(row.as_slice(), ComparisonOp::Le, a + g0);
    }
    let solution = lp.solve().ok().and_then(|s| s.into_solution().ok());
    terms
        .iter()
        .zip(&vars)
        .map(|(term, us)| {
            let mut u: Vec<f64> = match &solution {
                Some(s) => us.iter().map(|&v| s.var_value(v).max(0.0)).collect(),
                // The LP is always feasible and bounded; should the solver fail, use ISH's
                // type (b) for the whole term.
                None => us
                    .iter()
                    .enumerate()
                    .map(|(i, _)| f64::from(u8::from(i == 0)))
                    .collect(),
            };
            for x in &mut u {
                if *x < 1e-9 {
                    *x = 0.0;
                }
            }
            let total: f64 = u.iter().sum();
            let mut w: Vec<f64> = u.iter().map(|x| term.a * x / total).collect();
            // Make Σ w = a as exact as floating point allows.
            if let Some(last) = w.iter().rposition(|&x| x != 0.0) {
                let rest: f64 = w
                    .iter()
                    .enumerate()
                    .filter(|&(i, _)| i != last)
                    .map(|(_, x)| x)
                    .sum();
                w[last] = term.a - rest;
            }
            w
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::qssr::build_qpbo;
    use crate::quadratize::tests::{arb_higher_order, assert_exact};
    use crate::quadratize::{quadratize as quadratize_with, Quadratizer};
    use proptest::prelude::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// QPBO's roof-dual lower bound of a quadratization (or of a quadratic function).
    fn qpbo_bound(q: &Quadratization) -> f64 {
        let mut inst = build_qpbo(&q.poly);
        inst.qpbo.solve();
        inst.qpbo.lower_bound()
    }

    fn bound_of(f: &Polynomial, method: Quadratizer) -> f64 {
        qpbo_bound(&quadratize_with(f, method))
    }

    /// f = c + Σ aᵢxᵢ + Σ a_P x_P + Σ a_S x_S over positive literals from (vars, a) lists.
    fn multilinear(n: usize, terms: &[(&[u32], f64)]) -> Polynomial {
        let mut f = Polynomial::new(n);
        for (vars, a) in terms {
            let lits: Vec<Literal> = vars.iter().map(|&v| Literal::pos(v)).collect();
            f.add_term(*a, &lits);
        }
        f
    }

    /// A random multilinear function on `n` variables: every linear term, every pair, and
    /// each triple (and quad, if `quartic`) with probability ½, integer coefficients in
    /// [−9, 9] (the design's random instances).
    fn random_multilinear(rng: &mut ChaCha8Rng, n: usize, quartic: bool) -> Polynomial {
        let mut f = Polynomial::new(n);
        let max = if quartic { 4 } else { 3 };
        for mask in 1u32..1 << n {
            let k = mask.count_ones() as usize;
            if k > max || (k >= 3 && rng.gen_bool(0.5)) {
                continue;
            }
            let lits: Vec<Literal> = (0..n as u32)
                .filter(|&v| mask >> v & 1 == 1)
                .map(Literal::pos)
                .collect();
            f.add_term(f64::from(rng.gen_range(-9i32..=9)), &lits);
        }
        f
    }

    #[test]
    fn contributions_match_the_design_table() {
        // Cubic, a > 0: B_ij += b + c; B_ik += b + d; B_jk += b + e; no cross rows.
        let pos: Vec<_> = type_masks(3)
            .iter()
            .map(|&m| {
                let mut c = contributions(3, m, 1.0);
                c.sort_by_key(|e| e.0);
                c
            })
            .collect();
        assert_eq!(
            pos[0],
            vec![((0, 1), 1.0, 0.0), ((0, 2), 1.0, 0.0), ((1, 2), 1.0, 0.0)]
        );
        assert_eq!(pos[3], vec![((0, 1), 1.0, 0.0)]); // c = {k}: pair ij
                                                      // Cubic, a < 0: type c gives C_ik, C_jk += c (w ≤ 0) and nothing net on B_ij.
        let neg = contributions(3, 4, -1.0);
        let get = |p: (usize, usize)| {
            neg.iter()
                .find(|e| e.0 == p)
                .map_or((0.0, 0.0), |e| (e.1, e.2))
        };
        assert_eq!(get((0, 1)), (0.0, 0.0));
        assert_eq!(get((0, 2)), (0.0, 1.0));
        assert_eq!(get((1, 2)), (0.0, 1.0));
        // Quartic, a > 0, q = {k, l}: B_ij += 2q, B_kl += q, C_ik −= q.
        let q = contributions(4, 0b1100, 1.0);
        let get = |p: (usize, usize)| {
            q.iter()
                .find(|e| e.0 == p)
                .map_or((0.0, 0.0), |e| (e.1, e.2))
        };
        assert_eq!(get((0, 1)), (2.0, 0.0));
        assert_eq!(get((2, 3)), (1.0, 0.0));
        assert_eq!(get((0, 2)), (0.0, -1.0));
    }

    #[test]
    fn single_terms_give_the_designs_bounds() {
        // a·x0x1x2: a < 0 → a; a > 0 → −a/2 (ISH −a). x0x1x2x3 → −1.5 (ISH −2.5).
        for a in [1.0, 3.0, -2.0] {
            let f = multilinear(3, &[(&[0, 1, 2], a)]);
            let want = if a > 0.0 { -a / 2.0 } else { a };
            assert!(
                (bound_of(&f, Quadratizer::Grd) - want).abs() < 1e-9,
                "a={a}"
            );
        }
        let f = multilinear(4, &[(&[0, 1, 2, 3], 1.0)]);
        assert!((bound_of(&f, Quadratizer::Grd) + 1.5).abs() < 1e-9);
        assert!((bound_of(&f, Quadratizer::Ish) + 2.5).abs() < 1e-9);
        let f = multilinear(4, &[(&[0, 1, 2, 3], -1.0)]);
        assert!((bound_of(&f, Quadratizer::Grd) + 1.0).abs() < 1e-9);
    }

    #[test]
    fn paper_cubic_example_is_tight() {
        // −2x0 + x1 − x2 + 4x0x1 + 4x0x2 − 2x1x2 − 2x0x1x2 (tests/cubic_paper.txt of the
        // authors' code): min f = −2 at 100 and 011; GRD's bound is −2, ISH/ASM/FIX's −3.
        let f = multilinear(
            3,
            &[
                (&[0], -2.0),
                (&[1], 1.0),
                (&[2], -1.0),
                (&[0, 1], 4.0),
                (&[0, 2], 4.0),
                (&[1, 2], -2.0),
                (&[0, 1, 2], -2.0),
            ],
        );
        assert_eq!(f.brute_force_minimum().0, -2.0);
        let q = quadratize(&f);
        assert_exact(&f, &q).unwrap();
        let mut inst = build_qpbo(&q.poly);
        inst.qpbo.solve();
        assert!((inst.qpbo.lower_bound() + 2.0).abs() < 1e-9);
        // Both minimisers differ in every variable, so no variable is strongly persistent;
        // the weak persistencies label all three to one of the minimisers.
        inst.qpbo.compute_weak_persistencies();
        let labels: Vec<Option<bool>> = (0..3)
            .map(|v| inst.node_of_var[v].and_then(|i| inst.qpbo.label(i).value()))
            .collect();
        let x: Vec<bool> = labels.iter().map(|l| l.expect("labelled")).collect();
        assert_eq!(f.evaluate(&x), -2.0, "labels {x:?}");
        for method in [Quadratizer::Ish, Quadratizer::Asm, Quadratizer::Fix] {
            assert!((bound_of(&f, method) + 3.0).abs() < 1e-9, "{method}");
        }
    }

    #[test]
    fn cached_group_solution_is_reused_on_a_renamed_copy() {
        // Two disjoint copies of the paper's cubic example (a 1-term group with 3 pairs)
        // plus a 2-term group copied once: the second copies come from the caches and
        // must be as tight as the first (bound = sum of the copies' bounds).
        let paper = |o: u32| -> Vec<(Vec<u32>, f64)> {
            vec![
                (vec![o], -2.0),
                (vec![o + 1], 1.0),
                (vec![o + 2], -1.0),
                (vec![o, o + 1], 4.0),
                (vec![o, o + 2], 4.0),
                (vec![o + 1, o + 2], -2.0),
                (vec![o, o + 1, o + 2], -2.0),
            ]
        };
        let pair = |o: u32| -> Vec<(Vec<u32>, f64)> {
            vec![
                (vec![o, o + 1, o + 2], 3.0),
                (vec![o, o + 1, o + 3], -2.0),
                (vec![o + 2], 1.0),
            ]
        };
        let build = |parts: &[Vec<(Vec<u32>, f64)>], n: usize| {
            let mut f = Polynomial::new(n);
            for (vars, a) in parts.iter().flatten() {
                let lits: Vec<Literal> = vars.iter().map(|&v| Literal::pos(v)).collect();
                f.add_term(*a, &lits);
            }
            f
        };
        let one = bound_of(&build(&[paper(0), pair(3)], 7), Quadratizer::Grd);
        let f = build(&[paper(0), pair(3), paper(7), pair(10)], 14);
        let q = quadratize(&f);
        assert!(
            (qpbo_bound(&q) - 2.0 * one).abs() < 1e-9,
            "{} vs 2·{one}",
            qpbo_bound(&q)
        );
        let two = build(&[paper(0), pair(3)], 7);
        assert_exact(&two, &quadratize(&two)).unwrap();
        assert!((one + 2.0 - bound_of(&build(&[pair(0)], 4), Quadratizer::Grd)).abs() < 1e-9);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]
        /// min over slacks of ρ is f, ρ is quadratic, and QPBO's bound on ρ is ≤ min f
        /// (exactness by enumeration where there are at most 16 slacks: a few inputs of
        /// many quartic terms have more, and 2^(6 + slacks) worlds would take minutes).
        #[test]
        fn grd_is_exact_and_its_bound_is_below_the_minimum(f in arb_higher_order(6)) {
            let q = quadratize(&f);
            if q.num_slacks() <= 16 {
                assert_exact(&f, &q)?;
            }
            let (min, _) = f.brute_force_minimum();
            prop_assert!(qpbo_bound(&q) <= min + 1e-9);
        }

        /// The term-by-term path (used above [`LP_MAX_TERMS`]) is exact as well, and its
        /// bound is below the minimum.
        #[test]
        fn term_by_term_path_is_exact(seed in any::<u64>(), n in 3usize..=6, quartic in any::<bool>()) {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let f = random_multilinear(&mut rng, n, quartic);
            let q = quadratize_with_lp_limit(&f, 0);
            if q.num_slacks() <= 12 {
                assert_exact(&f, &q)?;
            }
            let (min, _) = f.brute_force_minimum();
            prop_assert!(qpbo_bound(&q) <= min + 1e-9);
        }

        /// The same on multilinear cubic and quartic functions (every term expanded).
        #[test]
        fn grd_is_exact_on_multilinear_functions(seed in any::<u64>(), n in 3usize..=6, quartic in any::<bool>()) {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let f = random_multilinear(&mut rng, n, quartic);
            let q = quadratize(&f);
            if q.num_slacks() <= 12 {
                assert_exact(&f, &q)?;
            }
            let (min, _) = f.brute_force_minimum();
            prop_assert!(qpbo_bound(&q) <= min + 1e-9);
        }
    }

    /// GRD's roof dual is never below ISH's on random cubic functions (observed by the
    /// design on 293 instances, not proven). Against ASM and FIX it is not a dominance:
    /// on these 300 cubic seeds (n = 4–5) GRD's bound won/tied/lost 146/154/0 against ISH,
    /// 81/217/2 against ASM and 109/191/0 against FIX; with quartics (same seeds) 192/108/0
    /// against ISH, 155/144/1 against ASM and 148/139/13 against FIX (measured when written;
    /// printed with `--nocapture`).
    #[test]
    fn grd_bound_is_at_least_ish_on_random_cubics() {
        let tally = |quartic: bool| {
            let mut counts = [[0usize; 3]; 3];
            for seed in 0..300u64 {
                let mut rng = ChaCha8Rng::seed_from_u64(seed);
                let n = 4 + (seed % 2) as usize;
                let f = random_multilinear(&mut rng, n, quartic);
                let grd = bound_of(&f, Quadratizer::Grd);
                let min = f.brute_force_minimum().0;
                assert!(grd <= min + 1e-9, "seed {seed}: bound {grd} > min {min}");
                for (k, m) in [Quadratizer::Ish, Quadratizer::Asm, Quadratizer::Fix]
                    .into_iter()
                    .enumerate()
                {
                    let other = bound_of(&f, m);
                    let slot = if grd > other + 1e-9 {
                        0
                    } else if grd < other - 1e-9 {
                        2
                    } else {
                        1
                    };
                    counts[k][slot] += 1;
                    if m == Quadratizer::Ish && !quartic {
                        assert!(grd >= other - 1e-9, "seed {seed}: GRD {grd} < ISH {other}");
                    }
                }
            }
            counts
        };
        let cubic = tally(false);
        let quartic = tally(true);
        println!("won/tied/lost vs ish, asm, fix: cubic {cubic:?}, quartic {quartic:?}");
    }
}
