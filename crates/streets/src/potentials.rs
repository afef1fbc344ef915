//! Segment geometry potentials (thesis eq. 4.2) for every θ by the column-count DP of eq. 4.4,
//! the geometry prior, and the intersegment potential's scale.
//!
//! A geometry θ = (w, d) of a corridor with N columns of `bin_m` is the column range
//! `a ..= b` it covers: lower edge `u = −half + a·bin`, upper edge `u = −half + (b+1)·bin`,
//! so d = (lower + upper)/2 and w = (b − a + 1)·bin. The log-likelihood of eq. 4.4,
//! `Σ_ij log P(z_ij | x_ij(θ))`, depends on the label grid only through the per-column counts
//! of bins classified 1 and 0; with prefix sums over the columns each θ costs O(1) after an
//! O(L·N) count, so the whole table of N(N+1)/2 geometries costs O(L·N + N²).
//! Unobserved or masked bins (no label) contribute nothing.

use serde::{Deserialize, Serialize};

/// Per-column counts of bins classified street (1) and non-street (0).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ColumnCounts {
    /// Bins labelled 1 per column.
    pub ones: Vec<u32>,
    /// Bins labelled 0 per column.
    pub zeros: Vec<u32>,
}

impl ColumnCounts {
    /// Counts from a row-major `rows × cols` grid of labels (`None`: unobserved or masked).
    pub fn from_grid(labels: &[Option<bool>], cols: usize) -> ColumnCounts {
        let mut c = ColumnCounts {
            ones: vec![0; cols],
            zeros: vec![0; cols],
        };
        if cols == 0 {
            return c;
        }
        for row in labels.chunks_exact(cols) {
            for (j, l) in row.iter().enumerate() {
                match l {
                    Some(true) => c.ones[j] += 1,
                    Some(false) => c.zeros[j] += 1,
                    None => {}
                }
            }
        }
        c
    }

    /// Number of columns.
    pub fn cols(&self) -> usize {
        self.ones.len()
    }

    /// Labelled bins in all columns.
    pub fn total(&self) -> u64 {
        self.ones
            .iter()
            .zip(&self.zeros)
            .map(|(&a, &b)| u64::from(a) + u64::from(b))
            .sum()
    }
}

/// The classifier's confusion matrix `counts[x][z]` (x: true class, z: predicted).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Confusion {
    /// Counts: `[true 0 → [pred 0, pred 1], true 1 → [pred 0, pred 1]]`.
    pub counts: [[u64; 2]; 2],
}

impl Confusion {
    /// Counts from paired truths and predictions.
    pub fn from_pairs(truth: &[bool], predicted: &[bool]) -> Confusion {
        let mut counts = [[0u64; 2]; 2];
        for (&t, &p) in truth.iter().zip(predicted) {
            counts[usize::from(t)][usize::from(p)] += 1;
        }
        Confusion { counts }
    }

    /// `c̃(x, z) = log C[x, z] / P(x) = log P(z | x)`, Laplace-smoothed (+1 per cell).
    pub fn log_likelihood(&self) -> [[f64; 2]; 2] {
        let mut out = [[0.0; 2]; 2];
        for (o, row) in out.iter_mut().zip(&self.counts) {
            let total = (row[0] + row[1] + 2) as f64;
            for (v, &c) in o.iter_mut().zip(row) {
                *v = ((c + 1) as f64 / total).ln();
            }
        }
        out
    }
}

/// The discrete geometry grid of one corridor: N columns of `bin_m`, symmetric about the centre line.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ThetaGrid {
    /// Columns N.
    pub cols: usize,
    /// Column width, metres.
    pub bin_m: f64,
    /// Widest street considered, in columns.
    pub max_width_cols: usize,
}

impl ThetaGrid {
    /// Half width of the corridor, metres.
    pub fn half_m(&self) -> f64 {
        0.5 * self.cols as f64 * self.bin_m
    }

    /// (offset d, width w) in metres of the column range `a ..= b`.
    pub fn geometry(&self, a: usize, b: usize) -> (f64, f64) {
        let lo = -self.half_m() + a as f64 * self.bin_m;
        let hi = -self.half_m() + (b + 1) as f64 * self.bin_m;
        (0.5 * (lo + hi), hi - lo)
    }

    /// The column range closest to a geometry (clamped to the corridor).
    pub fn columns_of(&self, offset_m: f64, width_m: f64) -> (usize, usize) {
        let n = self.cols as f64;
        let lo = ((offset_m - 0.5 * width_m + self.half_m()) / self.bin_m).round();
        let hi = ((offset_m + 0.5 * width_m + self.half_m()) / self.bin_m).round() - 1.0;
        let a = lo.clamp(0.0, n - 1.0) as usize;
        let b = hi.clamp(a as f64, n - 1.0) as usize;
        (a, b)
    }

    /// Whether `a ..= b` is an allowed geometry.
    pub fn valid(&self, a: usize, b: usize) -> bool {
        a <= b && b < self.cols && b - a < self.max_width_cols
    }
}

/// Gaussian prior N(d | μ_d, σ_d) · N(log w | μ_w, σ_w) of thesis §4.4.2.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GeometryPrior {
    /// Mean offset, metres.
    pub mean_offset_m: f64,
    /// Offset standard deviation, metres.
    pub sigma_offset_m: f64,
    /// Mean of log width (width in metres).
    pub mean_log_width: f64,
    /// Standard deviation of log width.
    pub sigma_log_width: f64,
}

impl GeometryPrior {
    /// Maximum-likelihood fit on training geometries (offset, width); floors keep it proper.
    pub fn fit(geometries: &[(f64, f64)]) -> GeometryPrior {
        let n = geometries.len().max(1) as f64;
        let md = geometries.iter().map(|g| g.0).sum::<f64>() / n;
        let mw = geometries.iter().map(|g| g.1.max(0.1).ln()).sum::<f64>() / n;
        let sd = (geometries.iter().map(|g| (g.0 - md).powi(2)).sum::<f64>() / n).sqrt();
        let sw = (geometries
            .iter()
            .map(|g| (g.1.max(0.1).ln() - mw).powi(2))
            .sum::<f64>()
            / n)
            .sqrt();
        GeometryPrior {
            mean_offset_m: md,
            sigma_offset_m: sd.max(0.2),
            mean_log_width: mw,
            sigma_log_width: sw.max(0.05),
        }
    }

    /// A flat prior (used for the fit on true labels).
    pub fn flat() -> GeometryPrior {
        GeometryPrior {
            mean_offset_m: 0.0,
            sigma_offset_m: f64::INFINITY,
            mean_log_width: 0.0,
            sigma_log_width: f64::INFINITY,
        }
    }

    /// log P(θ) up to a constant.
    pub fn log_density(&self, offset_m: f64, width_m: f64) -> f64 {
        let zd = (offset_m - self.mean_offset_m) / self.sigma_offset_m;
        let zw = (width_m.max(1e-6).ln() - self.mean_log_width) / self.sigma_log_width;
        -0.5 * (zd * zd + zw * zw)
    }
}

/// log P(θ | Z) up to a constant for every θ = `a ..= b` of one segment (eq. 4.2).
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentPotential {
    /// Columns N.
    pub cols: usize,
    /// Row-major `N × N` table indexed `a·N + b`; invalid geometries are −∞.
    pub log: Vec<f64>,
}

impl SegmentPotential {
    /// The value of θ = `a ..= b`.
    pub fn at(&self, a: usize, b: usize) -> f64 {
        self.log[a * self.cols + b]
    }

    /// The best θ of this potential alone (ties: smallest index).
    pub fn argmax(&self) -> (usize, usize) {
        let mut best = (f64::NEG_INFINITY, 0);
        for (k, &v) in self.log.iter().enumerate() {
            if v > best.0 {
                best = (v, k);
            }
        }
        (best.1 / self.cols.max(1), best.1 % self.cols.max(1))
    }
}

/// The table of eq. 4.4 for all θ, plus the prior: O(N²) from the column counts.
pub fn segment_potential(
    counts: &ColumnCounts,
    confusion_log: &[[f64; 2]; 2],
    prior: &GeometryPrior,
    grid: &ThetaGrid,
) -> SegmentPotential {
    let n = grid.cols;
    let c = confusion_log;
    // Base: every column non-street; prefix[j] = gain of turning columns < j into street.
    let mut base = 0.0;
    let mut prefix = vec![0.0; n + 1];
    for j in 0..n {
        let (o, z) = (
            f64::from(counts.ones.get(j).copied().unwrap_or(0)),
            f64::from(counts.zeros.get(j).copied().unwrap_or(0)),
        );
        base += o * c[0][1] + z * c[0][0];
        prefix[j + 1] = prefix[j] + o * (c[1][1] - c[0][1]) + z * (c[1][0] - c[0][0]);
    }
    let mut log = prior_table(prior, grid);
    for a in 0..n {
        for b in a..n {
            if !grid.valid(a, b) {
                break;
            }
            log[a * n + b] += base + prefix[b + 1] - prefix[a];
        }
    }
    SegmentPotential { cols: n, log }
}

/// Tempered, robust segment likelihood: `max(ℓ(θ)/τ − max_θ ℓ/τ, −floor)`.
///
/// Eq. 4.4 multiplies thousands of bins as if their labels were independent given θ; the
/// classifier's errors are spatially correlated (a whole setts street or a sidewalk paved
/// like the square next to it is mislabelled together), so the product is far too peaked.
/// Dividing the log-likelihood by τ (≈ bins per independent error) tempers it; the floor is
/// the max-approximation of a mixture with a "classifier failed on this segment" component
/// whose likelihood does not depend on θ, so no geometry is more than `floor` nats worse
/// than the best and the prior and the neighbours can overrule a wrong segment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Tempering {
    /// τ: the log-likelihood is divided by it (1: eq. 4.4 as is).
    pub tau: f64,
    /// Deepest a geometry falls below the segment's best, nats (∞: no floor; JSON null).
    #[serde(with = "infinite_as_null")]
    pub floor_nats: f64,
    /// Weight of the log prior (1: eq. 4.2 as is).
    pub prior_weight: f64,
    /// Largest penalty of one intersegment coupling, nats (∞: the thesis' Gaussian; JSON
    /// null or absent).
    #[serde(default = "infinite", with = "infinite_as_null")]
    pub coupling_cap_nats: f64,
}

fn infinite() -> f64 {
    f64::INFINITY
}

/// JSON has no ∞: +∞ is written as null and null read as +∞.
mod infinite_as_null {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        if v.is_finite() {
            s.serialize_some(v)
        } else {
            s.serialize_none()
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::INFINITY))
    }
}

impl Default for Tempering {
    fn default() -> Self {
        Tempering {
            tau: 1.0,
            floor_nats: f64::INFINITY,
            prior_weight: 1.0,
            coupling_cap_nats: f64::INFINITY,
        }
    }
}

/// The segment potential from a likelihood table `ll` (from [`segment_potential`] with a flat
/// prior): tempered and floored as `t` says, plus the weighted prior.
pub fn tempered_potential(
    ll: &SegmentPotential,
    t: &Tempering,
    prior: &GeometryPrior,
    grid: &ThetaGrid,
) -> SegmentPotential {
    tempered_with_prior(ll, t, &prior_table(prior, grid))
}

/// log P(θ) for every θ = `a ..= b` (row-major `N × N`, invalid geometries −∞).
pub fn prior_table(prior: &GeometryPrior, grid: &ThetaGrid) -> Vec<f64> {
    let n = grid.cols;
    let mut log = vec![f64::NEG_INFINITY; n * n];
    for a in 0..n {
        for b in a..n {
            if !grid.valid(a, b) {
                break;
            }
            let (d, w) = grid.geometry(a, b);
            log[a * n + b] = prior.log_density(d, w);
        }
    }
    log
}

/// [`tempered_potential`] with the prior as a [`prior_table`].
pub fn tempered_with_prior(
    ll: &SegmentPotential,
    t: &Tempering,
    prior: &[f64],
) -> SegmentPotential {
    let top = ll.log.iter().copied().fold(f64::NEG_INFINITY, f64::max) / t.tau;
    let log = ll
        .log
        .iter()
        .zip(prior)
        .map(|(&v, &p)| {
            if v == f64::NEG_INFINITY || p == f64::NEG_INFINITY {
                f64::NEG_INFINITY
            } else {
                (v / t.tau - top).max(-t.floor_nats) + t.prior_weight * p
            }
        })
        .collect();
    SegmentPotential { cols: ll.cols, log }
}

/// Standard deviation of the width, metres, under the distribution ∝ exp(`p`) over its valid
/// geometries: the segment's posterior spread (0 when one geometry holds all the mass).
pub fn width_spread_m(p: &SegmentPotential, grid: &ThetaGrid) -> f64 {
    let top = p.log.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !top.is_finite() {
        return f64::INFINITY;
    }
    let n = p.cols;
    let (mut z, mut m1, mut m2) = (0.0f64, 0.0f64, 0.0f64);
    for a in 0..n {
        for b in a..n {
            let v = p.log[a * n + b];
            if v == f64::NEG_INFINITY {
                continue;
            }
            let weight = (v - top).exp();
            let w = grid.geometry(a, b).1;
            z += weight;
            m1 += weight * w;
            m2 += weight * w * w;
        }
    }
    let mean = m1 / z;
    (m2 / z - mean * mean).max(0.0).sqrt()
}

/// The same value as [`segment_potential`] for one θ by direct summation over the bins.
pub fn direct_log_potential(
    labels: &[Option<bool>],
    confusion_log: &[[f64; 2]; 2],
    prior: &GeometryPrior,
    grid: &ThetaGrid,
    a: usize,
    b: usize,
) -> f64 {
    let n = grid.cols;
    let mut s = 0.0;
    for row in labels.chunks_exact(n) {
        for (j, l) in row.iter().enumerate() {
            if let Some(z) = l {
                let x = (a..=b).contains(&j);
                s += confusion_log[usize::from(x)][usize::from(*z)];
            }
        }
    }
    let (d, w) = grid.geometry(a, b);
    s + prior.log_density(d, w)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn geometry_and_columns_round_trip() {
        let g = ThetaGrid {
            cols: 200,
            bin_m: 0.2,
            max_width_cols: 150,
        };
        let (d, w) = g.geometry(90, 109);
        assert!((d - 0.0).abs() < 1e-9 && (w - 4.0).abs() < 1e-9);
        assert_eq!(g.columns_of(d, w), (90, 109));
        let (d, w) = g.geometry(10, 60);
        assert_eq!(g.columns_of(d, w), (10, 60));
    }

    #[test]
    fn width_spread_is_the_standard_deviation_of_the_normalised_potential() {
        let g = ThetaGrid {
            cols: 20,
            bin_m: 0.5,
            max_width_cols: 20,
        };
        let n = g.cols;
        // Brute force: two geometries of widths 2 m and 4 m with probabilities 1/4 and 3/4.
        let mut log = vec![f64::NEG_INFINITY; n * n];
        log[5 * n + 8] = (0.25f64).ln() + 3.0;
        log[4 * n + 11] = (0.75f64).ln() + 3.0;
        let p = SegmentPotential { cols: n, log };
        let (w1, w2) = (g.geometry(5, 8).1, g.geometry(4, 11).1);
        assert!((w1 - 2.0).abs() < 1e-12 && (w2 - 4.0).abs() < 1e-12);
        let mean = 0.25 * w1 + 0.75 * w2;
        let var = 0.25 * (w1 - mean).powi(2) + 0.75 * (w2 - mean).powi(2);
        assert!((width_spread_m(&p, &g) - var.sqrt()).abs() < 1e-12);
        // One geometry: no spread; nothing valid: infinitely unsure.
        let mut one = vec![f64::NEG_INFINITY; n * n];
        one[2 * n + 9] = -7.0;
        assert_eq!(
            width_spread_m(&SegmentPotential { cols: n, log: one }, &g),
            0.0
        );
        let none = vec![f64::NEG_INFINITY; n * n];
        assert!(width_spread_m(&SegmentPotential { cols: n, log: none }, &g).is_infinite());
    }

    #[test]
    fn confusion_log_likelihood_rows_sum_to_one() {
        let c = Confusion::from_pairs(
            &[true, true, false, false, true],
            &[true, false, false, false, true],
        );
        assert_eq!(c.counts, [[2, 0], [1, 2]]);
        for row in c.log_likelihood() {
            assert!((row[0].exp() + row[1].exp() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn tempering_round_trips_through_json_with_infinities() {
        for t in [
            Tempering::default(),
            Tempering {
                tau: 32.0,
                floor_nats: 8.0,
                prior_weight: 4.0,
                coupling_cap_nats: 10.0,
            },
        ] {
            let json = serde_json::to_string(&t).unwrap();
            assert_eq!(serde_json::from_str::<Tempering>(&json).unwrap(), t);
        }
        let old: Tempering =
            serde_json::from_str(r#"{"tau": 2.0, "floor_nats": null, "prior_weight": 1.0}"#)
                .unwrap();
        assert_eq!(old.coupling_cap_nats, f64::INFINITY);
    }

    #[test]
    fn tempering_one_without_floor_is_eq_4_4() {
        let grid = ThetaGrid {
            cols: 9,
            bin_m: 0.2,
            max_width_cols: 8,
        };
        let labels: Vec<Option<bool>> = (0..27)
            .map(|k| match k % 4 {
                0 => None,
                1 => Some(false),
                _ => Some(k % 9 > 2),
            })
            .collect();
        let conf = Confusion {
            counts: [[30, 5], [4, 40]],
        }
        .log_likelihood();
        let prior = GeometryPrior {
            mean_offset_m: 0.1,
            sigma_offset_m: 0.5,
            mean_log_width: 0.0,
            sigma_log_width: 0.7,
        };
        let counts = ColumnCounts::from_grid(&labels, grid.cols);
        let ll = segment_potential(&counts, &conf, &GeometryPrior::flat(), &grid);
        let plain = segment_potential(&counts, &conf, &prior, &grid);
        let top = ll.log.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let t1 = tempered_potential(&ll, &Tempering::default(), &prior, &grid);
        let floored = Tempering {
            tau: 2.0,
            floor_nats: 1.5,
            prior_weight: 1.0,
            coupling_cap_nats: f64::INFINITY,
        };
        let t2 = tempered_potential(&ll, &floored, &GeometryPrior::flat(), &grid);
        for a in 0..grid.cols {
            for b in 0..grid.cols {
                if grid.valid(a, b) {
                    assert!((t1.at(a, b) - (plain.at(a, b) - top)).abs() < 1e-9);
                    let want = ((ll.at(a, b) - top) / 2.0).max(-1.5);
                    assert!((t2.at(a, b) - want).abs() < 1e-9);
                } else {
                    assert_eq!(t1.at(a, b), f64::NEG_INFINITY);
                }
            }
        }
    }

    proptest! {
        #[test]
        fn dp_equals_direct_summation(
            rows in 1usize..6,
            cols in 1usize..12,
            cells in proptest::collection::vec(0u8..3, 72),
            c in proptest::collection::vec(1u64..50, 4),
            prior_on in any::<bool>(),
        ) {
            let labels: Vec<Option<bool>> = (0..rows * cols)
                .map(|k| match cells[k % cells.len()] { 0 => None, 1 => Some(false), _ => Some(true) })
                .collect();
            let conf = Confusion { counts: [[c[0], c[1]], [c[2], c[3]]] }.log_likelihood();
            let grid = ThetaGrid { cols, bin_m: 0.2, max_width_cols: cols.max(2) - 1 };
            let prior = if prior_on {
                GeometryPrior { mean_offset_m: 0.1, sigma_offset_m: 0.5, mean_log_width: 0.0, sigma_log_width: 0.7 }
            } else { GeometryPrior::flat() };
            let pot = segment_potential(&ColumnCounts::from_grid(&labels, cols), &conf, &prior, &grid);
            for a in 0..cols {
                for b in 0..cols {
                    if grid.valid(a, b) {
                        let direct = direct_log_potential(&labels, &conf, &prior, &grid, a, b);
                        prop_assert!((pot.at(a, b) - direct).abs() < 1e-9 * (1.0 + direct.abs()));
                    } else {
                        prop_assert_eq!(pot.at(a, b), f64::NEG_INFINITY);
                    }
                }
            }
        }
    }
}
