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
//! shifts a whole wall, not its samples one by one).
//!
//! The odometry's drift is mostly systematic: a wheel radius that is a little off scales
//! every step alike, a gyro bias turns every metre alike. So each run also estimates one
//! scale error and one heading bias per metre ([`GraphOptions::systematic_drift`], on by
//! default), with the track's drift assumptions as their prior spreads
//! ([`crate::ODOMETRY_SCALE_DRIFT`], [`crate::ODOMETRY_YAW_DRIFT_DEG_PER_50M`]); each step
//! then keeps only a small random spread. A stretch whose walls pin the scans in both
//! directions (a turn, cross walls at both ends) thereby calibrates the odometry for the
//! stretches whose walls do not. The two global unknowns border the block-tridiagonal
//! system; their 2 × 2 Schur complement keeps the solve O(n). Off, every step's spread grows
//! with its length as the drift assumptions do, independently of the others.

use crate::candidates::sample_segment_points;
use crate::refine::{normal_equations, RefineOptions};
use crate::{Pose2, Segment};
use nalgebra::{Matrix2, Matrix3, Matrix3x2, Vector2, Vector3};
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
    /// A pose moved farther than this keeps its start, metres (with the systematic drift
    /// estimated, plus `odometry_scale` times the run's odometry length: as far as the
    /// odometry can have drifted over it).
    pub max_shift_m: f64,
    /// Estimate the odometry's systematic drift (a scale error and a heading bias per metre,
    /// one each per run, with `odometry_scale` and `odometry_yaw_rad_per_m` as their prior
    /// spreads) beside the poses; each step then keeps only the random spreads below.
    pub systematic_drift: bool,
    /// Random odometry position spread per step beyond the floor (share of the step length),
    /// when the systematic drift is estimated.
    pub odometry_random_share: f64,
    /// Random odometry heading spread per step beyond the floor, radians per metre, when the
    /// systematic drift is estimated.
    pub odometry_random_yaw_rad_per_m: f64,
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
            systematic_drift: true,
            odometry_random_share: 0.005,
            odometry_random_yaw_rad_per_m: 0.2f64.to_radians() / 50.0,
        }
    }
}

/// The odometry's systematic drift over a run, as the graph estimated it: the odometry's
/// steps are the true ones scaled by 1 + `scale_error` and turned by `heading_bias` per metre
/// travelled (counter-clockwise positive), with their posterior standard deviations.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct OdometryDrift {
    /// Scale error of the odometry's distances (0.02: it reads 2 % long).
    pub scale_error: f64,
    /// Posterior standard deviation of the scale error.
    pub scale_error_sd: f64,
    /// Heading bias, degrees per 100 m travelled.
    pub heading_bias_deg_per_100m: f64,
    /// Posterior standard deviation of the heading bias, degrees per 100 m.
    pub heading_bias_sd_deg_per_100m: f64,
}

/// A run of consecutive scans of a track whose answers the graph refined together, and the
/// odometry drift estimated over it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct OdometryRun {
    /// Index of the run's first scan in the track.
    pub first_scan: usize,
    /// Scans in the run.
    pub scans: usize,
    /// Distance the odometry travelled over the run, metres.
    pub length_m: f64,
    /// The drift estimated over the run (`None`: not estimated).
    pub drift: Option<OdometryDrift>,
}

/// The refined poses of a run of scans linked by odometry: `scans[i]` (sensor frame) seen
/// from `poses[i]` against `edges[i]` (the map edges visible there), `steps[i]` the odometry
/// step from scan i to scan i + 1 (in scan i's frame; one fewer than the scans), and the
/// odometry drift estimated over the run (`None` unless [`GraphOptions::systematic_drift`]
/// is on and the run has two scans or more).
pub fn refine_run(
    scans: &[&[Segment]],
    edges: &[Vec<Segment>],
    poses: &[Pose2],
    steps: &[Pose2],
    options: &GraphOptions,
    refine: &RefineOptions,
) -> (Vec<Pose2>, Option<OdometryDrift>) {
    let n = poses.len();
    if n == 0 || scans.len() != n || edges.len() != n || steps.len() + 1 != n {
        return (poses.to_vec(), None);
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
    // The systematic drift (scale error, heading bias per metre) and its prior weights.
    let mut theta = Vector2::<f64>::zeros();
    let sys = options.systematic_drift && n > 1;
    let prior = Matrix2::from_diagonal(&Vector2::new(
        1.0 / options.odometry_scale.max(1e-9).powi(2),
        1.0 / options.odometry_yaw_rad_per_m.max(1e-12).powi(2),
    ));
    let it_n = options.iterations.max(1);
    // The posterior covariance of the drift at the last step taken.
    let mut theta_cov: Option<Matrix2<f64>> = None;
    for it in 0..it_n {
        let radius = refine.radius_at(it, it_n);
        let mut d: Vec<Matrix3<f64>> = vec![Matrix3::zeros(); n];
        let mut b: Vec<Matrix3<f64>> = vec![Matrix3::zeros(); n.saturating_sub(1)];
        let mut g: Vec<Vector3<f64>> = vec![Vector3::zeros(); n];
        let mut border: Vec<Matrix3x2<f64>> = vec![Matrix3x2::zeros(); n];
        let mut corner = prior;
        let mut g_theta = prior * theta;
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
            // The step predicted by the two poses, in scan i's frame, against the odometry's
            // (with its systematic drift taken out when that is estimated).
            let pred = [co * dx + s * dy, -s * dx + co * dy];
            let len = m.x.hypot(m.y);
            let (scale, bias) = if sys {
                (1.0 + theta[0], theta[1])
            } else {
                (1.0, 0.0)
            };
            let true_len = len / scale;
            let e = Vector3::new(
                pred[0] - m.x / scale,
                pred[1] - m.y / scale,
                (c.yaw_rad - a.yaw_rad - m.yaw_rad + bias * true_len + PI).rem_euclid(TAU) - PI,
            );
            let (sd_xy, sd_yaw) = if sys {
                (
                    options.odometry_floor_m + options.odometry_random_share * len,
                    options.odometry_floor_rad + options.odometry_random_yaw_rad_per_m * len,
                )
            } else {
                (
                    options.odometry_floor_m
                        + options.odometry_scale * len
                        + 0.5 * len * options.odometry_yaw_rad_per_m * len,
                    options.odometry_floor_rad + options.odometry_yaw_rad_per_m * len,
                )
            };
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
            if sys {
                // ∂e/∂(scale error, heading bias).
                let jt = Matrix3x2::new(
                    m.x / (scale * scale),
                    0.0,
                    m.y / (scale * scale),
                    0.0,
                    0.0,
                    true_len,
                );
                border[i] += ji.transpose() * w * jt;
                border[i + 1] += jj.transpose() * w * jt;
                corner += jt.transpose() * w * jt;
                g_theta += jt.transpose() * w * e;
            }
        }
        let delta = if sys {
            let Some((delta, dt, cov)) = solve_bordered(d, &b, g, &border, corner, g_theta) else {
                break;
            };
            theta += dt;
            theta_cov = Some(cov);
            delta
        } else {
            let Some(delta) = solve_block_tridiagonal(d, &b, g) else {
                break;
            };
            delta
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
    // With the drift estimated, a pose may move as far as the odometry can drift over the run.
    let run_m: f64 = steps.iter().map(|m| m.x.hypot(m.y)).sum();
    let shift_limit = options.max_shift_m
        + if sys {
            options.odometry_scale * run_m
        } else {
            0.0
        };
    let refined = x
        .iter()
        .zip(poses)
        .map(|(r, p)| {
            if r.x.is_finite()
                && r.y.is_finite()
                && r.yaw_rad.is_finite()
                && r.distance_to(p) <= shift_limit
            {
                Pose2 {
                    yaw_rad: r.yaw_rad.rem_euclid(TAU),
                    ..*r
                }
            } else {
                *p
            }
        })
        .collect();
    let per_100m = 100f64.to_degrees();
    let drift = theta_cov
        .filter(|c| theta.iter().chain(c.iter()).all(|v| v.is_finite()))
        .map(|c| OdometryDrift {
            scale_error: theta[0],
            scale_error_sd: c[(0, 0)].max(0.0).sqrt(),
            heading_bias_deg_per_100m: theta[1] * per_100m,
            heading_bias_sd_deg_per_100m: c[(1, 1)].max(0.0).sqrt() * per_100m,
        });
    (refined, drift)
}

/// The steps of the poses and of θ, and θ's covariance.
type BorderedSolution = (Vec<Vector3<f64>>, Vector2<f64>, Matrix2<f64>);

/// Solves [H B; Bᵀ C] (δ, δθ) = −(g, g_θ) for a symmetric block-tridiagonal H (blocks `d`,
/// `b`, as [`solve_block_tridiagonal`]) bordered by the two global unknowns θ: their Schur
/// complement, with one block elimination of H for its three solves, so O(n); also the
/// inverse of that complement (θ's posterior covariance). `None` when a pivot is singular.
fn solve_bordered(
    d: Vec<Matrix3<f64>>,
    b: &[Matrix3<f64>],
    g: Vec<Vector3<f64>>,
    border: &[Matrix3x2<f64>],
    corner: Matrix2<f64>,
    g_theta: Vector2<f64>,
) -> Option<BorderedSolution> {
    // u = H⁻¹(−g); y_k = H⁻¹ B_k (one elimination of H; `solve` gives δ with H δ = −rhs).
    let h = BlockElimination::factor(d, b)?;
    let u = h.solve(g);
    let y: Vec<Vec<Vector3<f64>>> = (0..2)
        .map(|k| h.solve(border.iter().map(|bk| -bk.column(k).into_owned()).collect()))
        .collect();
    let mut schur = corner;
    let mut rhs = -g_theta;
    for (i, bi) in border.iter().enumerate() {
        for k in 0..2 {
            for l in 0..2 {
                schur[(k, l)] -= bi.column(k).dot(&y[l][i]);
            }
            rhs[k] -= bi.column(k).dot(&u[i]);
        }
    }
    schur += Matrix2::identity() * (1e-9 * (schur.trace().abs() + 1.0));
    let cov = schur.try_inverse()?;
    let dt = cov * rhs;
    let delta = (0..u.len())
        .map(|i| u[i] - y[0][i] * dt[0] - y[1][i] * dt[1])
        .collect();
    Some((delta, dt, cov))
}

/// Solves H δ = −g for a symmetric block-tridiagonal H with diagonal blocks `d` and upper
/// blocks `b` (H[i][i + 1] = b[i], H[i + 1][i] = b[i]ᵀ), with a small damping on the diagonal;
/// `None` when a pivot block is singular.
fn solve_block_tridiagonal(
    d: Vec<Matrix3<f64>>,
    b: &[Matrix3<f64>],
    g: Vec<Vector3<f64>>,
) -> Option<Vec<Vector3<f64>>> {
    Some(BlockElimination::factor(d, b)?.solve(g))
}

/// The block elimination of a damped symmetric block-tridiagonal H (as
/// [`solve_block_tridiagonal`] takes it), kept to solve for several right-hand sides.
struct BlockElimination<'a> {
    /// The upper blocks of H.
    b: &'a [Matrix3<f64>],
    /// Inverses of the eliminated pivot blocks.
    inv: Vec<Matrix3<f64>>,
    /// The multipliers b[i − 1]ᵀ · inv[i − 1] of row i (one fewer than the blocks).
    l: Vec<Matrix3<f64>>,
}

impl<'a> BlockElimination<'a> {
    /// Eliminates H's lower blocks; `None` when a pivot block is singular.
    fn factor(mut d: Vec<Matrix3<f64>>, b: &'a [Matrix3<f64>]) -> Option<BlockElimination<'a>> {
        let n = d.len();
        let mut inv: Vec<Matrix3<f64>> = Vec::with_capacity(n);
        let mut l: Vec<Matrix3<f64>> = Vec::with_capacity(n.saturating_sub(1));
        for i in 0..n {
            let damping = 1e-6 * (d[i].trace() + 1.0);
            d[i] += Matrix3::identity() * damping;
            if i > 0 {
                let li = b[i - 1].transpose() * inv[i - 1];
                d[i] -= li * b[i - 1];
                l.push(li);
            }
            inv.push(d[i].try_inverse()?);
        }
        Some(BlockElimination { b, inv, l })
    }

    /// δ with H δ = −g.
    fn solve(&self, g: Vec<Vector3<f64>>) -> Vec<Vector3<f64>> {
        let n = self.inv.len();
        let mut r: Vec<Vector3<f64>> = g.into_iter().map(|v| -v).collect();
        for i in 1..n {
            let previous = r[i - 1];
            r[i] -= self.l[i - 1] * previous;
        }
        let mut delta = vec![Vector3::zeros(); n];
        for i in (0..n).rev() {
            let rhs = if i + 1 < n {
                r[i] - self.b[i] * delta[i + 1]
            } else {
                r[i]
            };
            delta[i] = self.inv[i] * rhs;
        }
        delta
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    /// The dense form of a block-tridiagonal system (damped as the solver damps it), in the
    /// top-left of a system `extra` unknowns larger, and its right-hand side −g.
    fn dense(
        d: &[Matrix3<f64>],
        b: &[Matrix3<f64>],
        g: &[Vector3<f64>],
        extra: usize,
    ) -> (DMatrix<f64>, nalgebra::DVector<f64>) {
        let n = d.len();
        let mut h = DMatrix::<f64>::zeros(3 * n + extra, 3 * n + extra);
        let mut rhs = nalgebra::DVector::<f64>::zeros(3 * n + extra);
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
        (h, rhs)
    }

    /// [`refine_run`] with the default refinement options.
    fn refined(
        scans: &[&[Segment]],
        edges: &[Vec<Segment>],
        start: &[Pose2],
        steps: &[Pose2],
        options: &GraphOptions,
    ) -> Vec<Pose2> {
        refine_run(
            scans,
            edges,
            start,
            steps,
            options,
            &RefineOptions::default(),
        )
        .0
    }

    /// A block-tridiagonal system: diagonal blocks, upper blocks, right-hand side.
    type System = (Vec<Matrix3<f64>>, Vec<Matrix3<f64>>, Vec<Vector3<f64>>);

    /// A well-conditioned block-tridiagonal test system of `n` blocks.
    fn test_system(n: usize) -> System {
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
        (d, b, g)
    }

    #[test]
    fn block_elimination_equals_a_dense_solve() {
        let n = 5;
        let (d, b, g) = test_system(n);
        let got = solve_block_tridiagonal(d.clone(), &b, g.clone()).unwrap();
        let (h, rhs) = dense(&d, &b, &g, 0);
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
        let got = refined(&scans, &edges, &start, &steps, &GraphOptions::default());
        for (g, t) in got.iter().zip(&truth) {
            assert!(g.distance_to(t) < 0.3, "{got:?}");
        }
        // Without the odometry's pull (each scan alone), the along-street error stays.
        let alone = refined(
            &scans[1..2],
            &edges[1..2],
            &start[1..2],
            &[],
            &GraphOptions::default(),
        );
        assert!(alone[0].distance_to(&truth[1]) > 2.5, "{alone:?}");
    }

    /// An L-shaped drive: four 40 m steps east along a street, a left turn, three steps north
    /// along another; a cross wall pins the first scan along the first street, the second
    /// street's walls pin the corner scan across it, and nothing pins the last scans along the
    /// second street. The odometry overstates every step by 2 % and turns 1° per 50 m too
    /// far, and the poses start where a chain coasting from the first scan would put them.
    /// With the drift estimated, the first leg (pinned at both ends) gives the scale and the
    /// bias, and the second leg comes back within 0.3 m; with independent step spreads (and
    /// no move limit), its last scan stays 2.4 m off along the street.
    #[test]
    fn the_systematic_drift_learnt_on_one_street_corrects_the_next() {
        let mut truth: Vec<Pose2> = (0..5)
            .map(|i| Pose2 {
                x: 10.0 + 40.0 * i as f64,
                y: 0.0,
                yaw_rad: 0.0,
            })
            .collect();
        truth[4].yaw_rad = std::f64::consts::FRAC_PI_2;
        truth.extend((1..4).map(|i| Pose2 {
            x: 170.0,
            y: 40.0 * i as f64,
            yaw_rad: std::f64::consts::FRAC_PI_2,
        }));
        let map: Vec<Segment> = vec![
            Segment::new([0.0, 8.0], [162.0, 8.0]),
            Segment::new([0.0, -8.0], [178.0, -8.0]),
            Segment::new([0.0, -8.0], [0.0, 8.0]),
            Segment::new([162.0, 8.0], [162.0, 300.0]),
            Segment::new([178.0, -8.0], [178.0, 300.0]),
        ];
        // What a scan sees of the map: each wall within 12 m of the sensor, clipped to 20 m
        // around the sensor's nearest point on it, in the sensor frame.
        let seen = |t: &Pose2| -> Vec<Segment> {
            let inv = t.inverse();
            map.iter()
                .filter(|e| e.distance_to([t.x, t.y]) < 12.0)
                .filter_map(|e| {
                    let (l, d) = (
                        e.length(),
                        [
                            (e.b[0] - e.a[0]) / e.length(),
                            (e.b[1] - e.a[1]) / e.length(),
                        ],
                    );
                    let u = (t.x - e.a[0]) * d[0] + (t.y - e.a[1]) * d[1];
                    let (u0, u1) = ((u - 10.0).max(0.0), (u + 10.0).min(l));
                    (u1 - u0 > 2.0).then(|| {
                        Segment::new(
                            inv.apply([e.a[0] + u0 * d[0], e.a[1] + u0 * d[1]]),
                            inv.apply([e.a[0] + u1 * d[0], e.a[1] + u1 * d[1]]),
                        )
                    })
                })
                .collect()
        };
        let owned: Vec<Vec<Segment>> = truth.iter().map(seen).collect();
        let scans: Vec<&[Segment]> = owned.iter().map(|v| v.as_slice()).collect();
        let edges = vec![map.clone(); truth.len()];
        let bias = 1f64.to_radians() / 50.0;
        let steps: Vec<Pose2> = truth
            .windows(2)
            .map(|w| {
                let rel = w[0].inverse().compose(&w[1]);
                Pose2 {
                    x: rel.x * 1.02,
                    y: rel.y * 1.02,
                    yaw_rad: rel.yaw_rad + bias * rel.x.hypot(rel.y),
                }
            })
            .collect();
        let mut start = vec![truth[0]];
        for m in &steps {
            let last = *start.last().unwrap();
            start.push(last.compose(m));
        }
        assert!(start[7].distance_to(&truth[7]) > 5.0, "{:?}", start[7]);
        assert!(owned.iter().all(|v| v.len() >= 2), "{owned:?}");
        let (got, drift) = refine_run(
            &scans,
            &edges,
            &start,
            &steps,
            &GraphOptions::default(),
            &RefineOptions::default(),
        );
        for (i, (g, t)) in got.iter().zip(&truth).enumerate() {
            assert!(g.distance_to(t) < 0.3, "scan {i}: {g:?} against {t:?}");
        }
        // The drift it reports is the one applied: 2 % and 1° per 50 m (2° per 100 m).
        let drift = drift.expect("the drift of a run");
        assert!((drift.scale_error - 0.02).abs() < 0.005, "{drift:?}");
        assert!(
            (drift.heading_bias_deg_per_100m - 2.0).abs() < 0.5,
            "{drift:?}"
        );
        assert!(
            drift.scale_error_sd > 0.0 && drift.scale_error_sd < 0.02,
            "{drift:?}"
        );
        assert!(drift.heading_bias_sd_deg_per_100m > 0.0, "{drift:?}");
        let independent = refined(
            &scans,
            &edges,
            &start,
            &steps,
            &GraphOptions {
                systematic_drift: false,
                max_shift_m: 100.0,
                ..GraphOptions::default()
            },
        );
        assert!(
            independent[7].distance_to(&truth[7]) > 1.5,
            "{independent:?}"
        );
    }

    /// A car standing still: zero steps leave the scale and the bias to their priors, and the
    /// poses stay finite and where the walls put them.
    #[test]
    fn a_car_standing_still_keeps_finite_poses() {
        let map = vec![
            Segment::new([-20.0, 8.0], [20.0, 8.0]),
            Segment::new([-20.0, -8.0], [20.0, -8.0]),
            Segment::new([-20.0, -8.0], [-20.0, 8.0]),
        ];
        let truth = Pose2 {
            x: 0.0,
            y: 0.0,
            yaw_rad: 0.0,
        };
        let scan: Vec<Segment> = map.clone();
        let scans: Vec<&[Segment]> = vec![&scan; 3];
        let edges = vec![map.clone(); 3];
        let still = Pose2 {
            x: 0.0,
            y: 0.0,
            yaw_rad: 0.0,
        };
        let start = vec![
            Pose2 {
                x: 0.4,
                y: -0.3,
                yaw_rad: 0.01,
            };
            3
        ];
        let got = refined(
            &scans,
            &edges,
            &start,
            &[still, still],
            &GraphOptions::default(),
        );
        for g in &got {
            assert!(
                g.x.is_finite() && g.y.is_finite() && g.yaw_rad.is_finite(),
                "{got:?}"
            );
            assert!(g.distance_to(&truth) < 0.1, "{got:?}");
        }
    }

    #[test]
    fn bordered_elimination_equals_a_dense_solve() {
        let n = 6;
        let (d, b, g) = test_system(n);
        let border: Vec<Matrix3x2<f64>> = (0..n)
            .map(|k| Matrix3x2::from_fn(|r, c| ((r + 2 * c + k) % 5) as f64 / 10.0 - 0.2))
            .collect();
        let corner = Matrix2::new(40.0, 1.0, 1.0, 30.0);
        let g_theta = Vector2::new(0.5, -1.5);
        let (got, got_t, got_cov) =
            solve_bordered(d.clone(), &b, g.clone(), &border, corner, g_theta).unwrap();
        let (mut h, mut rhs) = dense(&d, &b, &g, 2);
        for (i, bi) in border.iter().enumerate() {
            h.fixed_view_mut::<3, 2>(3 * i, 3 * n).copy_from(bi);
            h.fixed_view_mut::<2, 3>(3 * n, 3 * i)
                .copy_from(&bi.transpose());
        }
        h.fixed_view_mut::<2, 2>(3 * n, 3 * n).copy_from(&corner);
        rhs.fixed_rows_mut::<2>(3 * n).copy_from(&(-g_theta));
        let want = h.clone().lu().solve(&rhs).unwrap();
        for i in 0..n {
            for k in 0..3 {
                assert!((got[i][k] - want[3 * i + k]).abs() < 1e-6, "{i} {k}");
            }
        }
        for k in 0..2 {
            assert!((got_t[k] - want[3 * n + k]).abs() < 1e-6, "theta {k}");
        }
        // θ's covariance: the corner block of the whole system's inverse.
        let inverse = h.try_inverse().unwrap();
        for k in 0..2 {
            for l in 0..2 {
                let want = inverse[(3 * n + k, 3 * n + l)];
                assert!(
                    (got_cov[(k, l)] - want).abs() < 1e-6 * (1.0 + want.abs()),
                    "cov {k} {l}"
                );
            }
        }
    }
}
