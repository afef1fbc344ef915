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
//! minimiser. Each probe costs two QPBO solves, O(max-flow).

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
            // Probe candidates in cyclic order from the cursor.
            let m = roots.len();
            let start = roots.partition_point(|&rt| rt < cursor);
            for step in 0..m {
                if probes >= options.max_probes {
                    break 'outer;
                }
                let k = (start + step) % m;
                cursor = roots[k] + 1;
                probes += 1;
                let mut branch_labels: [Vec<Label>; 2] = [Vec::new(), Vec::new()];
                let mut branch_bound = [T::ZERO; 2];
                for (b, value) in [false, true].into_iter().enumerate() {
                    let sub: Vec<Subst> = (0..m as u32)
                        .map(|u| {
                            if u as usize == k {
                                Subst::Value(value)
                            } else {
                                Subst::Lit(u, false)
                            }
                        })
                        .collect();
                    let mut rb = r.restrict(&sub, m);
                    solve_labels(&mut rb);
                    let y = expand(&sub, &rb.labelling_or_zero());
                    let x = expand(&subst, &y);
                    let e = self.energy(&x);
                    if e < best_e {
                        best_e = e;
                        best_x = x;
                    }
                    branch_bound[b] = rb.twice_lower_bound();
                    branch_labels[b] = rb.labels().to_vec();
                }
                let twice_best = best_e + best_e;
                if definitely_greater(branch_bound[0], twice_best, tol) {
                    classes.value[roots[k]] = Some(true);
                    continue 'outer;
                }
                if definitely_greater(branch_bound[1], twice_best, tol) {
                    classes.value[roots[k]] = Some(false);
                    continue 'outer;
                }
                for u in 0..m {
                    if u == k {
                        continue;
                    }
                    match (branch_labels[0][u].value(), branch_labels[1][u].value()) {
                        (Some(a), Some(b)) if a == b => {
                            classes.value[roots[u]] = Some(a);
                            changed = true;
                        }
                        (Some(a), Some(_)) => {
                            // x_u = x_k xor a
                            classes.parent[roots[u]] = (roots[k] as u32, a);
                            changed = true;
                        }
                        _ => {}
                    }
                }
                if changed {
                    continue 'outer;
                }
            }
            break;
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

#[cfg(test)]
mod tests {
    use super::*;

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
