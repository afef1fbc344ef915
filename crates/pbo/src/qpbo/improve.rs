//! QPBO-I: improving a given assignment by roof duality on random restrictions.
//!
//! Rother, Kolmogorov, Lempitsky & Szummer, "Optimizing binary MRFs via extended roof
//! duality", CVPR 2007, §3.2: fix a random subset of the variables to their current values,
//! run QPBO with weak persistencies on the rest, and overwrite the labelled variables. The
//! weakly persistent labelling is an autarky, so the energy never increases; each round
//! costs one QPBO solve, O(max-flow).

use super::reduce::{expand, Subst};
use super::Qpbo;
use crate::maxflow::Capacity;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Options of [`Qpbo::improve`].
#[derive(Debug, Clone)]
pub struct ImproveOptions {
    /// Number of restrict-and-solve rounds (0: only evaluates the energy).
    pub rounds: usize,
    /// Seed of the random subsets.
    pub seed: u64,
    /// Probability that a variable is held at its current value in a round.
    pub fix_probability: f64,
}

impl Default for ImproveOptions {
    fn default() -> Self {
        ImproveOptions {
            rounds: 20,
            seed: 0,
            fix_probability: 0.5,
        }
    }
}

impl<T: Capacity> Qpbo<T> {
    /// Improves assignment `x` in place (QPBO-I) and returns its energy, which never
    /// exceeds the energy of the input (a round whose result is worse, e.g. by float
    /// round-off, is discarded).
    pub fn improve(&mut self, x: &mut [bool], options: &ImproveOptions) -> T {
        assert_eq!(x.len(), self.num_vars(), "assignment length");
        let mut best = self.energy(x);
        let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
        let n = self.num_vars();
        let mut subst = vec![Subst::Value(false); n];
        for _ in 0..options.rounds {
            let mut num_free = 0u32;
            for i in 0..n {
                if rng.gen_bool(options.fix_probability.clamp(0.0, 1.0)) {
                    subst[i] = Subst::Value(x[i]);
                } else {
                    subst[i] = Subst::Lit(num_free, false);
                    num_free += 1;
                }
            }
            if num_free == 0 {
                continue;
            }
            let mut r = self.restrict(&subst, num_free as usize);
            r.solve();
            r.compute_weak_persistencies();
            // Unlabelled variables keep their current value.
            let mut y = vec![false; num_free as usize];
            for i in 0..n {
                if let Subst::Lit(k, _) = subst[i] {
                    y[k as usize] = r.label(k as usize).value().unwrap_or(x[i]);
                }
            }
            let candidate = expand(&subst, &y);
            let e = self.energy(&candidate);
            if e <= best {
                best = e;
                x.copy_from_slice(&candidate);
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn improve_fixes_a_bad_assignment_of_a_submodular_chain() {
        let mut q = Qpbo::<i32>::new(3, 2);
        q.add_unary(0, 0, 5);
        q.add_pairwise(0, 1, 0, 3, 3, 0);
        q.add_pairwise(1, 2, 0, 3, 3, 0);
        let mut x = vec![true, false, true];
        let before = q.energy(&x);
        let after = q.improve(&mut x, &ImproveOptions::default());
        assert!(after <= before);
        assert_eq!(after, q.energy(&x));
        assert_eq!(after, 0);
    }
}
