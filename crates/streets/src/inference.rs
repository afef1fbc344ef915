//! MAP inference of eq. 4.3 over the street network: exact max-product on trees, loopy
//! max-product on networks with loops, and parallel seeded MCMC (the thesis' method).
//!
//! States of a segment are column ranges `a ..= b` ([`crate::potentials::ThetaGrid`]). The
//! intersegment potential N(a₁−a₂|0,σ)·N(b₁−b₂|0,σ) is separable in the two boundaries, so a
//! max-product message `max_{a₁,b₁} h(a₁,b₁) − λ(a₁−a₂)² − λ(b₁−b₂)²` is a 2-D distance
//! transform computed in O(N²) by two 1-D lower-envelope passes (Felzenszwalb &
//! Huttenlocher, "Distance transforms of sampled functions", Theory of Computing 8 (2012),
//! doi:10.4086/toc.2012.v008a019) instead of O(N⁴). Two segments meeting head to head or
//! tail to tail see each other mirrored (left ↔ right): `(a, b) ↦ (N−1−b, N−1−a)`.

use crate::potentials::SegmentPotential;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::Serialize;

/// A coupled pair of segments.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Edge {
    /// First segment (index into the network's potentials).
    pub s1: usize,
    /// Second segment.
    pub s2: usize,
    /// The two segments run in opposite directions (left of one is right of the other).
    pub flipped: bool,
}

/// The graphical model of eq. 4.1: one potential per segment, Gaussian couplings on edges.
#[derive(Debug, Clone)]
pub struct Network {
    /// Segment potentials (all with the same number of columns).
    pub potentials: Vec<SegmentPotential>,
    /// Coupled pairs N.
    pub edges: Vec<Edge>,
    /// λ = bin² / (2σ²): the coupling per squared column difference.
    pub lambda: f64,
    /// Largest penalty of one coupling, nats (∞: the thesis' Gaussian; finite: a truncated
    /// quadratic, so a segment whose street really changes width can break away).
    pub truncation: f64,
}

/// A labelling: one `(a, b)` per segment.
pub type Labelling = Vec<(usize, usize)>;

/// An inference result.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Solution {
    /// θ per segment.
    pub states: Labelling,
    /// log P(Θ | Z) up to a constant.
    pub log_probability: f64,
    /// Whether the result is the exact optimum (tree-shaped network).
    pub exact: bool,
}

fn mirror(cols: usize, (a, b): (usize, usize)) -> (usize, usize) {
    (cols - 1 - b, cols - 1 - a)
}

impl Network {
    /// Columns per segment.
    fn cols(&self) -> usize {
        self.potentials.first().map_or(0, |p| p.cols)
    }

    /// Pairwise log potential of `x1` (segment s1) and `x2` (segment s2) on `edge`.
    pub fn pairwise(&self, edge: &Edge, x1: (usize, usize), x2: (usize, usize)) -> f64 {
        let x2 = if edge.flipped {
            mirror(self.cols(), x2)
        } else {
            x2
        };
        let da = x1.0 as f64 - x2.0 as f64;
        let db = x1.1 as f64 - x2.1 as f64;
        (-self.lambda * (da * da + db * db)).max(-self.truncation)
    }

    /// log P(Θ | Z) of a labelling up to a constant (eq. 4.1).
    pub fn log_probability(&self, states: &[(usize, usize)]) -> f64 {
        let unary: f64 = self
            .potentials
            .iter()
            .zip(states)
            .map(|(p, &(a, b))| p.at(a, b))
            .sum();
        let pair: f64 = self
            .edges
            .iter()
            .map(|e| self.pairwise(e, states[e.s1], states[e.s2]))
            .sum();
        unary + pair
    }

    /// Each segment on its own: the argmax of its potential (the thesis' "single segment").
    pub fn single_segment(&self) -> Solution {
        let states: Labelling = self.potentials.iter().map(|p| p.argmax()).collect();
        Solution {
            log_probability: self.log_probability(&states),
            states,
            exact: self.edges.is_empty(),
        }
    }

    fn adjacency(&self) -> Vec<Vec<(usize, usize)>> {
        let mut adj = vec![Vec::new(); self.potentials.len()];
        for (k, e) in self.edges.iter().enumerate() {
            adj[e.s1].push((e.s2, k));
            adj[e.s2].push((e.s1, k));
        }
        adj
    }

    /// Whether the network has no cycle (then [`Network::max_product`] is exact).
    pub fn is_forest(&self) -> bool {
        let n = self.potentials.len();
        let mut parent: Vec<usize> = (0..n).collect();
        fn find(p: &mut [usize], mut x: usize) -> usize {
            while p[x] != x {
                p[x] = p[p[x]];
                x = p[x];
            }
            x
        }
        for e in &self.edges {
            let (r1, r2) = (find(&mut parent, e.s1), find(&mut parent, e.s2));
            if r1 == r2 {
                return false;
            }
            parent[r1] = r2;
        }
        true
    }

    /// The message from a table `h` (in the sender's frame) to the receiver across `edge`.
    fn message(&self, h: &[f64], flipped: bool) -> Vec<f64> {
        let n = self.cols();
        let src: Vec<f64> = if flipped {
            let mut m = vec![f64::NEG_INFINITY; n * n];
            for a in 0..n {
                for b in a..n {
                    let (ma, mb) = mirror(n, (a, b));
                    m[ma * n + mb] = h[a * n + b];
                }
            }
            m
        } else {
            h.to_vec()
        };
        let mut msg = distance_transform_2d(&src, n, self.lambda);
        if self.truncation.is_finite() {
            // max(DT, max h − K): the truncated quadratic's message, still exact.
            let floor = src.iter().copied().fold(f64::NEG_INFINITY, f64::max) - self.truncation;
            msg.iter_mut().for_each(|v| *v = v.max(floor));
        }
        msg
    }

    /// Connected components of the coupling graph: segments ascending within each, components
    /// ordered by their first segment. O(S + E).
    pub fn components(&self) -> Vec<Vec<usize>> {
        let adj = self.adjacency();
        let mut component = vec![usize::MAX; self.potentials.len()];
        let mut out: Vec<Vec<usize>> = Vec::new();
        for root in 0..self.potentials.len() {
            if component[root] != usize::MAX {
                continue;
            }
            let id = out.len();
            component[root] = id;
            let mut members = vec![root];
            let mut k = 0;
            while k < members.len() {
                for &(t, _) in &adj[members[k]] {
                    if component[t] == usize::MAX {
                        component[t] = id;
                        members.push(t);
                    }
                }
                k += 1;
            }
            members.sort_unstable();
            out.push(members);
        }
        out
    }

    /// The network induced on `nodes` (ascending): their potentials in that order and the
    /// edges among them in this network's order, renumbered.
    pub fn subnetwork(&self, nodes: &[usize]) -> Network {
        let mut local = vec![usize::MAX; self.potentials.len()];
        for (k, &s) in nodes.iter().enumerate() {
            local[s] = k;
        }
        let edges = self
            .edges
            .iter()
            .filter(|e| local[e.s1] != usize::MAX && local[e.s2] != usize::MAX)
            .map(|e| Edge {
                s1: local[e.s1],
                s2: local[e.s2],
                flipped: e.flipped,
            })
            .collect();
        Network {
            potentials: nodes.iter().map(|&s| self.potentials[s].clone()).collect(),
            edges,
            lambda: self.lambda,
            truncation: self.truncation,
        }
    }

    /// Max-product, each connected component of the coupling graph on its own: exact
    /// two-pass on a tree component; on a component with loops `rounds` of damped loopy
    /// max-product (stopped by that component's own largest message change) followed by
    /// ICM. `exact` says whether every component was a tree.
    ///
    /// A segment's state is a function of its component alone (the component's
    /// [`Network::subnetwork`], segments and edges in this network's order): running the
    /// components separately, or in any larger network holding them whole, gives
    /// bit-identical states. [`crate::tiles`] relies on this.
    pub fn max_product(&self, rounds: usize) -> Solution {
        let components = self.components();
        if components.len() <= 1 {
            // The one component is this network itself (its own subnetwork).
            return self.connected_max_product(rounds);
        }
        let parts: Vec<Solution> = components
            .par_iter()
            .map(|nodes| self.subnetwork(nodes).connected_max_product(rounds))
            .collect();
        let mut states = vec![(0usize, 0usize); self.potentials.len()];
        for (nodes, part) in components.iter().zip(&parts) {
            for (&s, &x) in nodes.iter().zip(&part.states) {
                states[s] = x;
            }
        }
        Solution {
            log_probability: self.log_probability(&states),
            states,
            exact: parts.iter().all(|p| p.exact),
        }
    }

    /// Max-product on a network taken as one unit (one stopping rule for all its messages).
    fn connected_max_product(&self, rounds: usize) -> Solution {
        if self.is_forest() {
            self.tree_max_product()
        } else {
            self.loopy_max_product(rounds)
        }
    }

    fn tree_max_product(&self) -> Solution {
        let n_seg = self.potentials.len();
        let adj = self.adjacency();
        let n = self.cols();
        let mut order = Vec::with_capacity(n_seg);
        let mut parent: Vec<Option<(usize, usize)>> = vec![None; n_seg];
        let mut seen = vec![false; n_seg];
        for root in 0..n_seg {
            if seen[root] {
                continue;
            }
            seen[root] = true;
            let start = order.len();
            order.push(root);
            let mut k = start;
            while k < order.len() {
                let s = order[k];
                for &(t, e) in &adj[s] {
                    if !seen[t] {
                        seen[t] = true;
                        parent[t] = Some((s, e));
                        order.push(t);
                    }
                }
                k += 1;
            }
        }
        // Upward pass: h[s] = φ_s + Σ messages from children.
        let mut h: Vec<Vec<f64>> = self.potentials.iter().map(|p| p.log.clone()).collect();
        for &s in order.iter().rev() {
            if let Some((p, e)) = parent[s] {
                let m = self.message(&h[s], self.edges[e].flipped);
                for (x, v) in h[p].iter_mut().zip(&m) {
                    *x += v;
                }
            }
        }
        // Downward decoding: roots take their argmax, children the best given the parent.
        let mut states = vec![(0usize, 0usize); n_seg];
        for &s in &order {
            let mut best = (f64::NEG_INFINITY, (0, 0));
            for a in 0..n {
                for b in a..n {
                    let v = h[s][a * n + b];
                    if v == f64::NEG_INFINITY {
                        continue;
                    }
                    let v = match parent[s] {
                        Some((p, e)) => {
                            let edge = &self.edges[e];
                            if edge.s1 == s {
                                v + self.pairwise(edge, (a, b), states[p])
                            } else {
                                v + self.pairwise(edge, states[p], (a, b))
                            }
                        }
                        None => v,
                    };
                    if v > best.0 {
                        best = (v, (a, b));
                    }
                }
            }
            states[s] = best.1;
        }
        Solution {
            log_probability: self.log_probability(&states),
            states,
            exact: true,
        }
    }

    fn loopy_max_product(&self, rounds: usize) -> Solution {
        let n = self.cols();
        let n_seg = self.potentials.len();
        // messages[2k]: s1 → s2 of edge k; messages[2k+1]: s2 → s1.
        let zero = vec![0.0; n * n];
        let mut messages = vec![zero; 2 * self.edges.len()];
        let adj = self.adjacency();
        let belief = |s: usize, msgs: &[Vec<f64>], skip: Option<usize>| {
            let mut h = self.potentials[s].log.clone();
            for &(_, e) in &adj[s] {
                let incoming = if self.edges[e].s2 == s {
                    2 * e
                } else {
                    2 * e + 1
                };
                if Some(incoming) == skip {
                    continue;
                }
                for (x, v) in h.iter_mut().zip(&msgs[incoming]) {
                    *x += v;
                }
            }
            h
        };
        for _ in 0..rounds {
            let new: Vec<Vec<f64>> = (0..2 * self.edges.len())
                .into_par_iter()
                .map(|m| {
                    let e = &self.edges[m / 2];
                    let (from, back) = if m % 2 == 0 {
                        (e.s1, m + 1)
                    } else {
                        (e.s2, m - 1)
                    };
                    let h = belief(from, &messages, Some(back));
                    let mut msg = self.message(&h, e.flipped);
                    let top = msg.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                    if top.is_finite() {
                        msg.iter_mut().for_each(|v| *v -= top);
                    }
                    // Damping against oscillation.
                    for (v, old) in msg.iter_mut().zip(&messages[m]) {
                        if v.is_finite() && old.is_finite() {
                            *v = 0.5 * *v + 0.5 * old;
                        }
                    }
                    msg
                })
                .collect();
            // Stop once no message moves (a fixed point of the damped updates).
            let change = new
                .iter()
                .zip(&messages)
                .flat_map(|(a, b)| a.iter().zip(b))
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f64::max);
            messages = new;
            if change < 1e-6 {
                break;
            }
        }
        let mut states: Labelling = (0..n_seg)
            .map(|s| {
                let h = belief(s, &messages, None);
                SegmentPotential { cols: n, log: h }.argmax()
            })
            .collect();
        self.icm(&mut states, &adj);
        Solution {
            log_probability: self.log_probability(&states),
            states,
            exact: false,
        }
    }

    /// Iterated conditional modes: each segment to its best state given its neighbours.
    fn icm(&self, states: &mut Labelling, adj: &[Vec<(usize, usize)>]) {
        let n = self.cols();
        for _ in 0..20 {
            let mut changed = false;
            for s in 0..states.len() {
                let mut best = (f64::NEG_INFINITY, states[s]);
                for a in 0..n {
                    for b in a..n {
                        let v = self.potentials[s].at(a, b);
                        if v == f64::NEG_INFINITY {
                            continue;
                        }
                        let v = v + self.local_pairwise(s, (a, b), states, adj);
                        if v > best.0 {
                            best = (v, (a, b));
                        }
                    }
                }
                if best.1 != states[s] {
                    states[s] = best.1;
                    changed = true;
                }
            }
            if !changed {
                break;
            }
        }
    }

    fn local_pairwise(
        &self,
        s: usize,
        x: (usize, usize),
        states: &[(usize, usize)],
        adj: &[Vec<(usize, usize)>],
    ) -> f64 {
        adj[s]
            .iter()
            .map(|&(t, e)| {
                let edge = &self.edges[e];
                if edge.s1 == s {
                    self.pairwise(edge, x, states[t])
                } else {
                    self.pairwise(edge, states[t], x)
                }
            })
            .sum()
    }

    /// Metropolis MCMC with annealing, `chains` independent seeded chains in parallel; the
    /// best labelling any chain visits. Chains start from the single-segment optimum.
    pub fn mcmc(&self, options: &McmcOptions) -> Solution {
        let adj = self.adjacency();
        let n = self.cols();
        let start = self.single_segment().states;
        let n_seg = self.potentials.len();
        if n_seg == 0 || n == 0 {
            return Solution {
                states: Vec::new(),
                log_probability: 0.0,
                exact: true,
            };
        }
        let results: Vec<(f64, Labelling)> = (0..options.chains)
            .into_par_iter()
            .map(|chain| {
                let mut rng = ChaCha8Rng::seed_from_u64(
                    options.seed ^ (chain as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
                );
                let mut states = start.clone();
                let mut current = self.log_probability(&states);
                let mut best = (current, states.clone());
                let iters = options.iterations.max(1);
                let ratio = (options.t_end / options.t_start).ln();
                for it in 0..iters {
                    let temp = options.t_start * (ratio * it as f64 / iters as f64).exp();
                    let s = rng.gen_range(0..n_seg);
                    let (a, b) = states[s];
                    // Mostly small steps; one in ten a long jump (up to a quarter of the corridor).
                    let step = if rng.gen_range(0..10) == 0 {
                        rng.gen_range(1..=(n as i64 / 4).max(1))
                    } else {
                        rng.gen_range(1..=options.max_step.max(1) as i64)
                    };
                    let sign = if rng.gen::<bool>() { 1 } else { -1 };
                    let delta = sign * step;
                    let (na, nb) = match rng.gen_range(0..3) {
                        0 => (a as i64 + delta, b as i64 + delta),
                        1 => (a as i64 + delta, b as i64),
                        _ => (a as i64, b as i64 + delta),
                    };
                    if na < 0 || nb < 0 || na as usize >= n || nb as usize >= n {
                        continue;
                    }
                    let x = (na as usize, nb as usize);
                    let new_unary = if x.0 <= x.1 {
                        self.potentials[s].at(x.0, x.1)
                    } else {
                        f64::NEG_INFINITY
                    };
                    if new_unary == f64::NEG_INFINITY {
                        continue;
                    }
                    let gain = new_unary - self.potentials[s].at(a, b)
                        + self.local_pairwise(s, x, &states, &adj)
                        - self.local_pairwise(s, (a, b), &states, &adj);
                    if gain >= 0.0 || rng.gen::<f64>() < (gain / temp).exp() {
                        states[s] = x;
                        current += gain;
                        if current > best.0 {
                            best = (current, states.clone());
                        }
                    }
                }
                best
            })
            .collect();
        let mut best = (f64::NEG_INFINITY, start);
        for (v, s) in results {
            if v > best.0 {
                best = (v, s);
            }
        }
        Solution {
            log_probability: self.log_probability(&best.1),
            states: best.1,
            exact: false,
        }
    }
}

/// Options of [`Network::mcmc`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct McmcOptions {
    /// Independent chains (thesis: 50).
    pub chains: usize,
    /// Iterations per chain (thesis: 10⁶).
    pub iterations: usize,
    /// Initial temperature.
    pub t_start: f64,
    /// Final temperature (geometric schedule).
    pub t_end: f64,
    /// Largest boundary move of the frequent small steps, columns.
    pub max_step: usize,
    /// Seed.
    pub seed: u64,
}

impl Default for McmcOptions {
    fn default() -> Self {
        McmcOptions {
            chains: 50,
            iterations: 1_000_000,
            t_start: 5.0,
            t_end: 0.05,
            max_step: 3,
            seed: 1,
        }
    }
}

/// 1-D max-convolution `out[q] = max_p f[p] − λ(p − q)²` by the lower envelope of parabolas
/// (−∞ entries are skipped; λ > 0).
fn distance_transform_1d(f: &[f64], lambda: f64, out: &mut [f64]) {
    // Minimise g = −f plus λ(p − q)²: parabola roots v, left envelope breaks z.
    let mut v: Vec<usize> = Vec::with_capacity(f.len());
    let mut z: Vec<f64> = Vec::with_capacity(f.len() + 1);
    for (q, &fq) in f.iter().enumerate() {
        if fq == f64::NEG_INFINITY {
            continue;
        }
        if v.is_empty() {
            v.push(q);
            z.push(f64::NEG_INFINITY);
            continue;
        }
        let qf = q as f64;
        loop {
            let p = v[v.len() - 1];
            let pf = p as f64;
            let s = ((-fq + lambda * qf * qf) - (-f[p] + lambda * pf * pf))
                / (2.0 * lambda * (qf - pf));
            // z[0] = −∞, so the first parabola is never popped.
            if s <= z[v.len() - 1] {
                v.pop();
                z.pop();
                continue;
            }
            z.push(s);
            v.push(q);
            break;
        }
    }
    if v.is_empty() {
        out.iter_mut().for_each(|o| *o = f64::NEG_INFINITY);
        return;
    }
    let mut k = 0;
    for (q, o) in out.iter_mut().enumerate() {
        let qf = q as f64;
        while k + 1 < v.len() && z[k + 1] < qf {
            k += 1;
        }
        let p = v[k] as f64;
        *o = f[v[k]] - lambda * (qf - p) * (qf - p);
    }
}

/// 2-D separable max-convolution of an `n × n` table (indexed `a·n + b`).
fn distance_transform_2d(h: &[f64], n: usize, lambda: f64) -> Vec<f64> {
    if lambda <= 0.0 {
        // No coupling: the message is the constant max.
        let top = h.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        return vec![top; n * n];
    }
    let mut tmp = vec![0.0; n * n];
    let mut col = vec![0.0; n];
    let mut out_col = vec![0.0; n];
    // Over a for each b.
    for b in 0..n {
        for a in 0..n {
            col[a] = h[a * n + b];
        }
        distance_transform_1d(&col, lambda, &mut out_col);
        for a in 0..n {
            tmp[a * n + b] = out_col[a];
        }
    }
    let mut out = vec![0.0; n * n];
    for a in 0..n {
        distance_transform_1d(
            &tmp[a * n..(a + 1) * n],
            lambda,
            &mut out[a * n..(a + 1) * n],
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::{any, prop_assert, proptest, ProptestConfig};

    fn random_potential(n: usize, rng: &mut ChaCha8Rng, max_width: usize) -> SegmentPotential {
        let mut log = vec![f64::NEG_INFINITY; n * n];
        for a in 0..n {
            for b in a..n.min(a + max_width) {
                log[a * n + b] = rng.gen_range(-4.0..0.0);
            }
        }
        SegmentPotential { cols: n, log }
    }

    /// A random tree on `k` nodes (node i > 0 attached to a random earlier node).
    fn random_tree(k: usize, n: usize, seed: u64, lambda: f64, truncation: f64) -> Network {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let potentials = (0..k)
            .map(|_| random_potential(n, &mut rng, n - 1))
            .collect();
        let edges = (1..k)
            .map(|i| Edge {
                s1: rng.gen_range(0..i),
                s2: i,
                flipped: rng.gen::<bool>(),
            })
            .collect();
        Network {
            potentials,
            edges,
            lambda,
            truncation,
        }
    }

    fn brute_force(net: &Network) -> f64 {
        let n = net.cols();
        let states: Vec<(usize, usize)> =
            (0..n).flat_map(|a| (a..n).map(move |b| (a, b))).collect();
        let k = net.potentials.len();
        let mut idx = vec![0usize; k];
        let mut best = f64::NEG_INFINITY;
        loop {
            let lab: Labelling = idx.iter().map(|&i| states[i]).collect();
            best = best.max(net.log_probability(&lab));
            let mut p = 0;
            loop {
                if p == k {
                    return best;
                }
                idx[p] += 1;
                if idx[p] < states.len() {
                    break;
                }
                idx[p] = 0;
                p += 1;
            }
        }
    }

    #[test]
    #[allow(clippy::needless_range_loop)]
    fn distance_transform_matches_brute_force() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        for _ in 0..50 {
            let n = rng.gen_range(1..15);
            let f: Vec<f64> = (0..n)
                .map(|_| {
                    if rng.gen_range(0..4) == 0 {
                        f64::NEG_INFINITY
                    } else {
                        rng.gen_range(-5.0..5.0)
                    }
                })
                .collect();
            let lambda = rng.gen_range(0.01..3.0);
            let mut out = vec![0.0; n];
            distance_transform_1d(&f, lambda, &mut out);
            for q in 0..n {
                let want = (0..n)
                    .map(|p| f[p] - lambda * (p as f64 - q as f64).powi(2))
                    .fold(f64::NEG_INFINITY, f64::max);
                assert!(
                    (out[q] == want) || (out[q] - want).abs() < 1e-9,
                    "{f:?} λ={lambda} q={q}: {} vs {want}",
                    out[q]
                );
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 40, ..ProptestConfig::default() })]
        #[test]
        fn exact_tree_inference_equals_brute_force(k in 1usize..5, n in 2usize..6, seed in 0u64..1000, lambda in 0.0f64..2.0, truncated in any::<bool>(), cap in 0.1f64..4.0) {
            let net = random_tree(k, n, seed, lambda, if truncated { cap } else { f64::INFINITY });
            let sol = net.max_product(10);
            prop_assert!(sol.exact);
            let bf = brute_force(&net);
            prop_assert!((sol.log_probability - bf).abs() < 1e-9, "max-product {} vs brute force {}", sol.log_probability, bf);
        }
    }

    #[test]
    fn mcmc_reaches_the_exact_optimum_on_small_trees() {
        for seed in 0..8 {
            let net = random_tree(4, 5, seed, 0.5, f64::INFINITY);
            let exact = net.max_product(0).log_probability;
            let mc = net.mcmc(&McmcOptions {
                chains: 8,
                iterations: 20_000,
                seed,
                ..McmcOptions::default()
            });
            assert!(
                (mc.log_probability - exact).abs() < 1e-9,
                "seed {seed}: MCMC {} vs exact {exact}",
                mc.log_probability
            );
        }
    }

    #[test]
    fn mcmc_is_deterministic_for_a_seed() {
        let net = random_tree(5, 6, 3, 0.3, f64::INFINITY);
        let o = McmcOptions {
            chains: 4,
            iterations: 5_000,
            ..McmcOptions::default()
        };
        assert_eq!(net.mcmc(&o), net.mcmc(&o));
    }

    #[test]
    fn loopy_max_product_is_near_brute_force_on_a_cycle() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let n = 5;
        let potentials = (0..4).map(|_| random_potential(n, &mut rng, n)).collect();
        let edges = vec![
            Edge {
                s1: 0,
                s2: 1,
                flipped: false,
            },
            Edge {
                s1: 1,
                s2: 2,
                flipped: true,
            },
            Edge {
                s1: 2,
                s2: 3,
                flipped: false,
            },
            Edge {
                s1: 0,
                s2: 3,
                flipped: false,
            },
        ];
        let net = Network {
            potentials,
            edges,
            lambda: 0.4,
            truncation: f64::INFINITY,
        };
        assert!(!net.is_forest());
        let sol = net.max_product(30);
        assert!(!sol.exact);
        let bf = brute_force(&net);
        // ICM after loopy BP: a local optimum; on this instance it is the global one.
        assert!(sol.log_probability <= bf + 1e-9);
        assert!(
            sol.log_probability >= bf - 1.0,
            "loopy {} vs exact {bf}",
            sol.log_probability
        );
    }
}
