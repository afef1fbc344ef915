//! Visibility-aware chamfer costs per candidate and the ranking (thesis §5.3.3).
//!
//! With Û the scan segments moved to the candidate pose and V_e the visible map edges:
//! forward d_f = mean over samples û of min_v (|û − v| + λ·Δφ) (eq. 5.4, directional form),
//! reverse d_r = the same from samples of V_e to Û (eq. 5.5), symmetric d_s = (d_f + d_r)/2.
//! λ = 0 gives the plain equations. Each point term is truncated at τ (∞ gives the plain
//! equations), so clutter and map errors cost at most τ. Samples are spaced evenly along the
//! segments, so the means are length-weighted. Cost O(samples × segments) per candidate.

use crate::candidates::sample_segment_points;
use crate::{orientation_diff, Segment};
use serde::Serialize;

/// Options of the per-candidate costs.
#[derive(Debug, Clone, PartialEq)]
pub struct CostOptions {
    /// Orientation penalty λ, metres per radian.
    pub lambda_m_per_rad: f64,
    /// Truncation τ of each point term, metres.
    pub truncation_m: f64,
    /// Sample spacing along segments, metres.
    pub sample_m: f64,
}

impl Default for CostOptions {
    fn default() -> Self {
        CostOptions {
            lambda_m_per_rad: 2.0,
            truncation_m: 3.0,
            sample_m: 0.5,
        }
    }
}

/// Which cost ranks the candidates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum CostKind {
    /// d_DCM of the search (eq. 5.3).
    Dcm,
    /// Forward d_f (eq. 5.4).
    Forward,
    /// Reverse d_r (eq. 5.5).
    Reverse,
    /// Symmetric d_s.
    Symmetric,
}

impl CostKind {
    /// Every cost kind.
    pub const ALL: [CostKind; 4] = [
        CostKind::Dcm,
        CostKind::Forward,
        CostKind::Reverse,
        CostKind::Symmetric,
    ];

    /// The lowercase name (`dcm`, `forward`, `reverse`, `symmetric`).
    pub fn name(self) -> &'static str {
        match self {
            CostKind::Dcm => "dcm",
            CostKind::Forward => "forward",
            CostKind::Reverse => "reverse",
            CostKind::Symmetric => "symmetric",
        }
    }
}

/// Every cost of one candidate, metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Costs {
    /// d_DCM of the search.
    pub dcm: f64,
    /// Forward d_f.
    pub forward: f64,
    /// Reverse d_r.
    pub reverse: f64,
    /// Symmetric d_s.
    pub symmetric: f64,
}

impl Costs {
    /// The cost of one kind.
    pub fn get(&self, kind: CostKind) -> f64 {
        match kind {
            CostKind::Dcm => self.dcm,
            CostKind::Forward => self.forward,
            CostKind::Reverse => self.reverse,
            CostKind::Symmetric => self.symmetric,
        }
    }
}

/// Mean over the samples of `from` of the truncated directional distance to `to`; τ when
/// `to` is empty, `None` when `from` has no length.
pub fn directed_cost(from: &[Segment], to: &[Segment], options: &CostOptions) -> Option<f64> {
    let samples = sample_segment_points(from, options.sample_m);
    if samples.is_empty() {
        return None;
    }
    let to_o: Vec<(Segment, f64)> = to.iter().map(|s| (*s, s.orientation_rad())).collect();
    let tau = options.truncation_m;
    let mut sum = 0.0;
    for (p, o) in &samples {
        let mut best = tau;
        for (s, so) in &to_o {
            let pen = options.lambda_m_per_rad * orientation_diff(*o, *so);
            if pen >= best {
                continue;
            }
            let d = s.distance_to(*p) + pen;
            if d < best {
                best = d;
            }
        }
        sum += best;
    }
    Some(sum / samples.len() as f64)
}

/// Forward, reverse and symmetric costs of scan segments already in the map frame against the
/// visible map edges; `dcm` is passed through.
pub fn costs(
    scan_in_map: &[Segment],
    visible: &[Segment],
    dcm: f64,
    options: &CostOptions,
) -> Costs {
    let tau = options.truncation_m;
    let forward = directed_cost(scan_in_map, visible, options).unwrap_or(tau);
    let reverse = directed_cost(visible, scan_in_map, options).unwrap_or(tau);
    Costs {
        dcm,
        forward,
        reverse,
        symmetric: 0.5 * (forward + reverse),
    }
}

/// Ranks by one cost (ties: d_DCM, then position), best first; returns the order.
pub fn rank_order(costs: &[Costs], poses: &[crate::Pose2], kind: CostKind) -> Vec<usize> {
    let mut order: Vec<usize> = (0..costs.len()).collect();
    order.sort_by(|&a, &b| {
        costs[a]
            .get(kind)
            .total_cmp(&costs[b].get(kind))
            .then(costs[a].dcm.total_cmp(&costs[b].dcm))
            .then(poses[a].x.total_cmp(&poses[b].x))
            .then(poses[a].y.total_cmp(&poses[b].y))
            .then(poses[a].yaw_rad.total_cmp(&poses[b].yaw_rad))
    });
    order
}

/// Below this [`confidence`] a scan's answer is called ambiguous in the text output: another
/// place fits within 2 % of the best cost (none of the 7 such answers on the simulated
/// Helsinki HDL-64 scans is right, 1 of 12 on the real KITTI-360 car scans; README).
pub const AMBIGUOUS_CONFIDENCE: f64 = 0.02;

/// Confidence of the best of ranked costs: (c₂ − c₁)/c₂ with c₂ the best cost of a pose
/// distinct from the best (farther than `distinct_m` or `distinct_rad`); 1 when none, in [0, 1].
pub fn confidence(
    ranked_costs: &[f64],
    ranked_poses: &[crate::Pose2],
    distinct_m: f64,
    distinct_rad: f64,
) -> f64 {
    let (Some(&c1), Some(p1)) = (ranked_costs.first(), ranked_poses.first()) else {
        return 0.0;
    };
    let second = ranked_costs
        .iter()
        .zip(ranked_poses)
        .skip(1)
        .find(|(_, p)| p.distance_to(p1) > distinct_m || p.yaw_error_to(p1) > distinct_rad);
    match second {
        None => 1.0,
        Some((&c2, _)) if c2 > 0.0 => ((c2 - c1) / c2).clamp(0.0, 1.0),
        Some(_) => 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_segments(rng: &mut ChaCha8Rng, n: usize) -> Vec<Segment> {
        (0..n)
            .map(|_| {
                let a = [rng.gen_range(-20.0..20.0), rng.gen_range(-20.0..20.0)];
                let ang: f64 = rng.gen_range(0.0..std::f64::consts::TAU);
                let l = rng.gen_range(1.0..10.0);
                Segment::new(a, [a[0] + l * ang.cos(), a[1] + l * ang.sin()])
            })
            .collect()
    }

    /// Eq. 5.3 with both edge maps as dense point sets (step `h`), no truncation.
    fn direct_dcm(u: &[Segment], v: &[Segment], lambda: f64, h: f64) -> f64 {
        let pts = |segs: &[Segment], step: f64| -> Vec<([f64; 2], f64)> {
            segs.iter()
                .flat_map(|s| {
                    let n = ((s.length() / step).round() as usize).max(1);
                    (0..n).map(move |k| {
                        let t = (k as f64 + 0.5) / n as f64;
                        (
                            [
                                s.a[0] + t * (s.b[0] - s.a[0]),
                                s.a[1] + t * (s.b[1] - s.a[1]),
                            ],
                            s.orientation_rad(),
                        )
                    })
                })
                .collect()
        };
        let us = pts(u, 0.5);
        let vs = pts(v, h);
        let total: f64 = us
            .iter()
            .map(|(p, o)| {
                vs.iter()
                    .map(|(q, qo)| {
                        (p[0] - q[0]).hypot(p[1] - q[1]) + lambda * orientation_diff(*o, *qo)
                    })
                    .fold(f64::INFINITY, f64::min)
            })
            .sum();
        total / us.len() as f64
    }

    #[test]
    fn costs_match_direct_implementations_of_the_equations() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let h = 0.01;
        for _ in 0..10 {
            let scan = random_segments(&mut rng, 6);
            let visible = random_segments(&mut rng, 8);
            for lambda in [0.0, 1.5] {
                let o = CostOptions {
                    lambda_m_per_rad: lambda,
                    truncation_m: f64::INFINITY,
                    sample_m: 0.5,
                };
                let c = costs(&scan, &visible, 0.0, &o);
                // d_CM (5.2) / d_DCM (5.3) against V_e is d_f (5.4); d_r (5.5) swaps the sets.
                let f = direct_dcm(&scan, &visible, lambda, h);
                let r = direct_dcm(&visible, &scan, lambda, h);
                assert!((c.forward - f).abs() <= h, "forward {} vs {f}", c.forward);
                assert!((c.reverse - r).abs() <= h, "reverse {} vs {r}", c.reverse);
                assert!((c.symmetric - 0.5 * (f + r)).abs() <= h);
            }
        }
    }

    #[test]
    fn truncation_caps_each_term() {
        let scan = vec![Segment::new([0.0, 0.0], [10.0, 0.0])];
        let far = vec![Segment::new([0.0, 100.0], [10.0, 100.0])];
        let c = costs(&scan, &far, 0.0, &CostOptions::default());
        assert!((c.forward - 3.0).abs() < 1e-12 && (c.reverse - 3.0).abs() < 1e-12);
        let none = costs(&scan, &[], 0.0, &CostOptions::default());
        assert!((none.forward - 3.0).abs() < 1e-12 && (none.reverse - 3.0).abs() < 1e-12);
    }

    #[test]
    fn confidence_margin() {
        let p = |x: f64| crate::Pose2 {
            x,
            y: 0.0,
            yaw_rad: 0.0,
        };
        let c = confidence(&[1.0, 1.1, 2.0], &[p(0.0), p(1.0), p(10.0)], 4.0, 0.2);
        assert!((c - 0.5).abs() < 1e-12);
        assert_eq!(confidence(&[1.0], &[p(0.0)], 4.0, 0.2), 1.0);
    }
}
