//! Pose-graph refinement of a smoothed track's answers: the poses of a run of linked scans are
//! moved together to fit each scan's walls (point-to-line residuals against the map edges
//! visible from it, [`crate::refine`]) and the odometry steps between them at once.
//!
//! A chain picks one state per scan, and a state that was carried by the odometry through
//! scans whose walls do not pin it along the street keeps the drift of the whole stretch it
//! coasted. Here every scan's walls inform only the directions they constrain (their normals),
//! and the odometry fills in the rest from both sides, so the drift is shared between the
//! scans that anchor a stretch instead of piling up from one of them. Gauss–Newton on
//! (x, y, yaw) per scan; a run's system is block tridiagonal (each scan is tied to the next
//! only), solved by block elimination in O(n) for n scans. Walls count as independent
//! measurements every [`GraphOptions::wall_correlation_m`] of their length (a map error
//! shifts a whole wall, not its samples one by one); odometry spreads grow with the step as
//! the track's drift assumptions do ([`crate::ODOMETRY_SCALE_DRIFT`]).

use crate::candidates::sample_segment_points;
use crate::refine::{normal_equations, RefineOptions};
use crate::{Pose2, Segment};
use nalgebra::{Matrix3, Vector3};
use std::f64::consts::{PI, TAU};

/// Options of the pose-graph refinement.
#[derive(Debug, Clone, PartialEq)]
pub struct GraphOptions {
    /// Gauss–Newton iterations.
    pub iterations: usize,
    /// Spread of a wall's offset between scan and map, metres.
    pub wall_sigma_m: f64,
    /// Wall length over which that offset is one measurement, metres.
    pub wall_correlation_m: f64,
    /// Odometry scale drift (share of the step length).
    pub odometry_scale: f64,
    /// Odometry heading drift, radians per metre of the step.
    pub odometry_yaw_rad_per_m: f64,
    /// Smallest odometry position spread, metres.
    pub odometry_floor_m: f64,
    /// Smallest odometry heading spread, radians.
    pub odometry_floor_rad: f64,
    /// A pose moved farther than this keeps its start, metres.
    pub max_shift_m: f64,
}

impl Default for GraphOptions {
    fn default() -> Self {
        GraphOptions {
            iterations: 10,
            wall_sigma_m: 0.5,
            wall_correlation_m: 5.0,
            odometry_scale: crate::ODOMETRY_SCALE_DRIFT,
            odometry_yaw_rad_per_m: crate::ODOMETRY_YAW_DRIFT_DEG_PER_50M.to_radians() / 50.0,
            odometry_floor_m: 0.2,
            odometry_floor_rad: 0.5f64.to_radians(),
            max_shift_m: 5.0,
        }
    }
}

/// The refined poses of a run of scans linked by odometry: `scans[i]` (sensor frame) seen
/// from `poses[i]` against `edges[i]` (the map edges visible there), `steps[i]` the odometry
/// step from scan i to scan i + 1 (in scan i's frame; one fewer than the scans).
pub fn refine_run(
    scans: &[&[Segment]],
    edges: &[Vec<Segment>],
    poses: &[Pose2],
    steps: &[Pose2],
    options: &GraphOptions,
    refine: &RefineOptions,
) -> Vec<Pose2> {
    let n = poses.len();
    if n == 0 || scans.len() != n || edges.len() != n || steps.len() + 1 != n {
        return poses.to_vec();
    }
    let samples: Vec<Vec<([f64; 2], f64)>> = scans
        .iter()
        .map(|s| sample_segment_points(s, refine.sample_m))
        .collect();
    let edge_o: Vec<Vec<(Segment, f64)>> = edges
        .iter()
        .map(|es| es.iter().map(|e| (*e, e.orientation_rad())).collect())
        .collect();
    let wall_w = (refine.sample_m / options.wall_correlation_m.max(refine.sample_m))
        / options.wall_sigma_m.powi(2);
    let mut x: Vec<Pose2> = poses.to_vec();
    let it_n = options.iterations.max(1);
    for it in 0..it_n {
        let radius = refine.radius_at(it, it_n);
        let mut d: Vec<Matrix3<f64>> = vec![Matrix3::zeros(); n];
        let mut b: Vec<Matrix3<f64>> = vec![Matrix3::zeros(); n.saturating_sub(1)];
        let mut g: Vec<Vector3<f64>> = vec![Vector3::zeros(); n];
        for i in 0..n {
            let (h, gi, used) = normal_equations(&samples[i], &edge_o[i], &x[i], radius, refine);
            if used >= 3 {
                d[i] += wall_w * h;
                g[i] += wall_w * gi;
            }
        }
        for (i, m) in steps.iter().enumerate() {
            let (a, c) = (x[i], x[i + 1]);
            let (s, co) = a.yaw_rad.sin_cos();
            let (dx, dy) = (c.x - a.x, c.y - a.y);
            // The step predicted by the two poses, in scan i's frame, against the odometry's.
            let pred = [co * dx + s * dy, -s * dx + co * dy];
            let e = Vector3::new(
                pred[0] - m.x,
                pred[1] - m.y,
                (c.yaw_rad - a.yaw_rad - m.yaw_rad + PI).rem_euclid(TAU) - PI,
            );
            let len = m.x.hypot(m.y);
            let sd_xy = options.odometry_floor_m
                + options.odometry_scale * len
                + 0.5 * len * options.odometry_yaw_rad_per_m * len;
            let sd_yaw = options.odometry_floor_rad + options.odometry_yaw_rad_per_m * len;
            let w = Matrix3::from_diagonal(&Vector3::new(
                1.0 / (sd_xy * sd_xy),
                1.0 / (sd_xy * sd_xy),
                1.0 / (sd_yaw * sd_yaw),
            ));
            let ji = Matrix3::new(
                -co,
                -s,
                -s * dx + co * dy,
                s,
                -co,
                -co * dx - s * dy,
                0.0,
                0.0,
                -1.0,
            );
            let jj = Matrix3::new(co, s, 0.0, -s, co, 0.0, 0.0, 0.0, 1.0);
            d[i] += ji.transpose() * w * ji;
            d[i + 1] += jj.transpose() * w * jj;
            b[i] += ji.transpose() * w * jj;
            g[i] += ji.transpose() * w * e;
            g[i + 1] += jj.transpose() * w * e;
        }
        let Some(delta) = solve_block_tridiagonal(d, &b, g) else {
            break;
        };
        let mut largest = 0.0f64;
        for (p, dp) in x.iter_mut().zip(&delta) {
            p.x += dp[0];
            p.y += dp[1];
            p.yaw_rad += dp[2];
            largest = largest.max(dp.norm());
        }
        if largest < 1e-5 {
            break;
        }
    }
    x.iter()
        .zip(poses)
        .map(|(r, p)| {
            if r.x.is_finite()
                && r.y.is_finite()
                && r.yaw_rad.is_finite()
                && r.distance_to(p) <= options.max_shift_m
            {
                Pose2 {
                    yaw_rad: r.yaw_rad.rem_euclid(TAU),
                    ..*r
                }
            } else {
                *p
            }
        })
        .collect()
}

/// Solves H δ = −g for a symmetric block-tridiagonal H with diagonal blocks `d` and upper
/// blocks `b` (H[i][i + 1] = b[i], H[i + 1][i] = b[i]ᵀ), with a small damping on the diagonal;
/// `None` when a pivot block is singular.
fn solve_block_tridiagonal(
    mut d: Vec<Matrix3<f64>>,
    b: &[Matrix3<f64>],
    g: Vec<Vector3<f64>>,
) -> Option<Vec<Vector3<f64>>> {
    let n = d.len();
    let mut r: Vec<Vector3<f64>> = g.into_iter().map(|v| -v).collect();
    let mut inv: Vec<Matrix3<f64>> = Vec::with_capacity(n);
    for i in 0..n {
        let damping = 1e-6 * (d[i].trace() + 1.0);
        d[i] += Matrix3::identity() * damping;
        if i > 0 {
            let l = b[i - 1].transpose() * inv[i - 1];
            let previous = r[i - 1];
            d[i] -= l * b[i - 1];
            r[i] -= l * previous;
        }
        inv.push(d[i].try_inverse()?);
    }
    let mut delta = vec![Vector3::zeros(); n];
    for i in (0..n).rev() {
        let rhs = if i + 1 < n {
            r[i] - b[i] * delta[i + 1]
        } else {
            r[i]
        };
        delta[i] = inv[i] * rhs;
    }
    Some(delta)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    #[test]
    fn block_elimination_equals_a_dense_solve() {
        let n = 5;
        let m =
            |k: usize| Matrix3::from_fn(|r, c| ((r * 7 + c * 3 + k * 11) % 13) as f64 / 13.0 - 0.4);
        let b: Vec<Matrix3<f64>> = (0..n - 1).map(m).collect();
        let d: Vec<Matrix3<f64>> = (0..n)
            .map(|k| {
                let a = m(k + 20);
                a * a.transpose() + Matrix3::identity() * 4.0
            })
            .collect();
        let g: Vec<Vector3<f64>> = (0..n)
            .map(|k| Vector3::new(k as f64, 1.0 - k as f64, 0.5))
            .collect();
        let got = solve_block_tridiagonal(d.clone(), &b, g.clone()).unwrap();
        let mut h = DMatrix::<f64>::zeros(3 * n, 3 * n);
        let mut rhs = nalgebra::DVector::<f64>::zeros(3 * n);
        for i in 0..n {
            let di = d[i] + Matrix3::identity() * (1e-6 * (d[i].trace() + 1.0));
            h.fixed_view_mut::<3, 3>(3 * i, 3 * i).copy_from(&di);
            rhs.fixed_rows_mut::<3>(3 * i).copy_from(&(-g[i]));
            if i + 1 < n {
                h.fixed_view_mut::<3, 3>(3 * i, 3 * i + 3).copy_from(&b[i]);
                h.fixed_view_mut::<3, 3>(3 * i + 3, 3 * i)
                    .copy_from(&b[i].transpose());
            }
        }
        let want = h.lu().solve(&rhs).unwrap();
        for i in 0..n {
            for k in 0..3 {
                assert!((got[i][k] - want[3 * i + k]).abs() < 1e-9, "{i} {k}");
            }
        }
    }

    /// A straight street of two long parallel walls (y = ±8) with a cross wall at x = 0 seen
    /// by the first scan only: five scans 20 m apart, the first anchored by the cross wall,
    /// the others seeing the parallel walls only. Started 3 m along the street off the truth
    /// (as a chain that coasted), the scans that see no cross wall slide back along the street
    /// by the odometry from the anchored one.
    #[test]
    fn odometry_carries_the_anchor_along_a_street_the_walls_do_not_pin() {
        let map: Vec<Segment> = vec![
            Segment::new([-5.0, 8.0], [200.0, 8.0]),
            Segment::new([-5.0, -8.0], [200.0, -8.0]),
            Segment::new([-5.0, -8.0], [-5.0, 8.0]),
        ];
        let truth: Vec<Pose2> = (0..5)
            .map(|i| Pose2 {
                x: 10.0 + 20.0 * i as f64,
                y: 0.0,
                yaw_rad: 0.0,
            })
            .collect();
        let to_scan = |t: &Pose2, s: &Segment| {
            Segment::new([s.a[0] - t.x, s.a[1] - t.y], [s.b[0] - t.x, s.b[1] - t.y])
        };
        let owned: Vec<Vec<Segment>> = truth
            .iter()
            .enumerate()
            .map(|(i, t)| {
                // 20 m of each parallel wall around the sensor; the cross wall for scan 0.
                let mut v = vec![
                    to_scan(t, &Segment::new([t.x - 10.0, 8.0], [t.x + 10.0, 8.0])),
                    to_scan(t, &Segment::new([t.x - 10.0, -8.0], [t.x + 10.0, -8.0])),
                ];
                if i == 0 {
                    v.push(to_scan(t, &map[2]));
                }
                v
            })
            .collect();
        let scans: Vec<&[Segment]> = owned.iter().map(|v| v.as_slice()).collect();
        let edges = vec![map.clone(); 5];
        let steps: Vec<Pose2> = (0..4)
            .map(|_| Pose2 {
                x: 20.0,
                y: 0.0,
                yaw_rad: 0.0,
            })
            .collect();
        let start: Vec<Pose2> = truth
            .iter()
            .enumerate()
            .map(|(i, t)| Pose2 {
                x: t.x + if i == 0 { 0.3 } else { 3.0 },
                ..*t
            })
            .collect();
        let got = refine_run(
            &scans,
            &edges,
            &start,
            &steps,
            &GraphOptions::default(),
            &RefineOptions::default(),
        );
        for (g, t) in got.iter().zip(&truth) {
            assert!(g.distance_to(t) < 0.3, "{got:?}");
        }
        // Without the odometry's pull (each scan alone), the along-street error stays.
        let alone = refine_run(
            &scans[1..2],
            &edges[1..2],
            &start[1..2],
            &[],
            &GraphOptions::default(),
            &RefineOptions::default(),
        );
        assert!(alone[0].distance_to(&truth[1]) > 2.5, "{alone:?}");
    }
}
