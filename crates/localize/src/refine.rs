//! Continuous 2-D refinement of a candidate: point-to-line alignment of the scan segments'
//! samples to the visible map edges (Gauss–Newton on (x, y, yaw) with Huber weights and a
//! shrinking correspondence radius). Cost O(iterations × samples × edges).

use crate::candidates::sample_segment_points;
use crate::{orientation_diff, Pose2, Segment};
use nalgebra::{Matrix3, Vector3};

/// Options of the refinement.
#[derive(Debug, Clone, PartialEq)]
pub struct RefineOptions {
    /// Gauss–Newton iterations.
    pub iterations: usize,
    /// Correspondence radius at the first iteration, metres.
    pub start_distance_m: f64,
    /// Correspondence radius at the last iteration, metres.
    pub end_distance_m: f64,
    /// Largest orientation difference of a correspondence, radians.
    pub max_angle_rad: f64,
    /// Sample spacing, metres.
    pub sample_m: f64,
    /// Huber threshold, metres.
    pub huber_m: f64,
    /// Largest total move accepted, metres (else the start pose is kept).
    pub max_shift_m: f64,
}

impl Default for RefineOptions {
    fn default() -> Self {
        RefineOptions {
            iterations: 12,
            start_distance_m: 2.0,
            end_distance_m: 0.6,
            max_angle_rad: 20f64.to_radians(),
            sample_m: 0.5,
            huber_m: 0.3,
            max_shift_m: 3.0,
        }
    }
}

impl RefineOptions {
    /// The correspondence radius at iteration `it` of `iterations`: from the start distance
    /// to the end distance linearly.
    pub(crate) fn radius_at(&self, it: usize, iterations: usize) -> f64 {
        let f = if iterations > 1 {
            it as f64 / (iterations - 1) as f64
        } else {
            1.0
        };
        self.start_distance_m + f * (self.end_distance_m - self.start_distance_m)
    }
}

/// The Gauss–Newton normal equations (H, g) of the point-to-line residuals of `samples`
/// (sensor frame, with their orientations) at `pose` against `edges` (with theirs), each
/// sample matched to the nearest edge within `radius` and the orientation limit, Huber
/// weighted; the unknowns are (x, y, yaw) and the third value is the number of samples matched.
pub(crate) fn normal_equations(
    samples: &[([f64; 2], f64)],
    edges: &[(Segment, f64)],
    pose: &Pose2,
    radius: f64,
    options: &RefineOptions,
) -> (Matrix3<f64>, Vector3<f64>, usize) {
    let mut h = Matrix3::<f64>::zeros();
    let mut g = Vector3::<f64>::zeros();
    let mut used = 0usize;
    for (p_s, o_s) in samples {
        let p = pose.apply(*p_s);
        let o = o_s + pose.yaw_rad;
        let mut best: Option<(f64, &Segment)> = None;
        for (e, eo) in edges {
            if orientation_diff(o, *eo) > options.max_angle_rad {
                continue;
            }
            let d = e.distance_to(p);
            if d < radius && best.is_none_or(|(bd, _)| d < bd) {
                best = Some((d, e));
            }
        }
        let Some((_, e)) = best else {
            continue;
        };
        let len = e.length();
        let nrm = [-(e.b[1] - e.a[1]) / len, (e.b[0] - e.a[0]) / len];
        let r = nrm[0] * (p[0] - e.a[0]) + nrm[1] * (p[1] - e.a[1]);
        let w = if r.abs() <= options.huber_m {
            1.0
        } else {
            options.huber_m / r.abs()
        };
        let dtheta = nrm[0] * -(p[1] - pose.y) + nrm[1] * (p[0] - pose.x);
        let j = Vector3::new(nrm[0], nrm[1], dtheta);
        h += w * j * j.transpose();
        g += w * j * r;
        used += 1;
    }
    (h, g, used)
}

/// The refined pose of scan segments (sensor frame) against map edges, from `start`.
pub fn refine_pose(
    scan: &[Segment],
    edges: &[Segment],
    start: Pose2,
    options: &RefineOptions,
) -> Pose2 {
    let samples = sample_segment_points(scan, options.sample_m);
    if samples.is_empty() || edges.is_empty() {
        return start;
    }
    let edge_o: Vec<(Segment, f64)> = edges.iter().map(|e| (*e, e.orientation_rad())).collect();
    let mut pose = start;
    let n_it = options.iterations.max(1);
    for it in 0..n_it {
        let radius = options.radius_at(it, n_it);
        let (mut h, g, used) = normal_equations(&samples, &edge_o, &pose, radius, options);
        if used < 3 {
            break;
        }
        let damping = 1e-6 * (h.trace() + 1.0);
        h += Matrix3::identity() * damping;
        let Some(delta) = h.lu().solve(&(-g)) else {
            break;
        };
        pose.x += delta[0];
        pose.y += delta[1];
        pose.yaw_rad += delta[2];
        if delta.norm() < 1e-5 {
            break;
        }
    }
    if pose.distance_to(&start) > options.max_shift_m || !pose.x.is_finite() || !pose.y.is_finite()
    {
        return start;
    }
    pose.yaw_rad = pose.yaw_rad.rem_euclid(std::f64::consts::TAU);
    pose
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_small_offset_on_a_corner_scene() {
        let edges = vec![
            Segment::new([0.0, 0.0], [20.0, 0.0]),
            Segment::new([0.0, 0.0], [0.0, 15.0]),
            Segment::new([20.0, 0.0], [20.0, 8.0]),
        ];
        let truth = Pose2 {
            x: 8.0,
            y: 6.0,
            yaw_rad: 0.3,
        };
        let (s, c) = truth.yaw_rad.sin_cos();
        let to_scan = |p: [f64; 2]| {
            let (dx, dy) = (p[0] - truth.x, p[1] - truth.y);
            [c * dx + s * dy, -s * dx + c * dy]
        };
        let scan: Vec<Segment> = edges
            .iter()
            .map(|e| Segment::new(to_scan(e.a), to_scan(e.b)))
            .collect();
        let start = Pose2 {
            x: 8.4,
            y: 5.7,
            yaw_rad: 0.33,
        };
        let got = refine_pose(&scan, &edges, start, &RefineOptions::default());
        assert!(got.distance_to(&truth) < 0.02, "{got:?}");
        assert!(got.yaw_error_to(&truth) < 0.002, "{got:?}");
    }
}
