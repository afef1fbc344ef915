//! A linear SVM trained by dual coordinate descent, as liblinear's L2-regularised L1- and
//! L2-loss solvers (Hsieh, Chang, Lin, Keerthi, Sundararajan, "A dual coordinate descent
//! method for large-scale linear SVM", ICML 2008, Algorithm 1 with the shrinking of §3.2).
//!
//! It solves `min_α ½ αᵀ(Q + D)α − eᵀα, 0 ≤ α_i ≤ U_i` with `Q_ij = y_i y_j x_iᵀx_j`: for the
//! hinge loss `D = 0, U_i = C_i`; for the squared hinge (the default, liblinear `-s 1`)
//! `D_ii = 1 / (2 C_i), U_i = ∞`, a strongly convex dual on which coordinate descent
//! converges in a few epochs even where the classes overlap (the hinge dual needed hundreds
//! of epochs on the relation features). It keeps `w = Σ α_i y_i x_i` up to date, so each
//! coordinate step costs O(d). The bias is a
//! constant feature 1 (liblinear `-B 1`). Positive samples may get a larger `C` (`-w1`).
//! Epochs visit the samples in a seeded random order and stop when the projected gradient's
//! spread falls below `eps` (liblinear's 0.1) or after `max_epochs`.
//!
//! [`cross_validate`] picks C (and the positive weight) by k-fold cross-validation over
//! groups (whole scenes in one fold), maximising the F1 of the positive class.
//!
//! ```
//! use srtree::svm::{LinearSvm, SvmOptions};
//! let x: Vec<Vec<f32>> = (0..40).map(|i| vec![i as f32 / 40.0]).collect();
//! let y: Vec<bool> = (0..40).map(|i| i >= 20).collect();
//! let svm = LinearSvm::train(&x, &y, &SvmOptions { c: 100.0, ..SvmOptions::default() })?;
//! assert!(svm.predict(&[0.9]) && !svm.predict(&[0.1]));
//! # Ok::<(), srtree::SrtreeError>(())
//! ```

use crate::error::{Result, SrtreeError};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The loss of the primal problem.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum Loss {
    /// `max(0, 1 − y f(x))` (liblinear `-s 3`): dual box `0 ≤ α_i ≤ C_i`.
    Hinge,
    /// `max(0, 1 − y f(x))²` (liblinear `-s 1`, its default): dual `α_i ≥ 0` with
    /// `1 / (2 C_i)` added to `Q_ii`, strongly convex, so coordinate descent converges
    /// linearly even where the classes overlap.
    #[default]
    SquaredHinge,
}

/// Options of one training run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SvmOptions {
    /// Box constraint C.
    pub c: f64,
    /// The loss.
    #[serde(default)]
    pub loss: Loss,
    /// C of positive samples is `c · positive_weight`.
    pub positive_weight: f64,
    /// Stopping tolerance on the projected-gradient spread.
    pub eps: f64,
    /// Largest number of epochs.
    pub max_epochs: usize,
    /// Seed of the visiting order.
    pub seed: u64,
}

impl Default for SvmOptions {
    fn default() -> Self {
        SvmOptions {
            c: 1.0,
            loss: Loss::default(),
            positive_weight: 1.0,
            eps: 0.1,
            max_epochs: 1000,
            seed: 1,
        }
    }
}

/// A trained linear SVM: `f(x) = wᵀx + b`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LinearSvm {
    /// Weights.
    pub w: Vec<f64>,
    /// Bias.
    pub b: f64,
    /// The options it was trained with.
    pub options: SvmOptions,
    /// Epochs run.
    pub epochs: usize,
}

impl LinearSvm {
    /// A classifier that says yes exactly where the rule feature (the last of `dims`:
    /// `rule_value` when the rule fires, 0 otherwise) is set.
    pub fn rule_alone(dims: usize, rule_value: f32, options: SvmOptions) -> LinearSvm {
        let mut w = vec![0.0; dims];
        if let Some(last) = w.last_mut() {
            // Decision +1 where the rule fires, -1 where it does not.
            *last = 2.0 / f64::from(rule_value);
        }
        LinearSvm {
            w,
            b: -1.0,
            options,
            epochs: 0,
        }
    }

    /// Trains on rows `x` with labels `y`.
    pub fn train(x: &[Vec<f32>], y: &[bool], options: &SvmOptions) -> Result<LinearSvm> {
        let fail = |message: String| SrtreeError::Training {
            relation: "svm".into(),
            message,
        };
        if x.is_empty() || x.len() != y.len() {
            return Err(fail(format!("{} rows and {} labels", x.len(), y.len())));
        }
        if !(options.c > 0.0 && options.positive_weight > 0.0) {
            return Err(fail(format!(
                "C = {} and positive weight = {} must be positive",
                options.c, options.positive_weight
            )));
        }
        let d = x[0].len();
        if x.iter().any(|r| r.len() != d) {
            return Err(fail("rows of different lengths".into()));
        }
        let n = x.len();
        let mut w = vec![0.0f64; d + 1];
        let mut alpha = vec![0.0f64; n];
        let c_of = |p: bool| {
            if p {
                options.c * options.positive_weight
            } else {
                options.c
            }
        };
        // Diagonal added to Q and the upper bound of α, per sample.
        let (diag, upper): (Vec<f64>, Vec<f64>) = y
            .iter()
            .map(|&p| match options.loss {
                Loss::Hinge => (0.0, c_of(p)),
                Loss::SquaredHinge => (0.5 / c_of(p), f64::INFINITY),
            })
            .unzip();
        let qd: Vec<f64> = x
            .iter()
            .zip(&diag)
            .map(|(r, &dg)| 1.0 + dg + r.iter().map(|&v| f64::from(v) * f64::from(v)).sum::<f64>())
            .collect();
        // Shrinking (Hsieh et al. §3.2, liblinear): a sample at a bound whose gradient lies
        // outside the previous epoch's projected-gradient range leaves the active set; when
        // the active set has converged, every sample is checked once more.
        let mut active: Vec<usize> = (0..n).collect();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(options.seed);
        let (mut pg_max_old, mut pg_min_old) = (f64::INFINITY, f64::NEG_INFINITY);
        let mut epochs = 0;
        while epochs < options.max_epochs {
            epochs += 1;
            active.shuffle(&mut rng);
            let (mut pg_max, mut pg_min) = (f64::NEG_INFINITY, f64::INFINITY);
            let mut k = 0;
            while k < active.len() {
                let i = active[k];
                let yi = if y[i] { 1.0 } else { -1.0 };
                let dot: f64 = w[d]
                    + x[i]
                        .iter()
                        .zip(&w)
                        .map(|(&v, &wk)| f64::from(v) * wk)
                        .sum::<f64>();
                let g = yi * dot - 1.0 + diag[i] * alpha[i];
                let pg = if alpha[i] == 0.0 {
                    if g > pg_max_old {
                        active.swap_remove(k);
                        continue;
                    }
                    g.min(0.0)
                } else if alpha[i] == upper[i] {
                    if g < pg_min_old {
                        active.swap_remove(k);
                        continue;
                    }
                    g.max(0.0)
                } else {
                    g
                };
                k += 1;
                pg_max = pg_max.max(pg);
                pg_min = pg_min.min(pg);
                if pg.abs() > 1e-12 {
                    let old = alpha[i];
                    alpha[i] = (old - g / qd[i]).clamp(0.0, upper[i]);
                    let delta = (alpha[i] - old) * yi;
                    for (wk, &v) in w.iter_mut().zip(&x[i]) {
                        *wk += delta * f64::from(v);
                    }
                    w[d] += delta;
                }
            }
            if pg_max - pg_min < options.eps || active.is_empty() {
                if active.len() == n {
                    break;
                }
                active = (0..n).collect();
                (pg_max_old, pg_min_old) = (f64::INFINITY, f64::NEG_INFINITY);
                continue;
            }
            pg_max_old = if pg_max <= 0.0 { f64::INFINITY } else { pg_max };
            pg_min_old = if pg_min >= 0.0 {
                f64::NEG_INFINITY
            } else {
                pg_min
            };
        }
        let b = w.pop().unwrap_or(0.0);
        Ok(LinearSvm {
            w,
            b,
            options: options.clone(),
            epochs,
        })
    }

    /// The decision value `wᵀx + b`.
    pub fn decision(&self, x: &[f32]) -> f64 {
        self.b
            + x.iter()
                .zip(&self.w)
                .map(|(&v, &w)| f64::from(v) * w)
                .sum::<f64>()
    }

    /// The predicted label (`wᵀx + b > 0`).
    pub fn predict(&self, x: &[f32]) -> bool {
        self.decision(x) > 0.0
    }
}

/// F1 of the positive class.
pub fn f1(predicted: &[bool], truth: &[bool]) -> f64 {
    let tp = predicted
        .iter()
        .zip(truth)
        .filter(|(&p, &t)| p && t)
        .count() as f64;
    let fp = predicted
        .iter()
        .zip(truth)
        .filter(|(&p, &t)| p && !t)
        .count() as f64;
    let fneg = predicted
        .iter()
        .zip(truth)
        .filter(|(&p, &t)| !p && t)
        .count() as f64;
    if tp == 0.0 {
        0.0
    } else {
        2.0 * tp / (2.0 * tp + fp + fneg)
    }
}

/// The outcome of cross-validation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CvResult {
    /// The chosen options.
    pub best: SvmOptions,
    /// Cross-validated positive-class F1 of each (C, positive weight) tried.
    pub scores: Vec<(f64, f64, f64)>,
    /// Out-of-fold predictions of the chosen options, per sample.
    pub out_of_fold: Vec<bool>,
    /// Out-of-fold decision values of the chosen options, per sample.
    pub out_of_fold_decision: Vec<f64>,
}

/// k-fold cross-validation over groups of each (C, positive weight) of `grid`: fold of a
/// sample = group mod k; samples with
/// `keep[i] == false` are left out of training and of the score but still predicted (their
/// out-of-fold decisions are returned).
pub fn cross_validate(
    x: &[Vec<f32>],
    y: &[bool],
    groups: &[usize],
    keep: Option<&[bool]>,
    folds: usize,
    grid: &[(f64, f64)],
    base: &SvmOptions,
) -> Result<CvResult> {
    let folds = folds.max(2);
    let runs: Vec<(usize, usize)> = (0..grid.len())
        .flat_map(|g| (0..folds).map(move |f| (g, f)))
        .collect();
    type FoldPredictions = (usize, usize, Vec<(usize, f64)>);
    let predictions: Vec<Result<FoldPredictions>> = runs
        .par_iter()
        .map(|&(g, f)| {
            let train: Vec<usize> = (0..x.len())
                .filter(|&i| groups[i] % folds != f && keep.is_none_or(|k| k[i]))
                .collect();
            let test: Vec<usize> = (0..x.len()).filter(|&i| groups[i] % folds == f).collect();
            let opts = SvmOptions {
                c: grid[g].0,
                positive_weight: grid[g].1,
                ..base.clone()
            };
            let tx: Vec<Vec<f32>> = train.iter().map(|&i| x[i].clone()).collect();
            let ty: Vec<bool> = train.iter().map(|&i| y[i]).collect();
            if tx.is_empty() || ty.iter().all(|&v| v) || ty.iter().all(|&v| !v) {
                return Ok((g, f, test.iter().map(|&i| (i, -1.0)).collect()));
            }
            let svm = LinearSvm::train(&tx, &ty, &opts)?;
            Ok((
                g,
                f,
                test.iter().map(|&i| (i, svm.decision(&x[i]))).collect(),
            ))
        })
        .collect();
    let mut per_grid = vec![vec![-1.0; x.len()]; grid.len()];
    for r in predictions {
        let (g, _, preds) = r?;
        for (i, p) in preds {
            per_grid[g][i] = p;
        }
    }
    let kept = |i: usize| keep.is_none_or(|k| k[i]);
    let scored_truth: Vec<bool> = (0..x.len()).filter(|&i| kept(i)).map(|i| y[i]).collect();
    let scores: Vec<(f64, f64, f64)> = grid
        .iter()
        .zip(&per_grid)
        .map(|(&(c, p), d)| {
            let pred: Vec<bool> = (0..x.len())
                .filter(|&i| kept(i))
                .map(|i| d[i] > 0.0)
                .collect();
            (c, p, f1(&pred, &scored_truth))
        })
        .collect();
    let best_g = (0..grid.len())
        .max_by(|&a, &b| scores[a].2.total_cmp(&scores[b].2).then(b.cmp(&a)))
        .unwrap_or(0);
    Ok(CvResult {
        best: SvmOptions {
            c: grid[best_g].0,
            positive_weight: grid[best_g].1,
            ..base.clone()
        },
        scores,
        out_of_fold: per_grid[best_g].iter().map(|&v| v > 0.0).collect(),
        out_of_fold_decision: per_grid.swap_remove(best_g),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;

    #[test]
    fn the_rule_alone_says_yes_exactly_where_the_rule_fires() {
        let scale = 4.0;
        let svm = LinearSvm::rule_alone(4, scale, SvmOptions::default());
        assert!(svm.decision(&[9.0, -9.0, 9.0, scale]) > 0.0);
        assert!(svm.decision(&[9.0, -9.0, 9.0, 0.0]) < 0.0);
        assert_eq!(svm.w.len(), 4);
    }

    /// Primal objective ½‖w‖² + Σ C_i loss(y_i f(x_i)) with the bias regularised too.
    fn primal(svm: &LinearSvm, x: &[Vec<f32>], y: &[bool], c: f64, loss: Loss) -> f64 {
        let reg = 0.5 * (svm.w.iter().map(|w| w * w).sum::<f64>() + svm.b * svm.b);
        reg + x
            .iter()
            .zip(y)
            .map(|(r, &t)| {
                let s = if t { 1.0 } else { -1.0 };
                let h = (1.0 - s * svm.decision(r)).max(0.0);
                c * match loss {
                    Loss::Hinge => h,
                    Loss::SquaredHinge => h * h,
                }
            })
            .sum::<f64>()
    }

    #[test]
    fn separable_data_is_separated_and_the_objective_is_near_optimal() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let x: Vec<Vec<f32>> = (0..300)
            .map(|_| vec![rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)])
            .collect();
        let y: Vec<bool> = x.iter().map(|r| r[0] + 0.5 * r[1] > 0.1).collect();
        for loss in [Loss::Hinge, Loss::SquaredHinge] {
            let opts = SvmOptions {
                c: 10.0,
                loss,
                eps: 1e-4,
                max_epochs: 20_000,
                ..SvmOptions::default()
            };
            let svm = LinearSvm::train(&x, &y, &opts).unwrap();
            let errors = x
                .iter()
                .zip(&y)
                .filter(|(r, &t)| svm.predict(r) != t)
                .count();
            assert!(errors <= 3, "{loss:?}: {errors} training errors");
            // No small perturbation of the solution lowers the primal objective.
            let base = primal(&svm, &x, &y, 10.0, loss);
            for k in 0..3 {
                for delta in [-1e-3, 1e-3] {
                    let mut s = svm.clone();
                    if k < 2 {
                        s.w[k] += delta;
                    } else {
                        s.b += delta;
                    }
                    assert!(
                        primal(&s, &x, &y, 10.0, loss) >= base - 1e-3 * base.abs().max(1.0),
                        "{loss:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn cross_validation_prefers_a_working_c_and_reports_every_pair() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let x: Vec<Vec<f32>> = (0..400).map(|_| vec![rng.gen_range(-1.0..1.0)]).collect();
        let y: Vec<bool> = x.iter().map(|r| r[0] > 0.6).collect();
        let groups: Vec<usize> = (0..400).map(|i| i / 20).collect();
        let cv = cross_validate(
            &x,
            &y,
            &groups,
            None,
            5,
            &[(1e-4, 1.0), (10.0, 1.0)],
            &SvmOptions::default(),
        )
        .unwrap();
        assert_eq!(cv.scores.len(), 2);
        assert_eq!(cv.best.c, 10.0);
        assert!(cv.scores[1].2 > 0.9, "{:?}", cv.scores);
        assert_eq!(cv.out_of_fold.len(), 400);
        assert!(LinearSvm::train(&[], &[], &SvmOptions::default()).is_err());
    }
}
