//! Cell label choice by Dirichlet likelihood (thesis §3.3.1).
//!
//! Every cell keeps a histogram of the class labels of the points inserted into it. Its
//! normalised form `x_i` (with a pseudo-count per class, so that no component is zero and
//! sparse cells look uncertain) is scored under one Dirichlet per class `j`,
//! `p^j(x) = Γ(Σ_k α_k^j) / Π_k Γ(α_k^j) · Π_k x_k^{α_k^j − 1}`, and the cell's label is
//! `argmax_j p^j(x)`. The concentration parameters are learnt from labelled training cells
//! by moment matching (Minka, "Estimating a Dirichlet distribution", 2000, eq. 21–23): with
//! the sample means `m_k = E[x_k]` and second moments `E[x_k²]`, the precision is
//! `s = (m_k − E[x_k²]) / (E[x_k²] − m_k²)`, averaged in the log domain over the components
//! with non-zero variance, and `α_k = s · m_k`.
//!
//! Fitting is O(cells · K); a label costs O(K²) for K classes.
//!
//! ```
//! use srtree::dirichlet::{Dirichlet, DirichletModel};
//! // Two classes over 3 components: class 0 cells look like (0.8, 0.1, 0.1).
//! let model = DirichletModel {
//!     smoothing: 0.5,
//!     classes: vec![
//!         Some(Dirichlet::new(vec![8.0, 1.0, 1.0])),
//!         Some(Dirichlet::new(vec![1.0, 8.0, 1.0])),
//!         None,
//!     ],
//! };
//! assert_eq!(model.label(&[9, 1, 0]), Some(0));
//! assert_eq!(model.label(&[0, 7, 1]), Some(1));
//! ```

use crate::error::{Result, SrtreeError};
use serde::{Deserialize, Serialize};

/// `ln Γ(x)` for `x > 0` (Lanczos approximation, g = 7, 9 terms; relative error < 1e-13).
pub fn ln_gamma(x: f64) -> f64 {
    const G: f64 = 7.0;
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection: Γ(x) Γ(1 − x) = π / sin(πx).
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + G + 0.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// One Dirichlet distribution with its log normaliser precomputed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Dirichlet {
    /// Concentration parameters α_k (all > 0).
    pub alpha: Vec<f64>,
    /// `ln Γ(Σα) − Σ ln Γ(α_k)`.
    pub log_norm: f64,
}

impl Dirichlet {
    /// A Dirichlet with these concentration parameters (each must be > 0).
    pub fn new(alpha: Vec<f64>) -> Dirichlet {
        assert!(alpha.iter().all(|&a| a > 0.0 && a.is_finite()));
        let sum: f64 = alpha.iter().sum();
        let log_norm = ln_gamma(sum) - alpha.iter().map(|&a| ln_gamma(a)).sum::<f64>();
        Dirichlet { alpha, log_norm }
    }

    /// Log density at a point `x` of the open simplex (`x_k > 0`, `Σ x_k = 1`).
    pub fn log_pdf(&self, x: &[f64]) -> f64 {
        self.log_norm
            + self
                .alpha
                .iter()
                .zip(x)
                .map(|(&a, &xk)| (a - 1.0) * xk.ln())
                .sum::<f64>()
    }

    /// Moment-matching estimate from samples on the simplex (Minka 2000, eq. 21–23).
    ///
    /// Needs at least two samples with some spread; components whose mean is 0 get the
    /// smallest positive α seen (times 10⁻³), so the density stays defined.
    pub fn fit_moments(samples: &[Vec<f64>], name: &str) -> Result<Dirichlet> {
        let fail = |message: String| SrtreeError::Fit {
            class: name.to_string(),
            message,
        };
        let n = samples.len();
        if n < 2 {
            return Err(fail(format!("{n} training cells, need at least 2")));
        }
        let k = samples[0].len();
        let mut mean = vec![0.0; k];
        let mut second = vec![0.0; k];
        for x in samples {
            if x.len() != k {
                return Err(fail(format!(
                    "sample of {} components, expected {k}",
                    x.len()
                )));
            }
            for j in 0..k {
                mean[j] += x[j];
                second[j] += x[j] * x[j];
            }
        }
        for j in 0..k {
            mean[j] /= n as f64;
            second[j] /= n as f64;
        }
        let (mut log_s, mut used) = (0.0, 0usize);
        for j in 0..k {
            let var = second[j] - mean[j] * mean[j];
            let num = mean[j] - second[j];
            if var > 1e-12 && num > 0.0 {
                log_s += (num / var).ln();
                used += 1;
            }
        }
        if used == 0 {
            return Err(fail("all training cells have the same histogram".into()));
        }
        let s = (log_s / used as f64).exp();
        let floor = mean
            .iter()
            .filter(|&&m| m > 0.0)
            .fold(f64::INFINITY, |a, &m| a.min(s * m))
            * 1e-3;
        let alpha = mean
            .iter()
            .map(|&m| if m > 0.0 { s * m } else { floor })
            .collect();
        Ok(Dirichlet::new(alpha))
    }
}

/// One optional Dirichlet per class id and the pseudo-count used to normalise histograms.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DirichletModel {
    /// Pseudo-count added to every class count before normalising.
    pub smoothing: f64,
    /// Per class id: its Dirichlet, or `None` if the class had no training cells.
    pub classes: Vec<Option<Dirichlet>>,
}

/// Options of [`DirichletModel::fit`].
#[derive(Debug, Clone, PartialEq)]
pub struct FitOptions {
    /// Pseudo-count per class added before normalising a histogram (default 0.5).
    pub smoothing: f64,
    /// Classes with fewer training cells get no Dirichlet (default 20).
    pub min_cells: usize,
    /// Largest number of training cells used per class (seeded subsample; default 200 000).
    pub max_cells_per_class: usize,
    /// Seed of the subsample.
    pub seed: u64,
    /// Fit only on cells whose histogram holds two or more classes (default false). The
    /// choice is only ever open on such cells (see [`DirichletModel::label`]), and pure
    /// cells, the large majority, would otherwise set the precision.
    pub mixed_only: bool,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            smoothing: 0.5,
            min_cells: 20,
            max_cells_per_class: 200_000,
            seed: 1,
            mixed_only: false,
        }
    }
}

/// The normalised histogram with a pseudo-count per class.
pub fn normalise(counts: &[u16], smoothing: f64, out: &mut Vec<f64>) {
    let total: f64 =
        counts.iter().map(|&c| f64::from(c)).sum::<f64>() + smoothing * counts.len() as f64;
    out.clear();
    out.extend(counts.iter().map(|&c| (f64::from(c) + smoothing) / total));
}

impl DirichletModel {
    /// Learns one Dirichlet per class from training histograms and their true classes.
    ///
    /// `cells` pairs a class-count histogram with the cell's true class id (for example the
    /// majority of its points' ground-truth labels).
    pub fn fit(cells: &[(Vec<u16>, u8)], options: &FitOptions) -> Result<DirichletModel> {
        use rand::seq::SliceRandom;
        use rand::SeedableRng;
        if !(options.smoothing > 0.0 && options.smoothing.is_finite()) {
            return Err(SrtreeError::InvalidOption {
                name: "smoothing",
                value: options.smoothing,
                expected: "a positive pseudo-count",
            });
        }
        let k = cells.first().map_or(0, |c| c.0.len());
        let mut by_class: Vec<Vec<usize>> = vec![Vec::new(); k];
        for (i, (h, c)) in cells.iter().enumerate() {
            let mixed = h.iter().filter(|&&n| n > 0).count() >= 2;
            if h.len() == k && (mixed || !options.mixed_only) {
                if let Some(v) = by_class.get_mut(usize::from(*c)) {
                    v.push(i);
                }
            }
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(options.seed);
        let mut classes = Vec::with_capacity(k);
        let mut x = Vec::new();
        for (j, idx) in by_class.iter_mut().enumerate() {
            if idx.len() < options.min_cells.max(2) {
                classes.push(None);
                continue;
            }
            if idx.len() > options.max_cells_per_class {
                idx.shuffle(&mut rng);
                idx.truncate(options.max_cells_per_class);
            }
            let samples: Vec<Vec<f64>> = idx
                .iter()
                .map(|&i| {
                    normalise(&cells[i].0, options.smoothing, &mut x);
                    x.clone()
                })
                .collect();
            let name = geodata::classes::Class::from_id(j as u8)
                .map_or_else(|| format!("#{j}"), |c| c.name().to_string());
            classes.push(Some(Dirichlet::fit_moments(&samples, &name)?));
        }
        Ok(DirichletModel {
            smoothing: options.smoothing,
            classes,
        })
    }

    /// The class id of largest Dirichlet likelihood among the classes present in a histogram
    /// (`None`: no model fits its length, the histogram is empty, or no present class has
    /// a Dirichlet). A cell is never labelled with a class none of its points has, so a
    /// one-class histogram gets that class.
    pub fn label(&self, counts: &[u16]) -> Option<u8> {
        if counts.len() != self.classes.len() || counts.iter().all(|&c| c == 0) {
            return None;
        }
        let total: f64 = counts.iter().map(|&c| f64::from(c)).sum::<f64>()
            + self.smoothing * counts.len() as f64;
        let mut best: Option<(f64, u8)> = None;
        for (j, d) in self.classes.iter().enumerate() {
            let Some(d) = d else { continue };
            if counts[j] == 0 {
                continue;
            }
            let mut lp = d.log_norm;
            for (&a, &c) in d.alpha.iter().zip(counts) {
                lp += (a - 1.0) * ((f64::from(c) + self.smoothing) / total).ln();
            }
            if best.is_none_or(|(b, _)| lp > b) {
                best = Some((lp, j as u8));
            }
        }
        best.map(|(_, j)| j)
    }
}

/// The class id with the most points (ties: the smaller id); `None` for an empty histogram.
pub fn majority(counts: &[u16]) -> Option<u8> {
    let mut best: Option<(u16, u8)> = None;
    for (j, &c) in counts.iter().enumerate() {
        if c > 0 && best.is_none_or(|(b, _)| c > b) {
            best = Some((c, j as u8));
        }
    }
    best.map(|(_, j)| j)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr_free::sample_dirichlet;

    /// Gamma and Dirichlet sampling without an extra crate (Marsaglia–Tsang).
    mod rand_distr_free {
        use rand::Rng;
        fn normal(rng: &mut impl Rng) -> f64 {
            // Box–Muller.
            let u1: f64 = rng.gen::<f64>().max(1e-300);
            let u2: f64 = rng.gen();
            (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
        }
        fn gamma(rng: &mut impl Rng, shape: f64) -> f64 {
            if shape < 1.0 {
                let u: f64 = rng.gen::<f64>().max(1e-300);
                return gamma(rng, shape + 1.0) * u.powf(1.0 / shape);
            }
            let d = shape - 1.0 / 3.0;
            let c = 1.0 / (9.0 * d).sqrt();
            loop {
                let z = normal(rng);
                let v = (1.0 + c * z).powi(3);
                if v <= 0.0 {
                    continue;
                }
                let u: f64 = rng.gen();
                if u.ln() < 0.5 * z * z + d - d * v + d * v.ln() {
                    return d * v;
                }
            }
        }
        pub fn sample_dirichlet(rng: &mut impl Rng, alpha: &[f64]) -> Vec<f64> {
            let g: Vec<f64> = alpha.iter().map(|&a| gamma(rng, a)).collect();
            let s: f64 = g.iter().sum();
            g.iter().map(|x| x / s).collect()
        }
    }

    #[test]
    fn ln_gamma_matches_factorials_and_half_integers() {
        let mut f = 1.0f64;
        for n in 1..20 {
            assert!((ln_gamma(n as f64) - f.ln()).abs() < 1e-10, "n = {n}");
            f *= n as f64;
        }
        let sqrt_pi = std::f64::consts::PI.sqrt();
        assert!((ln_gamma(0.5) - sqrt_pi.ln()).abs() < 1e-12);
        assert!((ln_gamma(1.5) - (0.5 * sqrt_pi).ln()).abs() < 1e-12);
        assert!((ln_gamma(0.1) - 2.252_712_651_734_206).abs() < 1e-10);
    }

    #[test]
    fn moment_matching_recovers_known_parameters() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for truth in [
            vec![2.0, 5.0, 1.0],
            vec![0.5, 0.5, 3.0, 8.0],
            vec![20.0, 1.0, 1.0, 1.0, 2.0],
        ] {
            let samples: Vec<Vec<f64>> = (0..40_000)
                .map(|_| sample_dirichlet(&mut rng, &truth))
                .collect();
            let fit = Dirichlet::fit_moments(&samples, "test").unwrap();
            for (a, t) in fit.alpha.iter().zip(&truth) {
                assert!(
                    (a - t).abs() / t < 0.05,
                    "fitted {:?} for true {truth:?}",
                    fit.alpha
                );
            }
        }
    }

    #[test]
    fn label_choice_equals_brute_force() {
        // Brute force: the density Π x^(α−1) / B(α) with B from Γ itself, for every class.
        let gamma = |x: f64| ln_gamma(x).exp();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        use rand::Rng;
        for _ in 0..200 {
            let k = rng.gen_range(2..6);
            let classes: Vec<Option<Dirichlet>> = (0..k)
                .map(|_| {
                    rng.gen_bool(0.8)
                        .then(|| Dirichlet::new((0..k).map(|_| rng.gen_range(0.3..6.0)).collect()))
                })
                .collect();
            let model = DirichletModel {
                smoothing: 0.5,
                classes: classes.clone(),
            };
            let counts: Vec<u16> = (0..k).map(|_| rng.gen_range(0..6)).collect();
            let got = model.label(&counts);
            if classes
                .iter()
                .zip(&counts)
                .all(|(d, &c)| d.is_none() || c == 0)
            {
                assert_eq!(got, None);
                continue;
            }
            let total: f64 = counts.iter().map(|&c| f64::from(c) + 0.5).sum();
            let x: Vec<f64> = counts
                .iter()
                .map(|&c| (f64::from(c) + 0.5) / total)
                .collect();
            let mut best = (f64::NEG_INFINITY, 0u8);
            for (j, d) in classes.iter().enumerate() {
                let Some(d) = d else { continue };
                if counts[j] == 0 {
                    continue;
                }
                let b: f64 = d.alpha.iter().map(|&a| gamma(a)).product::<f64>()
                    / gamma(d.alpha.iter().sum());
                let p: f64 = d
                    .alpha
                    .iter()
                    .zip(&x)
                    .map(|(&a, &xk)| xk.powf(a - 1.0))
                    .product::<f64>()
                    / b;
                if p > best.0 {
                    best = (p, j as u8);
                }
            }
            assert_eq!(got, Some(best.1), "counts {counts:?}");
        }
    }

    #[test]
    fn fit_needs_spread_and_cells() {
        let same = vec![vec![0.5, 0.5]; 10];
        assert!(matches!(
            Dirichlet::fit_moments(&same, "car"),
            Err(SrtreeError::Fit { .. })
        ));
        assert!(Dirichlet::fit_moments(&same[..1], "car").is_err());
        assert_eq!(majority(&[0, 3, 3, 1]), Some(1));
        assert_eq!(majority(&[0, 0]), None);
    }
}
