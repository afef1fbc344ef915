//! A binary RBF-kernel support vector machine trained by SMO, as libsvm's C-SVC.
//!
//! Training solves the dual `min ½ αᵀQα − eᵀα, 0 ≤ α ≤ C, yᵀα = 0` with
//! `Q_ij = y_i y_j exp(−γ‖x_i − x_j‖²)` by sequential minimal optimisation with the
//! second-order working-set selection of Fan, Chen & Lin, "Working set selection using second
//! order information for training SVM", JMLR 6 (2005) (WSS 3, libsvm ≥ 2.8), and stops when
//! the maximal violating pair violates by less than `eps`. Kernel rows come from an LRU cache
//! bounded in bytes (libsvm's `-m`); a missing row is computed in parallel with rayon. The
//! Q matrix is never stored, so memory is O(n·d + cache).
//!
//! Each iteration costs O(n) plus at most two kernel rows (O(n·d) each on a cache miss).
//!
//! ```
//! use streets::svm::{Svm, SvmOptions};
//! let x: Vec<Vec<f32>> = (0..40).map(|i| vec![i as f32 / 40.0]).collect();
//! let y: Vec<bool> = (0..40).map(|i| i >= 20).collect();
//! let svm = Svm::train(&x, &y, &SvmOptions { c: 10.0, gamma: Some(10.0), ..SvmOptions::default() }).unwrap();
//! assert!(svm.predict(&[0.9]).unwrap());
//! assert!(!svm.predict(&[0.1]).unwrap());
//! ```

use crate::{Result, StreetsError};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Options of SVM training.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SvmOptions {
    /// Box constraint C.
    pub c: f64,
    /// RBF γ; `None`: 1 / number of features (libsvm's default).
    pub gamma: Option<f64>,
    /// Stopping tolerance on the maximal violating pair (libsvm's `-e`, 0.001).
    pub eps: f64,
    /// Kernel cache size in MiB (libsvm's `-m`, 100).
    pub cache_mb: usize,
    /// Iteration cap (0: 10⁷ or 100·n, whichever is larger).
    pub max_iterations: usize,
}

impl Default for SvmOptions {
    fn default() -> Self {
        SvmOptions {
            c: 1.0,
            gamma: None,
            eps: 1e-3,
            cache_mb: 100,
            max_iterations: 0,
        }
    }
}

/// Counters of one training run.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TrainStats {
    /// SMO iterations.
    pub iterations: usize,
    /// Kernel rows computed (cache misses).
    pub kernel_rows: usize,
    /// Final dual objective ½αᵀQα − eᵀα.
    pub objective: f64,
    /// Whether the stopping criterion was met (else the iteration cap hit).
    pub converged: bool,
}

/// A trained RBF SVM: support vectors, their coefficients yᵢαᵢ and the bias ρ.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Svm {
    /// RBF γ.
    pub gamma: f64,
    /// Number of features.
    pub dims: usize,
    /// Support vectors, row-major (`sv_count × dims`).
    pub support: Vec<f32>,
    /// yᵢαᵢ per support vector.
    pub coef: Vec<f64>,
    /// Bias: f(x) = Σ coefᵢ K(svᵢ, x) − ρ.
    pub rho: f64,
    /// Training counters.
    pub stats: TrainStats,
}

/// An LRU cache of Q rows bounded in bytes.
struct RowCache {
    rows: Vec<Option<Vec<f32>>>,
    last_used: Vec<u64>,
    cached: Vec<usize>,
    capacity_rows: usize,
    clock: u64,
    misses: usize,
}

impl RowCache {
    fn new(n: usize, cache_mb: usize) -> Self {
        let row_bytes = (n * 4).max(1);
        let capacity_rows = ((cache_mb << 20) / row_bytes).max(2);
        RowCache {
            rows: vec![None; n],
            last_used: vec![0; n],
            cached: Vec::new(),
            capacity_rows,
            clock: 0,
            misses: 0,
        }
    }
}

/// The training problem: points with squared norms, labels ±1.
struct Problem<'a> {
    x: &'a [f32],
    dims: usize,
    norms: Vec<f32>,
    y: Vec<i8>,
    gamma: f32,
}

impl Problem<'_> {
    fn len(&self) -> usize {
        self.y.len()
    }

    fn row(&self, i: usize) -> &[f32] {
        &self.x[i * self.dims..(i + 1) * self.dims]
    }

    /// Q row i: y_i y_j K(x_i, x_j) for all j.
    fn q_row(&self, i: usize) -> Vec<f32> {
        let xi = self.row(i);
        let ni = self.norms[i];
        let yi = self.y[i];
        let mut out = vec![0f32; self.len()];
        out.par_chunks_mut(1024)
            .enumerate()
            .for_each(|(chunk, slot)| {
                let start = chunk * 1024;
                for (k, v) in slot.iter_mut().enumerate() {
                    let j = start + k;
                    let d2 = (ni + self.norms[j] - 2.0 * dot(xi, self.row(j))).max(0.0);
                    let kij = (-self.gamma * d2).exp();
                    *v = if yi == self.y[j] { kij } else { -kij };
                }
            });
        out
    }
}

/// Dot product written for auto-vectorisation (8 independent lanes).
#[inline]
fn dot(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = [0f32; 8];
    let chunks = a.len() / 8;
    for c in 0..chunks {
        for l in 0..8 {
            acc[l] += a[c * 8 + l] * b[c * 8 + l];
        }
    }
    let mut s: f32 = acc.iter().sum();
    for k in chunks * 8..a.len() {
        s += a[k] * b[k];
    }
    s
}

fn get_row<'c>(cache: &'c mut RowCache, problem: &Problem, i: usize) -> &'c [f32] {
    cache.clock += 1;
    cache.last_used[i] = cache.clock;
    if cache.rows[i].is_none() {
        if cache.cached.len() >= cache.capacity_rows {
            // Evict the least recently used row.
            let (pos, _) = cache
                .cached
                .iter()
                .enumerate()
                .min_by_key(|(_, &r)| cache.last_used[r])
                .unwrap_or((0, &0));
            let victim = cache.cached.swap_remove(pos);
            cache.rows[victim] = None;
        }
        cache.rows[i] = Some(problem.q_row(i));
        cache.cached.push(i);
        cache.misses += 1;
    }
    cache.rows[i].as_deref().unwrap_or(&[])
}

const TAU: f64 = 1e-12;

impl Svm {
    /// Trains on rows `x` (all of one length) with labels `y` (`true` = street).
    pub fn train(x: &[Vec<f32>], y: &[bool], options: &SvmOptions) -> Result<Svm> {
        let dims = x.first().map_or(0, Vec::len);
        let mut flat = Vec::with_capacity(x.len() * dims);
        for row in x {
            if row.len() != dims {
                return Err(StreetsError::FeatureLength {
                    got: row.len(),
                    expected: dims,
                });
            }
            flat.extend_from_slice(row);
        }
        Svm::train_flat(&flat, dims, y, options)
    }

    /// Trains on a row-major matrix `x` (`y.len() × dims`).
    pub fn train_flat(x: &[f32], dims: usize, y: &[bool], options: &SvmOptions) -> Result<Svm> {
        let n = y.len();
        if x.len() != n * dims || dims == 0 {
            return Err(StreetsError::FeatureLength {
                got: x.len(),
                expected: n * dims,
            });
        }
        let positives = y.iter().filter(|&&v| v).count();
        if positives == 0 || positives == n {
            return Err(StreetsError::OneClass {
                positives,
                negatives: n - positives,
            });
        }
        if !(options.c.is_finite() && options.c > 0.0) {
            return Err(StreetsError::InvalidOption {
                name: "c",
                value: options.c,
                expected: "a positive box constraint",
            });
        }
        let gamma = options.gamma.unwrap_or(1.0 / dims as f64);
        if !(gamma.is_finite() && gamma > 0.0) {
            return Err(StreetsError::InvalidOption {
                name: "gamma",
                value: gamma,
                expected: "a positive RBF gamma",
            });
        }
        let problem = Problem {
            x,
            dims,
            norms: (0..n)
                .map(|i| {
                    let r = &x[i * dims..(i + 1) * dims];
                    dot(r, r)
                })
                .collect(),
            y: y.iter().map(|&v| if v { 1 } else { -1 }).collect(),
            gamma: gamma as f32,
        };
        let c = options.c;
        let max_iterations = if options.max_iterations == 0 {
            (100 * n).max(10_000_000)
        } else {
            options.max_iterations
        };
        let mut cache = RowCache::new(n, options.cache_mb);
        let mut alpha = vec![0f64; n];
        let mut grad = vec![-1f64; n];
        let qd = vec![1f64; n]; // K(x, x) = 1 for the RBF kernel.
        let yf: Vec<f64> = problem.y.iter().map(|&v| f64::from(v)).collect();
        let is_up = |a: f64, yv: f64| (yv > 0.0 && a < c) || (yv < 0.0 && a > 0.0);
        let is_low = |a: f64, yv: f64| (yv > 0.0 && a > 0.0) || (yv < 0.0 && a < c);
        let mut iterations = 0;
        let mut converged = false;
        while iterations < max_iterations {
            // WSS 3: i maximises −y G over I_up.
            let mut gmax = f64::NEG_INFINITY;
            let mut i_sel = usize::MAX;
            for t in 0..n {
                if is_up(alpha[t], yf[t]) {
                    let v = -yf[t] * grad[t];
                    if v >= gmax {
                        gmax = v;
                        i_sel = t;
                    }
                }
            }
            if i_sel == usize::MAX {
                converged = true;
                break;
            }
            let qi = get_row(&mut cache, &problem, i_sel).to_vec();
            // j minimises −b²/a over I_low with −y G < gmax.
            let mut gmax2 = f64::NEG_INFINITY;
            let mut obj_min = f64::INFINITY;
            let mut j_sel = usize::MAX;
            for t in 0..n {
                if !is_low(alpha[t], yf[t]) {
                    continue;
                }
                let ygt = yf[t] * grad[t];
                if ygt >= gmax2 {
                    gmax2 = ygt;
                }
                let b = gmax + ygt;
                if b > 0.0 {
                    // a = K_ii + K_tt − 2 K_it = Q_ii + Q_tt − 2 y_i y_t Q_it.
                    let a = qd[i_sel] + qd[t] - 2.0 * yf[i_sel] * yf[t] * f64::from(qi[t]);
                    let a = if a > 0.0 { a } else { TAU };
                    let v = -(b * b) / a;
                    if v <= obj_min {
                        obj_min = v;
                        j_sel = t;
                    }
                }
            }
            if gmax + gmax2 < options.eps || j_sel == usize::MAX {
                converged = true;
                break;
            }
            iterations += 1;
            let (i, j) = (i_sel, j_sel);
            let qj = get_row(&mut cache, &problem, j).to_vec();
            let (old_ai, old_aj) = (alpha[i], alpha[j]);
            // The two-variable update of libsvm's Solver::Solve.
            if yf[i] != yf[j] {
                let mut quad = qd[i] + qd[j] + 2.0 * f64::from(qi[j]);
                if quad <= 0.0 {
                    quad = TAU;
                }
                let delta = (-grad[i] - grad[j]) / quad;
                let diff = alpha[i] - alpha[j];
                alpha[i] += delta;
                alpha[j] += delta;
                if diff > 0.0 {
                    if alpha[j] < 0.0 {
                        alpha[j] = 0.0;
                        alpha[i] = diff;
                    }
                } else if alpha[i] < 0.0 {
                    alpha[i] = 0.0;
                    alpha[j] = -diff;
                }
                if diff > 0.0 {
                    if alpha[i] > c {
                        alpha[i] = c;
                        alpha[j] = c - diff;
                    }
                } else if alpha[j] > c {
                    alpha[j] = c;
                    alpha[i] = c + diff;
                }
            } else {
                let mut quad = qd[i] + qd[j] - 2.0 * f64::from(qi[j]);
                if quad <= 0.0 {
                    quad = TAU;
                }
                let delta = (grad[i] - grad[j]) / quad;
                let sum = alpha[i] + alpha[j];
                alpha[i] -= delta;
                alpha[j] += delta;
                if sum > c {
                    if alpha[i] > c {
                        alpha[i] = c;
                        alpha[j] = sum - c;
                    }
                } else if alpha[j] < 0.0 {
                    alpha[j] = 0.0;
                    alpha[i] = sum;
                }
                if sum > c {
                    if alpha[j] > c {
                        alpha[j] = c;
                        alpha[i] = sum - c;
                    }
                } else if alpha[i] < 0.0 {
                    alpha[i] = 0.0;
                    alpha[j] = sum;
                }
            }
            let (dai, daj) = (alpha[i] - old_ai, alpha[j] - old_aj);
            grad.par_iter_mut()
                .zip(qi.par_iter().zip(qj.par_iter()))
                .with_min_len(4096)
                .for_each(|(g, (&a, &b))| *g += f64::from(a) * dai + f64::from(b) * daj);
        }
        // ρ: mean of y G over free vectors, else the middle of the feasible interval.
        let (mut ub, mut lb, mut sum_free, mut n_free) =
            (f64::INFINITY, f64::NEG_INFINITY, 0.0, 0usize);
        for t in 0..n {
            let yg = yf[t] * grad[t];
            if alpha[t] >= c {
                if yf[t] < 0.0 {
                    ub = ub.min(yg);
                } else {
                    lb = lb.max(yg);
                }
            } else if alpha[t] <= 0.0 {
                if yf[t] > 0.0 {
                    ub = ub.min(yg);
                } else {
                    lb = lb.max(yg);
                }
            } else {
                n_free += 1;
                sum_free += yg;
            }
        }
        let rho = if n_free > 0 {
            sum_free / n_free as f64
        } else {
            (ub + lb) / 2.0
        };
        let objective = (0..n).map(|t| alpha[t] * (grad[t] - 1.0)).sum::<f64>() / 2.0;
        let mut support = Vec::new();
        let mut coef = Vec::new();
        for t in 0..n {
            if alpha[t] > 0.0 {
                support.extend_from_slice(problem.row(t));
                coef.push(yf[t] * alpha[t]);
            }
        }
        Ok(Svm {
            gamma,
            dims,
            support,
            coef,
            rho,
            stats: TrainStats {
                iterations,
                kernel_rows: cache.misses,
                objective,
                converged,
            },
        })
    }

    /// Number of support vectors.
    pub fn support_count(&self) -> usize {
        self.coef.len()
    }

    /// The decision value f(x) = Σ coefᵢ K(svᵢ, x) − ρ (positive: street).
    pub fn decision(&self, x: &[f32]) -> Result<f64> {
        if x.len() != self.dims {
            return Err(StreetsError::FeatureLength {
                got: x.len(),
                expected: self.dims,
            });
        }
        let nx = dot(x, x);
        let g = self.gamma as f32;
        let mut s = 0f64;
        for (k, &cf) in self.coef.iter().enumerate() {
            let sv = &self.support[k * self.dims..(k + 1) * self.dims];
            let d2 = (nx + dot(sv, sv) - 2.0 * dot(x, sv)).max(0.0);
            s += cf * f64::from((-g * d2).exp());
        }
        Ok(s - self.rho)
    }

    /// The predicted class of x (`true` = street).
    pub fn predict(&self, x: &[f32]) -> Result<bool> {
        Ok(self.decision(x)? > 0.0)
    }

    /// Predicted classes of the rows of a row-major matrix, in parallel.
    pub fn predict_flat(&self, x: &[f32]) -> Result<Vec<bool>> {
        if self.dims == 0 || x.len() % self.dims != 0 {
            return Err(StreetsError::FeatureLength {
                got: x.len(),
                expected: self.dims,
            });
        }
        let sv_norms: Vec<f32> = self
            .support
            .chunks_exact(self.dims)
            .map(|r| dot(r, r))
            .collect();
        let g = self.gamma as f32;
        Ok(x.par_chunks_exact(self.dims)
            .with_min_len(64)
            .map(|row| {
                let nx = dot(row, row);
                let mut s = 0f64;
                for ((sv, &nsv), &cf) in self
                    .support
                    .chunks_exact(self.dims)
                    .zip(&sv_norms)
                    .zip(&self.coef)
                {
                    let d2 = (nx + nsv - 2.0 * dot(row, sv)).max(0.0);
                    s += cf * f64::from((-g * d2).exp());
                }
                s > self.rho
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn kernel(a: &[f32], b: &[f32], gamma: f64) -> f64 {
        let d2: f64 = a.iter().zip(b).map(|(x, y)| f64::from(x - y).powi(2)).sum();
        (-gamma * d2).exp()
    }

    /// Two Gaussian blobs in 2-D, overlapping a little.
    fn blobs(n: usize, seed: u64) -> (Vec<Vec<f32>>, Vec<bool>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut x = Vec::new();
        let mut y = Vec::new();
        for k in 0..n {
            let pos = k % 2 == 0;
            let c = if pos { 1.0 } else { -1.0 };
            x.push(vec![
                c + rng.gen_range(-1.5f32..1.5),
                c * 0.5 + rng.gen_range(-1.5f32..1.5),
            ]);
            y.push(pos);
        }
        (x, y)
    }

    #[test]
    fn kkt_conditions_hold_at_the_solution() {
        let (x, y) = blobs(120, 3);
        let opt = SvmOptions {
            c: 2.0,
            gamma: Some(0.7),
            eps: 1e-5,
            ..SvmOptions::default()
        };
        let svm = Svm::train(&x, &y, &opt).unwrap();
        assert!(svm.stats.converged);
        // Recover α per training point and check the dual constraints and KKT.
        let mut alpha = vec![0.0; x.len()];
        for (k, cf) in svm.coef.iter().enumerate() {
            let sv = &svm.support[k * 2..k * 2 + 2];
            let t = x.iter().position(|r| r.as_slice() == sv).unwrap();
            alpha[t] = cf.abs();
        }
        let ysum: f64 = alpha
            .iter()
            .zip(&y)
            .map(|(a, &v)| if v { *a } else { -*a })
            .sum();
        assert!(ysum.abs() < 1e-9, "yᵀα = {ysum}");
        for (t, row) in x.iter().enumerate() {
            let yt = if y[t] { 1.0 } else { -1.0 };
            let margin = yt * svm.decision(row).unwrap();
            assert!((0.0..=opt.c + 1e-12).contains(&alpha[t]));
            if alpha[t] < 1e-9 {
                assert!(margin >= 1.0 - 1e-3, "α=0 but margin {margin}");
            } else if alpha[t] > opt.c - 1e-9 {
                assert!(margin <= 1.0 + 1e-3, "α=C but margin {margin}");
            } else {
                assert!((margin - 1.0).abs() < 1e-3, "free SV margin {margin}");
            }
        }
    }

    #[test]
    fn dual_objective_matches_brute_force_on_a_tiny_problem() {
        // 4 points, one dimension: the dual optimum found by a fine grid over the
        // equality-constrained feasible set equals SMO's objective.
        let x = vec![vec![0.0f32], vec![0.4], vec![0.6], vec![1.0]];
        let y = vec![false, true, false, true];
        let (c, gamma) = (1.5, 2.0);
        let svm = Svm::train(
            &x,
            &y,
            &SvmOptions {
                c,
                gamma: Some(gamma),
                eps: 1e-8,
                ..SvmOptions::default()
            },
        )
        .unwrap();
        let ys: Vec<f64> = y.iter().map(|&v| if v { 1.0 } else { -1.0 }).collect();
        let q = |i: usize, j: usize| ys[i] * ys[j] * kernel(&x[i], &x[j], gamma);
        let obj = |a: &[f64; 4]| {
            let mut s = 0.0;
            for i in 0..4 {
                for j in 0..4 {
                    s += 0.5 * a[i] * a[j] * q(i, j);
                }
                s -= a[i];
            }
            s
        };
        // α3 = α0 + α2 − α1 (from yᵀα = 0).
        let steps = 120;
        let mut best = f64::INFINITY;
        for a0 in 0..=steps {
            for a1 in 0..=steps {
                for a2 in 0..=steps {
                    let a = [
                        c * a0 as f64 / steps as f64,
                        c * a1 as f64 / steps as f64,
                        c * a2 as f64 / steps as f64,
                        0.0,
                    ];
                    let a3 = a[0] + a[2] - a[1];
                    if !(0.0..=c).contains(&a3) {
                        continue;
                    }
                    best = best.min(obj(&[a[0], a[1], a[2], a3]));
                }
            }
        }
        assert!(
            svm.stats.objective <= best + 1e-5,
            "SMO {} > grid {best}",
            svm.stats.objective
        );
        assert!(
            svm.stats.objective >= best - 5e-3,
            "SMO {} ≪ grid {best}",
            svm.stats.objective
        );
    }

    #[test]
    fn small_cache_gives_the_same_model() {
        let (x, y) = blobs(300, 9);
        let big = Svm::train(&x, &y, &SvmOptions::default()).unwrap();
        let tiny = Svm::train(
            &x,
            &y,
            &SvmOptions {
                cache_mb: 0,
                ..SvmOptions::default()
            },
        )
        .unwrap();
        assert_eq!(big.coef, tiny.coef);
        assert!(tiny.stats.kernel_rows > big.stats.kernel_rows);
    }

    #[test]
    fn separates_blobs_and_predict_flat_agrees() {
        let (x, y) = blobs(400, 4);
        let svm = Svm::train(&x, &y, &SvmOptions::default()).unwrap();
        let (xt, yt) = blobs(400, 5);
        let flat: Vec<f32> = xt.iter().flatten().copied().collect();
        let pred = svm.predict_flat(&flat).unwrap();
        let correct = pred.iter().zip(&yt).filter(|(a, b)| a == b).count();
        assert!(correct > 300, "accuracy {correct}/400");
        for (row, &p) in xt.iter().zip(&pred) {
            assert_eq!(svm.predict(row).unwrap(), p);
        }
    }

    #[test]
    fn one_class_and_bad_lengths_are_errors() {
        let x = vec![vec![0.0f32], vec![1.0]];
        assert!(matches!(
            Svm::train(&x, &[true, true], &SvmOptions::default()),
            Err(StreetsError::OneClass { .. })
        ));
        let bad = vec![vec![0.0f32], vec![1.0, 2.0]];
        assert!(Svm::train(&bad, &[true, false], &SvmOptions::default()).is_err());
    }
}
