//! QPBO-P: probing unlabelled variables to find more persistencies and equivalences.
//!
//! Boros, Hammer & Tavares, "Preprocessing of unconstrained quadratic binary optimization",
//! RUTCOR RRR 10-2006, and Rother, Kolmogorov, Lempitsky & Szummer, CVPR 2007, §3.1. For an
//! unlabelled variable xₖ, QPBO is run on the function restricted to xₖ = 0 and to xₖ = 1:
//! - a variable labelled `a` in both branches is persistent with value `a`;
//! - a variable labelled `a` in branch 0 and `¬a` in branch 1 satisfies xᵤ = xₖ xor a;
//! - a branch whose roof-dual bound exceeds the energy of a known assignment is infeasible
//!   for every minimiser, so xₖ takes the other value.
//!
//! Every finding is substituted into the function before the next probe, so all fixed
//! values and equivalences hold jointly: with strong persistencies only, in *every* global
//! minimiser; with weak persistencies (the default, more labels), in *some* global
//! minimiser.
//!
//! A branch does not solve its restricted function anew: it forces xₖ in a copy of the
//! solved doubled graph by terminal links no cut can afford and continues the max-flow
//! from the current flow with the search trees kept (Kohli & Torr's dynamic cuts, as
//! Kolmogorov's QPBO-P does); bound and strong labels equal those of the substituted
//! function (test). Values found are fixed the same way in place; an equivalence makes
//! the function be rebuilt with it substituted. A probe costs O(graph copy + the flow
//! the fixing disturbs + weak persistencies).

use super::reduce::{expand, Subst};
use super::{Label, Qpbo};
use crate::maxflow::Capacity;

/// Options of [`Qpbo::probe`].
#[derive(Debug, Clone)]
pub struct ProbeOptions {
    /// Use weakly persistent labels (more fixed variables; the result then holds in some
    /// global minimiser instead of every one).
    pub weak_persistencies: bool,
    /// Upper limit on the number of probed variables. Each probe costs two QPBO solves of
    /// the remaining function, so probing all of a large function is expensive.
    pub max_probes: usize,
}

impl Default for ProbeOptions {
    fn default() -> Self {
        ProbeOptions {
            weak_persistencies: true,
            max_probes: 1_000,
        }
    }
}

/// What probing found, per original variable.
#[derive(Debug, Clone)]
pub struct ProbeResult {
    /// Persistent values, jointly extendable to a global minimiser (see [`ProbeOptions`]).
    pub fixed: Vec<Option<bool>>,
    /// `Some((j, neg))`: xᵢ = xⱼ xor `neg` in the same minimisers (j is never fixed and
    /// never itself equivalent to another variable).
    pub equivalent: Vec<Option<(usize, bool)>>,
    /// Number of probed variables.
    pub probes: usize,
    /// The best assignment seen (persistent values applied), and its energy.
    pub best_assignment: Vec<bool>,
    /// Energy of `best_assignment` (as `f64`, so the result type is not generic).
    pub best_energy: f64,
}

/// Whether `a > b` beyond the round-off tolerance `tol` (zero for integers).
#[inline]
fn definitely_greater<T: Capacity>(a: T, b: T, tol: T) -> bool {
    a > b + tol
}

/// Union-find with parity over the original variables.
struct Classes {
    parent: Vec<(u32, bool)>,
    value: Vec<Option<bool>>,
}

impl Classes {
    fn new(n: usize) -> Self {
        Classes {
            parent: (0..n as u32).map(|i| (i, false)).collect(),
            value: vec![None; n],
        }
    }

    /// (root, parity) with xᵢ = x_root xor parity.
    fn find(&self, mut i: usize) -> (usize, bool) {
        let mut parity = false;
        loop {
            let (p, par) = self.parent[i];
            if p as usize == i {
                return (i, parity);
            }
            parity ^= par;
            i = p as usize;
        }
    }

    /// Records x_i = v (through i's class).
    fn set_value(&mut self, i: usize, v: bool) {
        let (root, parity) = self.find(i);
        self.value[root] = Some(v ^ parity);
    }

    /// Records x_i = x_j xor a; returns whether the classes changed. Classes with a value
    /// pass it on instead of joining.
    fn join(&mut self, i: usize, j: usize, a: bool) -> bool {
        let (ri, pi) = self.find(i);
        let (rj, pj) = self.find(j);
        if ri == rj {
            return false;
        }
        // x_ri = x_rj xor (a ^ pi ^ pj)
        let parity = a ^ pi ^ pj;
        match (self.value[ri], self.value[rj]) {
            (Some(_), Some(_)) => false,
            (Some(vi), None) => {
                self.value[rj] = Some(vi ^ parity);
                true
            }
            (None, Some(vj)) => {
                self.value[ri] = Some(vj ^ parity);
                true
            }
            (None, None) => {
                self.parent[ri] = (rj as u32, parity);
                true
            }
        }
    }

    fn subst(&self) -> (Vec<Subst>, Vec<usize>) {
        let n = self.parent.len();
        let mut new_index = vec![u32::MAX; n];
        let mut roots = Vec::new();
        let mut subst = Vec::with_capacity(n);
        for i in 0..n {
            let (r, par) = self.find(i);
            if let Some(v) = self.value[r] {
                subst.push(Subst::Value(v ^ par));
                continue;
            }
            if new_index[r] == u32::MAX {
                new_index[r] = roots.len() as u32;
                roots.push(r);
            }
            subst.push(Subst::Lit(new_index[r], par));
        }
        (subst, roots)
    }
}

impl<T: Capacity> Qpbo<T> {
    /// Probing (QPBO-P): fixes more variables than [`Qpbo::solve`] and finds equivalences.
    ///
    /// Works on the original function (the terms added so far) and leaves it unchanged;
    /// afterwards [`Qpbo::label`] reports the fixed variables.
    pub fn probe(&mut self, options: &ProbeOptions) -> ProbeResult {
        let n = self.num_vars();
        let mut classes = Classes::new(n);
        let mut best_x = vec![false; n];
        let mut best_e = self.energy(&best_x);
        let mut probes = 0usize;
        let mut cursor = 0usize; // original root index where probing resumes
                                 // Energies are sums of many terms: compare bounds with a tolerance of 1e-9 times
                                 // (number of terms) times the largest energy for floats.
        let tol = if T::IS_FLOAT {
            let terms = (n + self.num_pairwise() + 1) as f64;
            T::from_f64(self.energy_scale().to_f64() * 1e-9 * terms)
        } else {
            T::ZERO
        };
        let solve_labels = |q: &mut Qpbo<T>| {
            q.solve();
            if options.weak_persistencies {
                q.compute_weak_persistencies();
            }
        };
        'outer: loop {
            let (subst, roots) = classes.subst();
            if roots.is_empty() {
                break;
            }
            let mut r = self.restrict(&subst, roots.len());
            solve_labels(&mut r);
            let x = expand(&subst, &r.labelling_or_zero());
            let e = self.energy(&x);
            if e < best_e {
                best_e = e;
                best_x = x;
            }
            let mut changed = false;
            for (k, &root) in roots.iter().enumerate() {
                if let Some(v) = r.label(k).value() {
                    classes.value[root] = Some(v);
                    changed = true;
                }
            }
            if changed {
                continue;
            }
            // Probe candidates in cyclic order from the cursor. Values found are fixed in r
            // at once (max-flow continued from r's flow: r then equals the function with
            // them substituted); a probe that finds an equivalence rebuilds r, so that each
            // finding is made on the function with all earlier ones applied (which keeps
            // weak persistencies jointly valid).
            let m = roots.len();
            let start = roots.partition_point(|&rt| rt < cursor);
            let mut found_any = false;
            for step in 0..m {
                if probes >= options.max_probes {
                    break 'outer;
                }
                let k = (start + step) % m;
                if r.label(k).value().is_some() {
                    continue;
                }
                cursor = roots[k] + 1;
                probes += 1;
                let Some(branches) =
                    self.probe_branches(&r, k, &subst, options, &mut best_x, &mut best_e)
                else {
                    // r needed no doubled graph: every variable is labelled.
                    break;
                };
                let twice_best = best_e + best_e;
                let mut values: Vec<(usize, bool)> = Vec::new();
                let mut joined = false;
                if definitely_greater(branches[0].1, twice_best, tol) {
                    values.push((k, true));
                } else if definitely_greater(branches[1].1, twice_best, tol) {
                    values.push((k, false));
                } else {
                    for u in 0..m {
                        if u == k || r.label(u).value().is_some() {
                            continue;
                        }
                        match (branches[0].0[u].value(), branches[1].0[u].value()) {
                            (Some(a), Some(b)) if a == b => values.push((u, a)),
                            (Some(a), Some(_)) => {
                                // x_u = x_k xor a
                                joined |= classes.join(roots[u], roots[k], a);
                            }
                            _ => {}
                        }
                    }
                }
                for &(u, v) in &values {
                    classes.set_value(roots[u], v);
                }
                if joined {
                    continue 'outer;
                }
                if values.is_empty() {
                    continue;
                }
                found_any = true;
                r.fix_values(&values, options.weak_persistencies);
                // Fixing may label more variables of r: they are persistent too.
                for (u, &root) in roots.iter().enumerate() {
                    if let Some(v) = r.label(u).value() {
                        classes.set_value(root, v);
                    }
                }
            }
            if !found_any {
                break;
            }
        }
        let mut fixed = vec![None; n];
        let mut equivalent = vec![None; n];
        for i in 0..n {
            let (root, par) = classes.find(i);
            if let Some(v) = classes.value[root] {
                fixed[i] = Some(v ^ par);
                self.set_label(i, Label::from_bool(v ^ par));
            } else if root != i {
                equivalent[i] = Some((root, par));
            }
        }
        // Apply the persistent values to the best assignment (never worse for weak
        // persistency, which is an autarky; kept only if not worse).
        let mut x = best_x.clone();
        for (xi, f) in x.iter_mut().zip(&fixed) {
            if let Some(v) = f {
                *xi = *v;
            }
        }
        let e = self.energy(&x);
        if e <= best_e {
            best_e = e;
            best_x = x;
        }
        ProbeResult {
            fixed,
            equivalent,
            probes,
            best_assignment: best_x,
            best_energy: best_e.to_f64(),
        }
    }
}

impl<T: Capacity> Qpbo<T> {
    /// Both branches of probing r's variable k (x_k = 0, x_k = 1): labels of r's variables
    /// and twice the bound of each; the assignments they give update the best one known
    /// (`subst` maps this function's variables onto r's). `None`: r has no doubled graph.
    fn probe_branches(
        &self,
        r: &Qpbo<T>,
        k: usize,
        subst: &[Subst],
        options: &ProbeOptions,
        best_x: &mut Vec<bool>,
        best_e: &mut T,
    ) -> Option<[(Vec<Label>, T); 2]> {
        // The two branches are independent: solved side by side.
        let branch = |value: bool| {
            r.solve_fixed(k, value, options.weak_persistencies)
                .map(|(labels, twice)| {
                    let mut y: Vec<bool> =
                        labels.iter().map(|l| l.value().unwrap_or(false)).collect();
                    y[k] = value;
                    // r's energy equals this function's on the expanded assignment.
                    let e = r.energy(&y);
                    (labels, twice, y, e)
                })
        };
        let (b0, b1) = rayon::join(|| branch(false), || branch(true));
        let (b0, b1) = (b0?, b1?);
        for (_, _, y, e) in [&b0, &b1] {
            // The cheap check on r decides whether to expand.
            if *e < *best_e {
                let x = expand(subst, y);
                let e = self.energy(&x);
                if e < *best_e {
                    *best_e = e;
                    *best_x = x;
                }
            }
        }
        let out = [(b0.0, b0.1), (b1.0, b1.1)];
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn a_branch_continued_from_the_flow_equals_the_restricted_function() {
        // solve_fixed forces x_k in a copy of the solved doubled graph; the bound and the
        // strong labels must equal those of the function with x_k substituted, solved anew.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let mut compared = 0;
        for _ in 0..200 {
            let n = rng.gen_range(2..9);
            let mut q = Qpbo::<i32>::new(n, 2 * n);
            for i in 0..n {
                q.add_unary(i, rng.gen_range(-5..6), rng.gen_range(-5..6));
            }
            for _ in 0..rng.gen_range(1..3 * n) {
                let (i, j) = (rng.gen_range(0..n), rng.gen_range(0..n));
                if i != j {
                    let e: [i32; 4] = std::array::from_fn(|_| rng.gen_range(-6..7));
                    q.add_pairwise(i, j, e[0], e[1], e[2], e[3]);
                }
            }
            q.solve();
            for k in 0..n {
                for value in [false, true] {
                    let Some((labels, twice)) = q.solve_fixed(k, value, false) else {
                        continue;
                    };
                    let sub: Vec<Subst> = (0..n as u32)
                        .map(|u| {
                            if u as usize == k {
                                Subst::Value(value)
                            } else {
                                Subst::Lit(u, false)
                            }
                        })
                        .collect();
                    let mut rb = q.restrict(&sub, n);
                    rb.solve();
                    assert_eq!(twice, rb.twice_lower_bound());
                    assert_eq!(labels[k], Label::from_bool(value));
                    for u in (0..n).filter(|&u| u != k) {
                        assert_eq!(labels[u], rb.label(u), "variable {u}, x{k} = {value}");
                    }
                    compared += 1;
                }
            }
        }
        assert!(compared > 100);
    }

    #[test]
    fn probing_labels_a_frustrated_pair_behind_a_strong_unary() {
        // x0 = x1 preferred strongly, x0 != x1 preferred by two others: QPBO alone may
        // leave things unlabelled; probing must find values consistent with brute force.
        let mut q = Qpbo::<i32>::new(3, 3);
        q.add_pairwise(0, 1, 0, 4, 4, 0);
        q.add_pairwise(1, 2, 3, 0, 0, 3);
        q.add_pairwise(0, 2, 3, 0, 0, 3);
        q.add_unary(0, 0, 1);
        let res = q.probe(&ProbeOptions::default());
        let min = (0..8u32)
            .map(|b| q.energy(&[b & 1 == 1, b & 2 == 2, b & 4 == 4]))
            .min()
            .unwrap_or(i32::MAX);
        assert_eq!(res.best_energy, f64::from(min));
        assert!(res.fixed.iter().all(|f| f.is_some()));
    }
}
