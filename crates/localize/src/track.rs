//! Localization along a track: candidates of consecutive scans tied by odometry (issue 15).
//!
//! A robot rarely has one scan. Every scan is searched alone over the whole map; its states
//! are its best candidates plus the previous scan's best-ranked states carried forward by the
//! odometry step and refined on its own walls (so a place that one scan cannot single out is
//! still followed). Each state ends the best chain of states whose consecutive steps agree
//! with the odometry within a gate (a Viterbi pass over at most 40 states per scan, extended
//! scan by scan): the longest chain first, then the smallest mean cost over the window of K
//! scans ending at the scan. A chain's length counts the window and the scans within
//! `history_m` (300 m) of odometry before it, so a place followed consistently for longer
//! beats one that only fits the last few scans: in a long straight street of similar façades,
//! a parallel street driven the other way fits any five scans as well as the truth
//! (simulated Helsinki: 63/76 scans right with the window alone, 75/76 with the history;
//! README). Capping the count at the history lets a chain that broke (the truth lost for a
//! scan) win again after that distance. Odometry drifts (2 % of the distance and 1° per 50 m
//! assumed), so the gate grows with the step length; the odometry constrains, it does not
//! dictate. A first version searched the window's segments as one scan (slower, and its
//! top-1 was worse: README).
//!
//! Smoothing ([`TrackOptions::smooth`], the default): a batch of scans is also passed
//! backward (the scans reversed, each odometry step inverted), so each scan gets states
//! carried back from the scan after it too, and every state is ranked by the best chain
//! through it, the chain ending at it joined to the chain starting at it over the merged
//! states (`smoothed_chains`). Links are judged forward in time in both directions: a long
//! step with a few degrees of odometry turn predicts the later pose well but swings the
//! inverted prediction of the earlier one beyond the gate. On the real KITTI-360 tracks it
//! mends the first scans, where no chain has settled (README).
//! Then each run of linked answers is refined as a pose graph ([`crate::graph`],
//! [`TrackOptions::refine_poses`]): the walls and the odometry place the scans together.
//!
//! Odometry files have one line per scan, `x_m y_m yaw_rad` (optionally preceded by the scan
//! file name, which must then match), in any local frame; `#` starts a comment. The sensor's
//! 3-D poses as LiDAR odometry writes them (TUM or KITTI lines, z up) are read too
//! ([`read_odometry`]).

use crate::pipeline::{Candidate, Localization, Localizer, ScanSegments};
use crate::rank::{confidence, CostKind};
use crate::refine::refine_pose;
use crate::{angle_diff, LocalizeError, Pose2, Result, Segment};
use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};
use rayon::prelude::*;
use std::path::Path;

/// The line layouts of an odometry file, told apart by their number of fields (every line of
/// a file has the same layout).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum OdometryLayout {
    /// `x_m y_m yaw_rad`.
    Planar,
    /// `scan x_m y_m yaw_rad`.
    Named,
    /// TUM: `timestamp tx ty tz qx qy qz qw` (the sensor's pose, z up).
    Tum,
    /// KITTI: the 3 × 4 pose `r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz` row by row.
    Kitti,
}

impl OdometryLayout {
    fn of(fields: usize) -> Option<OdometryLayout> {
        match fields {
            3 => Some(OdometryLayout::Planar),
            4 => Some(OdometryLayout::Named),
            8 => Some(OdometryLayout::Tum),
            12 => Some(OdometryLayout::Kitti),
            _ => None,
        }
    }

    fn name(self) -> &'static str {
        match self {
            OdometryLayout::Planar => "`x_m y_m yaw_rad`",
            OdometryLayout::Named => "`scan x_m y_m yaw_rad`",
            OdometryLayout::Tum => "TUM `timestamp tx ty tz qx qy qz qw`",
            OdometryLayout::Kitti => "KITTI 3 × 4 pose (12 numbers)",
        }
    }
}

/// The layouts an odometry line may have, for error messages.
const ODOMETRY_LAYOUTS: &str = "`x_m y_m yaw_rad`, `scan x_m y_m yaw_rad`, TUM `timestamp tx ty tz qx qy qz qw` or a KITTI 3 × 4 pose (12 numbers)";

/// A unit quaternion's norm may be off by this much (rounding in the file).
const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

/// A rotation matrix's determinant may be off by this much: a rotation scaled by 1 ± the
/// quaternion tolerance has determinant 1 ± three times it.
const ROTATION_DETERMINANT_TOLERANCE: f64 = 3.0 * QUATERNION_NORM_TOLERANCE;

/// The planar pose of a 3-D pose: its position's x and y, and the heading of its x axis
/// projected on the x–y plane.
fn planar(t: [f64; 3], x_axis: Vector3<f64>) -> std::result::Result<Pose2, String> {
    if x_axis[0].hypot(x_axis[1]) < 0.1 {
        return Err(format!(
            "the pose's x axis points along z ({:.2}, {:.2}, {:.2}); the poses must be of a frame whose z axis points up",
            x_axis[0], x_axis[1], x_axis[2]
        ));
    }
    Ok(Pose2 {
        x: t[0],
        y: t[1],
        yaw_rad: x_axis[1].atan2(x_axis[0]),
    })
}

/// Reads an odometry file for scans named `names` (in order): one pose per scan, as `x_m
/// y_m yaw_rad`, `scan x_m y_m yaw_rad` (the name must match), a TUM line `timestamp tx ty
/// tz qx qy qz qw` or a KITTI 3 × 4 pose (12 numbers); the 3-D layouts are poses of the
/// sensor in a frame whose z axis points up (LiDAR odometry such as KISS-ICP writes both),
/// taken as their x, y and the heading of their x axis.
pub fn read_odometry(path: &Path, names: &[String]) -> Result<Vec<Pose2>> {
    let text = std::fs::read_to_string(path).map_err(|e| LocalizeError::Dataset {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    let err = |line: usize, message: String| LocalizeError::Odometry {
        path: path.to_path_buf(),
        line,
        message,
    };
    let mut poses = Vec::new();
    let mut positions: Vec<[f64; 3]> = Vec::new();
    let mut layout: Option<(OdometryLayout, usize)> = None;
    let mut last_line = 0;
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        last_line = line_no;
        let fields: Vec<&str> = line.split_whitespace().collect();
        let this = OdometryLayout::of(fields.len()).ok_or_else(|| {
            err(
                line_no,
                format!("{} fields; expected {ODOMETRY_LAYOUTS}", fields.len()),
            )
        })?;
        match layout {
            None => layout = Some((this, line_no)),
            Some((first, first_line)) if first != this => {
                return Err(err(
                    line_no,
                    format!(
                        "{} fields, a {} line, but line {first_line} is a {} line; every line of an odometry file has the same layout",
                        fields.len(),
                        this.name(),
                        first.name()
                    ),
                ))
            }
            Some(_) => {}
        }
        let (name, numbers, what): (Option<&str>, &[&str], &[&str]) = match this {
            OdometryLayout::Planar => (None, &fields[..], &["x_m", "y_m", "yaw_rad"]),
            OdometryLayout::Named => (Some(fields[0]), &fields[1..], &["x_m", "y_m", "yaw_rad"]),
            OdometryLayout::Tum => (
                None,
                &fields[..],
                &["timestamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw"],
            ),
            OdometryLayout::Kitti => (
                None,
                &fields[..],
                &[
                    "r11", "r12", "r13", "tx", "r21", "r22", "r23", "ty", "r31", "r32", "r33", "tz",
                ],
            ),
        };
        let mut v = [0.0; 12];
        for (k, (f, what)) in numbers.iter().zip(what).enumerate() {
            v[k] = f
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| err(line_no, format!("{what} `{f}` is not a finite number")))?;
        }
        if let Some(name) = name {
            let index = poses.len();
            match names.get(index) {
                Some(expected) if expected == name => {}
                Some(expected) => {
                    return Err(err(
                        line_no,
                        format!(
                            "pose {} is for `{name}`, but scan {} in file-name order is `{expected}` (the scans are taken in lexicographic file-name order)",
                            index + 1,
                            index + 1
                        ),
                    ))
                }
                None => {}
            }
        }
        let pose = match this {
            OdometryLayout::Planar | OdometryLayout::Named => Pose2 {
                x: v[0],
                y: v[1],
                yaw_rad: v[2],
            },
            OdometryLayout::Tum => {
                let q = Quaternion::new(v[7], v[4], v[5], v[6]);
                let norm = q.norm();
                if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
                    return Err(err(
                        line_no,
                        format!("the quaternion (qx qy qz qw) has norm {norm:.4}, not 1"),
                    ));
                }
                let x_axis = UnitQuaternion::new_unchecked(q) * Vector3::x();
                positions.push([v[1], v[2], v[3]]);
                planar([v[1], v[2], v[3]], x_axis).map_err(|m| err(line_no, m))?
            }
            OdometryLayout::Kitti => {
                let r = Matrix3::new(v[0], v[1], v[2], v[4], v[5], v[6], v[8], v[9], v[10]);
                let det = r.determinant();
                if (det - 1.0).abs() > ROTATION_DETERMINANT_TOLERANCE {
                    return Err(err(
                        line_no,
                        format!("the 3 × 3 rotation has determinant {det:.4}, not 1"),
                    ));
                }
                positions.push([v[3], v[7], v[11]]);
                planar([v[3], v[7], v[11]], r.column(0).into_owned())
                    .map_err(|m| err(line_no, m))?
            }
        };
        poses.push(pose);
    }
    if poses.len() != names.len() {
        return Err(err(
            last_line,
            format!(
                "{} poses for {} scans; expected one line per scan",
                poses.len(),
                names.len()
            ),
        ));
    }
    check_up_axis(&positions).map_err(|m| err(last_line, m))?;
    Ok(poses)
}

/// A 3-D track that moves more along z than across x–y over at least 10 m was written in a
/// frame whose z axis is not up (a camera's: KITTI's odometry ground truth has z forward).
fn check_up_axis(positions: &[[f64; 3]]) -> std::result::Result<(), String> {
    let (mut along_z, mut across) = (0.0, 0.0);
    for w in positions.windows(2) {
        along_z += (w[1][2] - w[0][2]).abs();
        across += (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]);
    }
    if along_z > 10.0 && along_z > across {
        return Err(format!(
            "the poses move {along_z:.0} m along z and {across:.0} m across x–y: a frame whose z axis is not up (a camera's?); give the sensor's poses in a frame with z up"
        ));
    }
    Ok(())
}

pub use crate::{ODOMETRY_SCALE_DRIFT, ODOMETRY_YAW_DRIFT_DEG_PER_50M};

/// Odometry from true poses with drift: every step's translation scaled by `1 + scale_error`
/// and its heading turned by `yaw_rad_per_m` per metre travelled (a systematic drift, the
/// worst case of a random one), starting at the origin.
pub fn drifted_odometry(truth: &[Pose2], scale_error: f64, yaw_rad_per_m: f64) -> Vec<Pose2> {
    odometry_with(truth, || (scale_error, yaw_rad_per_m))
}

/// Odometry from true poses, each step scaled by 1 + s and turned by b per metre travelled,
/// (s, b) from `drift` per step; starting at the origin.
fn odometry_with(truth: &[Pose2], mut drift: impl FnMut() -> (f64, f64)) -> Vec<Pose2> {
    let mut out = Vec::with_capacity(truth.len());
    let mut odo = Pose2 {
        x: 0.0,
        y: 0.0,
        yaw_rad: 0.0,
    };
    for i in 0..truth.len() {
        if let Some(rel) = step_into(truth, i) {
            let d = rel.x.hypot(rel.y);
            let (scale, bias) = drift();
            let step = Pose2 {
                x: rel.x * (1.0 + scale),
                y: rel.y * (1.0 + scale),
                yaw_rad: rel.yaw_rad + bias * d,
            };
            odo = odo.compose(&step);
        }
        out.push(odo);
    }
    out
}

/// Odometry from true poses with a *random* drift: each step's scale error drawn uniformly
/// within ±`scale_error` and its heading bias within ±`yaw_rad_per_m` (per metre of the
/// step), independently per step from `seed` (the odometry frame starts at the origin, as
/// [`drifted_odometry`]'s, whose drift is the same at every step: the worst case).
pub fn randomly_drifted_odometry(
    truth: &[Pose2],
    scale_error: f64,
    yaw_rad_per_m: f64,
    seed: u64,
) -> Vec<Pose2> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    odometry_with(truth, || {
        let s = scale_error * rng.gen_range(-1.0..=1.0);
        (s, yaw_rad_per_m * rng.gen_range(-1.0..=1.0))
    })
}

/// Most passes of the pose graph over a track's answers ([`TrackOptions::refine_poses`]).
const GRAPH_PASSES: usize = 5;
/// The graph's answers have settled when none moves more than this in a pass, metres…
const GRAPH_SETTLED_M: f64 = 0.01;
/// …and no more than this, radians.
const GRAPH_SETTLED_RAD: f64 = 1e-4;

/// Poses closer than this (and [`SAME_POSE_RAD`]) are one state of a scan, metres.
const SAME_POSE_M: f64 = 1e-3;
/// See [`SAME_POSE_M`], radians.
const SAME_POSE_RAD: f64 = 1e-6;

/// The default [`TrackOptions::history_m`]: 300 m of odometry before the window.
pub const TRACK_HISTORY_M: f64 = 300.0;

/// How the candidates of consecutive scans are tied by odometry in [`Localizer::localize_track`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackOptions {
    /// Scans per window (the scan and the K − 1 before it) whose costs rank a chain.
    pub window: usize,
    /// Odometry distance before the window, metres, through which a chain's consistency
    /// still counts: chains are compared by their length over the window and the scans of
    /// this stretch before it (so an older consistent chain beats a younger one), and by
    /// their cost over the window only.
    pub history_m: f64,
    /// Candidates of each scan's own search kept as states.
    pub own_states: usize,
    /// States of the previous scan carried forward by the odometry (and refined on this scan).
    pub carried_states: usize,
    /// Gate on the odometry residual between consecutive states: a fixed part, metres …
    pub gate_m: f64,
    /// … plus this share of the step length (odometry drift, 2 % assumed, and refinement).
    pub gate_per_m: f64,
    /// Yaw gate: a fixed part, radians …
    pub gate_rad: f64,
    /// … plus this many radians per metre of the step (1° per 50 m assumed, with margin).
    pub gate_rad_per_m: f64,
    /// Whether every carried state also coasts: its odometry prediction, unrefined, stays a
    /// state of the scan at the cost measured there, so a chain outlives a scan that none of
    /// the scan's own or refined states continues (a missed detection).
    pub coast: bool,
    /// Whether later scans count too (a batch of scans, not a robot driving): the pass runs
    /// forward and backward, and each scan's states (both passes') are ranked by the best
    /// chain through them over the scans before and after ([`Localizer::localize_track`]).
    pub smooth: bool,
    /// Whether a smoothed track's answers are moved to fit their walls and the odometry
    /// together, run by run ([`crate::graph`]).
    pub refine_poses: bool,
}

impl Default for TrackOptions {
    fn default() -> Self {
        TrackOptions {
            window: 5,
            history_m: TRACK_HISTORY_M,
            own_states: 20,
            carried_states: 20,
            gate_m: 1.5,
            gate_per_m: 0.05,
            gate_rad: 3f64.to_radians(),
            gate_rad_per_m: 4f64.to_radians() / 50.0,
            coast: true,
            smooth: true,
            refine_poses: true,
        }
    }
}

impl Localizer<'_> {
    /// Localizes every scan of a track (segments per scan, sensor frame) with the window of
    /// `options.window` scans ending at it: every scan is searched alone, the states of each
    /// scan are its best candidates plus the previous scan's states carried forward by the
    /// odometry (refined on its walls, and as predicted: [`TrackOptions::coast`]), and a
    /// scan's candidates are ranked by the cheapest chain of states through its window whose
    /// consecutive steps agree with the odometry within the gates (the sum of the scans'
    /// costs along the chain; a Viterbi pass).
    pub fn localize_track(
        &self,
        scans: &[ScanSegments],
        odometry: &[Pose2],
        options: &TrackOptions,
    ) -> Result<Vec<Localization>> {
        if scans.len() != odometry.len() {
            return Err(LocalizeError::InvalidOption {
                name: "odometry",
                value: odometry.len() as f64,
                expected: "one odometry pose per scan",
            });
        }
        // The scans' own searches are independent: run side by side (one search alone leaves
        // a core idle a third of the time). A car's headings are not restricted here: on the
        // simulated Helsinki HDL-64 drive that cost 12 of 76 scans (the parallel street driven
        // the other way then forms chains as consistent as the truth's); the chains constrain
        // the heading themselves. Searching a car's headings only (the heading mask, without
        // the filter) gave 29 of 76 there, 75 of 76 with coasting (2026-11-30), and the real
        // KITTI-360 tracks gained nothing at top-1.
        let singles: Vec<Localization> = scans
            .par_iter()
            .map(|scan| self.localize_free(&scan.segments))
            .collect();
        if !options.smooth {
            return Ok(self.track_pass(scans, singles, odometry, options));
        }
        // Smoothing: the same pass over the scans in reverse order (each odometry step
        // inverted) gives every scan the states carried back from the scans after it.
        let own_refine: Vec<f64> = singles.iter().map(|s| s.seconds.refine).collect();
        let forward = self.track_pass(scans, singles.clone(), odometry, options);
        let reversed: Vec<ScanSegments> = scans.iter().rev().cloned().collect();
        let odometry_reversed: Vec<Pose2> = odometry.iter().rev().copied().collect();
        let mut backward = self.track_pass(
            &reversed,
            singles.into_iter().rev().collect(),
            &odometry_reversed,
            options,
        );
        backward.reverse();
        Ok(self.smooth_pass(scans, forward, backward, &own_refine, odometry, options))
    }

    /// Ranks every scan's states (the forward and the backward pass's, merged) by the best
    /// gated chain through them: the chain ending at the state over the scans before it and
    /// the chain starting at it over the scans after it, each found by a Viterbi pass over the
    /// merged states and capped as one pass's chains are; the longer combined chain first,
    /// then the smaller mean cost over the two windows.
    fn smooth_pass(
        &self,
        scans: &[ScanSegments],
        forward: Vec<Localization>,
        backward: Vec<Localization>,
        own_refine: &[f64],
        odometry: &[Pose2],
        options: &TrackOptions,
    ) -> Vec<Localization> {
        let t = std::time::Instant::now();
        let o = &self.options;
        let states: Vec<Vec<Candidate>> = forward
            .iter()
            .zip(&backward)
            .map(|(f, b)| {
                let mut merged = f.candidates.clone();
                for c in &b.candidates {
                    if !merged.iter().any(|m| {
                        m.pose.distance_to(&c.pose) <= SAME_POSE_M
                            && m.pose.yaw_error_to(&c.pose) <= SAME_POSE_RAD
                    }) {
                        merged.push(*c);
                    }
                }
                merged
            })
            .collect();
        let through = smoothed_chains(&states, odometry, self.options.rank_by, options);
        let seconds = t.elapsed().as_secs_f64() / forward.len().max(1) as f64;
        let mut out: Vec<Localization> = forward
            .into_iter()
            .zip(backward)
            .enumerate()
            .map(|(i, (mut result, back))| {
                let through = &through[i];
                let mut order: Vec<usize> = (0..states[i].len()).collect();
                order.sort_by(|&x, &y| through[x].better(&through[y]));
                let chain: Vec<f64> = order.iter().map(|&s| through[s].mean_cost()).collect();
                set_ranked(
                    &mut result,
                    order.iter().map(|&s| states[i][s]).collect(),
                    &chain,
                    o,
                );
                // Both passes' track time (the scan's own search counted once).
                let extra = (back.seconds.refine - own_refine[i]).max(0.0) + seconds;
                result.seconds.refine += extra;
                result.seconds.total += extra;
                result
            })
            .collect();
        if options.refine_poses {
            let t = std::time::Instant::now();
            // Until the answers stop moving: moved answers see other map edges and may link
            // into longer runs.
            for _ in 0..GRAPH_PASSES {
                if !self.refine_answers(scans, &mut out, odometry, options) {
                    break;
                }
            }
            let per_scan = t.elapsed().as_secs_f64() / out.len().max(1) as f64;
            for r in &mut out {
                r.seconds.refine += per_scan;
                r.seconds.total += per_scan;
            }
        }
        out
    }

    /// Moves each run of linked answers (consecutive scans whose top candidates agree with
    /// the odometry within the gates) to fit their walls and the odometry together
    /// ([`crate::graph::refine_run`]); each moved top candidate is scored where it lands.
    /// Returns whether a top candidate moved by more than [`GRAPH_SETTLED_M`].
    fn refine_answers(
        &self,
        scans: &[ScanSegments],
        out: &mut [Localization],
        odometry: &[Pose2],
        options: &TrackOptions,
    ) -> bool {
        let mut moved = false;
        for r in out.iter_mut() {
            r.odometry_run = None;
        }
        let tops: Vec<Option<Pose2>> = out
            .iter()
            .map(|r| r.candidates.first().map(|c| c.pose))
            .collect();
        let mut start = 0;
        while start < out.len() {
            let mut end = start + 1;
            while end < out.len() {
                let linked = match (tops[end - 1], tops[end], step_into(odometry, end)) {
                    (Some(a), Some(b), Some(step)) => {
                        within_gates(&a.compose(&step), &b, &step, options)
                    }
                    _ => false,
                };
                if !linked {
                    break;
                }
                end += 1;
            }
            if end - start >= 2 {
                let poses: Vec<Pose2> = tops[start..end].iter().flatten().copied().collect();
                let segments: Vec<&[Segment]> = scans[start..end]
                    .iter()
                    .map(|s| s.segments.as_slice())
                    .collect();
                let edges: Vec<Vec<Segment>> = poses
                    .iter()
                    .map(|p| self.visible_from_views(p, &[[0.0, 0.0]]))
                    .collect();
                let steps: Vec<Pose2> = (start + 1..end)
                    .filter_map(|i| step_into(odometry, i))
                    .collect();
                let (refined, drift) = crate::graph::refine_run(
                    &segments,
                    &edges,
                    &poses,
                    &steps,
                    &crate::graph::GraphOptions::default(),
                    &self.options.refine,
                );
                let run = crate::graph::OdometryRun {
                    first_scan: start,
                    scans: end - start,
                    length_m: steps.iter().map(|m| m.x.hypot(m.y)).sum(),
                    drift,
                };
                for (k, pose) in refined.into_iter().enumerate() {
                    let r = &mut out[start + k];
                    r.odometry_run = Some(run);
                    if let Some(first) = r.candidates.first_mut() {
                        if pose != first.pose && self.pose_allowed(&pose) {
                            moved |= pose.distance_to(&first.pose) > GRAPH_SETTLED_M
                                || angle_diff(pose.yaw_rad, first.pose.yaw_rad).abs()
                                    > GRAPH_SETTLED_RAD;
                            first.costs =
                                self.costs_at(&scans[start + k].segments, pose, first.costs.dcm);
                            first.pose = pose;
                        }
                    }
                }
            }
            start = end;
        }
        moved
    }

    /// The track pass of [`Localizer::localize_track`] on every scan's own search result
    /// (`singles[i]` of `scans[i]`; one odometry pose per scan).
    fn track_pass(
        &self,
        scans: &[ScanSegments],
        singles: Vec<Localization>,
        odometry: &[Pose2],
        options: &TrackOptions,
    ) -> Vec<Localization> {
        let o = &self.options;
        let mut out: Vec<Localization> = Vec::with_capacity(scans.len());
        let mut states: Vec<Vec<Candidate>> = Vec::with_capacity(scans.len());
        let mut chains: Vec<Chain> = Vec::new();
        let travelled = travelled_m(odometry);
        for (i, (scan, single)) in scans.iter().zip(singles).enumerate() {
            let segs = &scan.segments;
            let t = std::time::Instant::now();
            let mut mine: Vec<Candidate> = single
                .candidates
                .iter()
                .take(options.own_states)
                .copied()
                .collect();
            // The odometry step from the previous scan (none for the first).
            let step = step_into(odometry, i);
            if let Some(step) = step {
                // The previous scan's states in its chain order, moved by the odometry: a
                // long-followed place is carried even when its own cost on that scan was poor.
                let predicted: Vec<Pose2> = out[i - 1]
                    .candidates
                    .iter()
                    .take(options.carried_states)
                    .map(|prev| prev.pose.compose(&step))
                    .collect();
                let carried: Vec<Candidate> = predicted
                    .par_iter()
                    .flat_map_iter(|&p| {
                        // Refined on this scan's walls (if it has any), unless one of its
                        // own states continues the chain (within the gates); a state merely
                        // near it (within the distinct radius, 4 m) would not, and the chain
                        // would break there.
                        let refined = (!segs.is_empty()
                            && !mine
                                .iter()
                                .any(|c| within_gates(&p, &c.pose, &step, options)))
                        .then(|| {
                            let visible = self.visible_from_views(&p, &[[0.0, 0.0]]);
                            refine_pose(segs, &visible, p, &o.refine)
                        });
                        // Coasting: the prediction itself, scored where it stands, even
                        // when an own state continues the chain. The chain then survives a
                        // scan whose own states and refinement all miss its place (a map
                        // error there; on the simulated Helsinki drive searched over a
                        // car's headings, the state that continued the chain was 3 m off
                        // and led it away from the truth), and a scan without walls is
                        // placed by the odometry (every state then costs the same: nothing
                        // matched). Not when the refinement left the prediction where it
                        // was: the same state twice would take two of the next scan's
                        // carried places.
                        let coasted = (options.coast
                            && !refined.is_some_and(|r| {
                                r.distance_to(&p) <= SAME_POSE_M
                                    && r.yaw_error_to(&p) <= SAME_POSE_RAD
                            }))
                        .then_some(p);
                        refined
                            .into_iter()
                            .map(|pose| (pose, true))
                            .chain(coasted.map(|pose| (pose, false)))
                            .filter(|(pose, _)| self.pose_allowed(pose))
                            .map(|(pose, refined)| Candidate {
                                pose,
                                costs: self.costs_at(segs, pose, f64::INFINITY),
                                refined,
                                confidence: 0.0,
                            })
                            .collect::<Vec<_>>()
                    })
                    .collect();
                mine.extend(carried);
            }
            self.sort(&mut mine);
            states.push(mine);
            let cap = chain_cap(&travelled, i, options);
            chains = extend_chains(
                &states,
                &chains,
                step,
                i,
                cap,
                self.options.rank_by,
                options,
                false,
            );
            let mut order: Vec<usize> = (0..states[i].len()).collect();
            order.sort_by(|&a, &b| chains[a].better(&chains[b]));
            let ranked: Vec<Candidate> = order
                .iter()
                .map(|&s| {
                    let mut c = states[i][s];
                    c.confidence = chains[s].mean_cost();
                    c
                })
                .collect();
            let mut result = single;
            if segs.is_empty() && !ranked.is_empty() {
                result.message = Some(
                    "the scan has no segments; its candidates are the previous scan's states \
                     moved by the odometry"
                        .into(),
                );
            }
            let chain: Vec<f64> = ranked.iter().map(|c| c.confidence).collect();
            set_ranked(&mut result, ranked, &chain, o);
            result.seconds.refine += t.elapsed().as_secs_f64();
            result.seconds.total += t.elapsed().as_secs_f64();
            result.record_extraction(scan);
            out.push(result);
        }
        out
    }
}

/// Sets a scan's candidates in their ranked order, with the confidence from their chains'
/// mean costs (`chain`, in the same order; lower is better) on the result and its first
/// candidate.
fn set_ranked(
    result: &mut Localization,
    ranked: Vec<Candidate>,
    chain: &[f64],
    o: &crate::pipeline::LocalizeOptions,
) {
    result.candidates = ranked;
    let poses: Vec<Pose2> = result.candidates.iter().map(|c| c.pose).collect();
    result.confidence = if chain.is_empty() {
        0.0
    } else {
        confidence(chain, &poses, o.distinct_m, o.distinct_rad)
    };
    for c in &mut result.candidates {
        c.confidence = 0.0;
    }
    if let Some(first) = result.candidates.first_mut() {
        first.confidence = result.confidence;
    }
}

/// The best gated chain ending in each state of each scan (a Viterbi pass over fixed
/// states, one odometry pose per scan; `reversed`: the scans and odometry run backward in
/// time, [`extend_chains`]).
fn viterbi(
    states: &[Vec<Candidate>],
    odometry: &[Pose2],
    kind: CostKind,
    options: &TrackOptions,
    reversed: bool,
) -> Vec<Vec<Chain>> {
    let travelled = travelled_m(odometry);
    let mut out: Vec<Vec<Chain>> = Vec::with_capacity(states.len());
    for i in 0..states.len() {
        let step = step_into(odometry, i);
        let cap = chain_cap(&travelled, i, options);
        let prev: &[Chain] = out.last().map_or(&[], |v| v.as_slice());
        let next = extend_chains(states, prev, step, i, cap, kind, options, reversed);
        out.push(next);
    }
    out
}

/// The best gated chain through each state of each scan: the chain ending at it (over the
/// scans before) joined to the chain starting at it (over the scans after), each from a
/// Viterbi pass over the same states and links ([`Chain::joined`]).
fn smoothed_chains(
    states: &[Vec<Candidate>],
    odometry: &[Pose2],
    kind: CostKind,
    options: &TrackOptions,
) -> Vec<Vec<Chain>> {
    let before = viterbi(states, odometry, kind, options, false);
    let states_reversed: Vec<Vec<Candidate>> = states.iter().rev().cloned().collect();
    let odometry_reversed: Vec<Pose2> = odometry.iter().rev().copied().collect();
    let mut after = viterbi(&states_reversed, &odometry_reversed, kind, options, true);
    after.reverse();
    before
        .iter()
        .zip(&after)
        .map(|(b, a)| b.iter().zip(a).map(|(b, a)| b.joined(a)).collect())
        .collect()
}

/// The odometry step from scan i − 1 to scan i, in scan i − 1's frame (none for the first).
fn step_into(odometry: &[Pose2], i: usize) -> Option<Pose2> {
    (i > 0).then(|| odometry[i - 1].inverse().compose(&odometry[i]))
}

/// Odometry distance travelled up to each scan, metres.
fn travelled_m(odometry: &[Pose2]) -> Vec<f64> {
    std::iter::once(0.0)
        .chain((1..odometry.len()).scan(0.0, |d, i| {
            let step = step_into(odometry, i)?;
            *d += step.x.hypot(step.y);
            Some(*d)
        }))
        .collect()
}

/// The longest chain length counted at scan i: the window's scans and those within the
/// history's odometry distance before it.
fn chain_cap(travelled: &[f64], i: usize, options: &TrackOptions) -> usize {
    let window = options.window.max(1);
    let start = (i + 1).saturating_sub(window);
    // `travelled` grows with the scan index: the scans before the window within the
    // history are a suffix of `travelled[..start]` (a NaN history holds none).
    let first = travelled[..start].partition_point(|&d| {
        !matches!(
            (travelled[start] - d).partial_cmp(&options.history_m),
            Some(std::cmp::Ordering::Less | std::cmp::Ordering::Equal)
        )
    });
    window + start - first
}

/// The best chain ending in each state of scan i, extending the chains of scan i − 1
/// (`prev`, one per state of `states[i - 1]`) by the odometry `step` within the gates;
/// lengths are capped at `cap` scans, costs (of `kind`) kept over the window. `reversed`:
/// the scans run backward in time (`step` is an inverted odometry step), and each link is
/// still judged forward in time, from the earlier state to the later one, so both passes
/// of a smoothed track agree on which states are linked.
#[allow(clippy::too_many_arguments)]
fn extend_chains(
    states: &[Vec<Candidate>],
    prev: &[Chain],
    step: Option<Pose2>,
    i: usize,
    cap: usize,
    kind: CostKind,
    options: &TrackOptions,
    reversed: bool,
) -> Vec<Chain> {
    let window = options.window.max(1);
    states[i]
        .iter()
        .map(|c| {
            let own = c.costs.get(kind);
            let mut best = Chain {
                length: 1,
                recent: vec![own],
            };
            let Some(step) = step else { return best };
            let forward_step = if reversed { step.inverse() } else { step };
            for (p, chain) in states[i - 1].iter().zip(prev) {
                let (earlier, later) = if reversed { (c, p) } else { (p, c) };
                if !within_gates(
                    &earlier.pose.compose(&forward_step),
                    &later.pose,
                    &forward_step,
                    options,
                ) {
                    continue;
                }
                let keep = chain.recent.len().min(window - 1);
                let mut recent = chain.recent[chain.recent.len() - keep..].to_vec();
                recent.push(own);
                let next = Chain {
                    length: (chain.length + 1).min(cap),
                    recent,
                };
                if next.better(&best).is_lt() {
                    best = next;
                }
            }
            best
        })
        .collect()
}

/// Whether a state at `pose` continues a chain whose last state, moved by the odometry
/// `step`, predicts `predicted`: the residual is within the gates (a fixed part plus a share
/// of the step's length).
fn within_gates(predicted: &Pose2, pose: &Pose2, step: &Pose2, options: &TrackOptions) -> bool {
    let len = step.x.hypot(step.y);
    predicted.distance_to(pose) <= options.gate_m + options.gate_per_m * len
        && predicted.yaw_error_to(pose) <= options.gate_rad + options.gate_rad_per_m * len
}

/// The best gated chain of states ending in one state.
#[derive(Debug, Clone)]
struct Chain {
    /// Consecutive scans the chain spans (capped at the window plus the history).
    length: usize,
    /// Its states' costs over the window's last scans, oldest first.
    recent: Vec<f64>,
}

impl Chain {
    /// Mean cost per scan over the window.
    fn mean_cost(&self) -> f64 {
        self.recent.iter().sum::<f64>() / self.recent.len().max(1) as f64
    }

    /// The chain through one state: `self` ending at it and `after` starting at it (both
    /// hold the state's own cost last).
    fn joined(&self, after: &Chain) -> Chain {
        let mut recent = self.recent.clone();
        let n = after.recent.len().saturating_sub(1);
        recent.extend(after.recent[..n].iter().rev());
        Chain {
            length: self.length + after.length.saturating_sub(1),
            recent,
        }
    }

    /// Longer chains first; among equals, the cheaper over the window.
    fn better(&self, other: &Chain) -> std::cmp::Ordering {
        other
            .length
            .cmp(&self.length)
            .then(self.mean_cost().total_cmp(&other.mean_cost()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(x: f64, y: f64, yaw_rad: f64) -> Pose2 {
        Pose2 { x, y, yaw_rad }
    }

    /// A refined state heading east at (x, y) with every cost `cost`.
    fn cand(x: f64, y: f64, cost: f64) -> Candidate {
        Candidate {
            pose: p(x, y, 0.0),
            costs: crate::rank::Costs {
                dcm: cost,
                forward: cost,
                reverse: cost,
                symmetric: cost,
            },
            refined: true,
            confidence: 0.0,
        }
    }

    #[test]
    fn the_gates_grow_with_the_step() {
        let o = TrackOptions::default();
        let at = p(10.0, 0.0, 0.0);
        let short = p(1.0, 0.0, 0.0);
        let long = p(40.0, 0.0, 0.0);
        // 1.5 m + 5 % of the step; 3° + 4° per 50 m.
        assert!(within_gates(&at, &p(11.4, 0.0, 0.0), &short, &o));
        assert!(!within_gates(&at, &p(11.6, 0.0, 0.0), &short, &o));
        assert!(within_gates(&at, &p(13.4, 0.0, 0.0), &long, &o));
        // A state 3 m away (within the 4 m distinct radius) does not continue the chain after
        // a short step: the carried state must then be kept.
        assert!(!within_gates(&at, &p(13.0, 0.0, 0.0), &short, &o));
        assert!(within_gates(
            &at,
            &p(10.0, 0.0, 3.0f64.to_radians()),
            &short,
            &o
        ));
        assert!(!within_gates(
            &at,
            &p(10.0, 0.0, 3.2f64.to_radians()),
            &short,
            &o
        ));
        assert!(within_gates(
            &at,
            &p(10.0, 0.0, 6.0f64.to_radians()),
            &long,
            &o
        ));
    }

    #[test]
    fn compose_and_inverse_agree() {
        let a = p(3.0, -2.0, 0.7);
        let b = p(-1.0, 4.0, -2.1);
        let id = a.inverse().compose(&a);
        assert!(id.x.abs() < 1e-12 && id.y.abs() < 1e-12 && id.yaw_rad.abs() < 1e-12);
        let q = [0.5, 1.5];
        let ab = a.compose(&b).apply(q);
        let step = a.apply(b.apply(q));
        assert!((ab[0] - step[0]).abs() < 1e-12 && (ab[1] - step[1]).abs() < 1e-12);
    }

    /// States of two places followed along x in 10 m steps: `old` from scan 0 at cost 0.3,
    /// `young` (50 m to the side) from scan 3 at cost 0.1; scan 7's chains with `history_m`.
    fn two_lineages(history_m: f64) -> (Vec<Candidate>, Vec<Chain>) {
        let options = TrackOptions {
            window: 3,
            history_m,
            ..Default::default()
        };
        let odometry: Vec<Pose2> = (0..8).map(|i| p(10.0 * i as f64, 0.0, 0.0)).collect();
        let travelled: Vec<f64> = (0..8).map(|i| 10.0 * i as f64).collect();
        let mut states = Vec::new();
        let mut chains = Vec::new();
        for i in 0..8 {
            let x = 10.0 * i as f64;
            let mut here = vec![cand(x, 0.0, 0.3)];
            if i >= 3 {
                here.push(cand(x, 50.0, 0.1));
            }
            states.push(here);
            let step = step_into(&odometry, i);
            let cap = chain_cap(&travelled, i, &options);
            chains = extend_chains(
                &states,
                &chains,
                step,
                i,
                cap,
                CostKind::Reverse,
                &options,
                false,
            );
        }
        (states.pop().unwrap(), chains)
    }

    #[test]
    fn an_older_consistent_chain_beats_a_younger_cheaper_one_within_the_history() {
        // Window only: both chains fill the window of 3; the younger is cheaper.
        let (_, chains) = two_lineages(0.0);
        assert_eq!((chains[0].length, chains[1].length), (3, 3));
        assert!(chains[1].better(&chains[0]).is_lt());
        // 30 m of history: 3 + 3 scans counted; the old chain spans them, the young one 5.
        let (_, chains) = two_lineages(30.0);
        assert_eq!((chains[0].length, chains[1].length), (6, 5));
        assert!(chains[0].better(&chains[1]).is_lt());
        // Costs are still the window's: the old chain's mean is its last 3 scans' 0.3.
        assert!((chains[0].mean_cost() - 0.3).abs() < 1e-12);
        assert_eq!(chains[0].recent.len(), 3);
        // The history is odometry distance: at scan 7 of 10 m steps, 30 m before the
        // window's first scan (scan 5) holds scans 2, 3 and 4.
        let options = TrackOptions {
            window: 3,
            history_m: 30.0,
            ..Default::default()
        };
        let travelled: Vec<f64> = (0..8).map(|i| 10.0 * i as f64).collect();
        assert_eq!(chain_cap(&travelled, 7, &options), 6);
        assert_eq!(chain_cap(&travelled, 1, &options), 3);
    }

    /// Scans 0–7 along x in 10 m steps: the truth (cost 0.3) at every scan, and a decoy 50 m
    /// to the side (cost 0.1) at scans 0–2 only. Ranked by the scans before each scan, the
    /// decoy wins scans 0–2 (as long a chain, cheaper); smoothed, the truth's chain runs on
    /// through scan 7 and wins every scan.
    #[test]
    fn smoothing_lets_later_scans_settle_the_first_ones() {
        let odometry: Vec<Pose2> = (0..8).map(|i| p(10.0 * i as f64, 0.0, 0.0)).collect();
        let states: Vec<Vec<Candidate>> = (0..8)
            .map(|i| {
                let x = 10.0 * i as f64;
                let mut here = vec![cand(x, 0.0, 0.3)];
                if i <= 2 {
                    here.push(cand(x, 50.0, 0.1));
                }
                here
            })
            .collect();
        let options = TrackOptions {
            window: 3,
            ..Default::default()
        };
        let kind = CostKind::Symmetric;
        let causal = viterbi(&states, &odometry, kind, &options, false);
        for (i, chains) in causal.iter().enumerate().take(3) {
            assert!(chains[1].better(&chains[0]).is_lt(), "scan {i}");
        }
        let smoothed = smoothed_chains(&states, &odometry, kind, &options);
        for (i, chains) in smoothed.iter().enumerate() {
            assert_eq!(chains[0].length, 8, "scan {i}: {chains:?}");
            if i <= 2 {
                assert_eq!(chains[1].length, 3, "scan {i}: {chains:?}");
                assert!(chains[0].better(&chains[1]).is_lt(), "scan {i}");
            }
        }
        // The joined chain holds each state's cost once: the window before and after it.
        assert_eq!(smoothed[4][0].recent.len(), 5);
        assert!((smoothed[4][0].mean_cost() - 0.3).abs() < 1e-12);
        // A link is judged forward in time in both passes: the backward pass links the same
        // pairs as the forward one. A 200 m step whose odometry turns 5° too far predicts the
        // later scan's pose well (the error is in its heading, within the yaw gate), while its
        // inverse swings the earlier scan's prediction 17 m sideways, beyond the 11.5 m gate.
        let odometry = [
            p(0.0, 0.0, 0.0),
            p(40.0, 0.0, 0.0),
            p(240.0, 0.0, 5f64.to_radians()),
        ];
        let states: Vec<Vec<Candidate>> = [0.0, 40.0, 240.0]
            .iter()
            .map(|&x| vec![cand(x, 0.0, 0.2)])
            .collect();
        let smoothed = smoothed_chains(&states, &odometry, kind, &options);
        for (i, chains) in smoothed.iter().enumerate() {
            assert_eq!(chains[0].length, 3, "scan {i}");
        }
    }

    #[test]
    fn drift_grows_with_distance() {
        let truth: Vec<Pose2> = (0..11).map(|i| p(10.0 * i as f64, 0.0, 0.0)).collect();
        let odo = drifted_odometry(&truth, 0.02, 1f64.to_radians() / 50.0);
        let last = odo[10];
        // 100 m at 2 % and 2° of heading drift: ≈ 102 m along, curving left.
        assert!((last.x - 101.9).abs() < 0.3, "{last:?}");
        assert!(last.y > 0.5 && last.y < 2.5, "{last:?}");
        assert!((last.yaw_rad - 2f64.to_radians()).abs() < 1e-9);
    }

    fn write(name: &str, text: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("urbansem-odo-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path
    }

    #[test]
    fn odometry_files_are_checked_line_by_line() {
        let names: Vec<String> = ["a.ply", "b.ply"].iter().map(|s| s.to_string()).collect();
        let ok = write("ok.txt", "# x y yaw\n0 0 0\n1.5 0.1 0.02 # second\n");
        assert_eq!(read_odometry(&ok, &names).unwrap().len(), 2);
        let named = write("named.txt", "a.ply 0 0 0\nb.ply 1 0 0\n");
        assert_eq!(read_odometry(&named, &names).unwrap().len(), 2);
        let short = write("short.txt", "0 0 0\n");
        let e = read_odometry(&short, &names).unwrap_err().to_string();
        assert!(
            e.contains("short.txt:1") && e.contains("1 poses for 2 scans"),
            "{e}"
        );
        let nan = write("nan.txt", "0 0 0\n1 NaN 0\n");
        let e = read_odometry(&nan, &names).unwrap_err().to_string();
        assert!(e.contains("nan.txt:2") && e.contains("y_m"), "{e}");
        let unsorted = write("unsorted.txt", "b.ply 0 0 0\na.ply 1 0 0\n");
        let e = read_odometry(&unsorted, &names).unwrap_err().to_string();
        assert!(e.contains("unsorted.txt:1") && e.contains("`a.ply`"), "{e}");
        let fields = write("fields.txt", "0 0\n1 0 0\n");
        let e = read_odometry(&fields, &names).unwrap_err().to_string();
        assert!(e.contains("fields.txt:1") && e.contains("2 fields"), "{e}");
    }

    #[test]
    fn tum_and_kitti_odometry_read_as_the_planar_layout() {
        let names: Vec<String> = (0..4).map(|i| format!("{i}.ply")).collect();
        let poses = [
            (0.0, 0.0, 0.1),
            (5.0, 1.0, 0.3),
            (9.0, 4.0, 1.2),
            (10.0, 9.0, -2.9),
        ];
        // A tilted sensor: its heading is that of its x axis on the ground plane.
        let (roll, pitch) = (-0.03, 0.05);
        let (mut plane, mut tum, mut kitti) = (String::new(), String::new(), String::new());
        for (i, &(x, y, yaw)) in poses.iter().enumerate() {
            plane += &format!("{x} {y} {yaw}\n");
            let r = nalgebra::Rotation3::from_euler_angles(roll, pitch, yaw);
            let q = nalgebra::UnitQuaternion::from_rotation_matrix(&r);
            tum += &format!("{i}.5 {x} {y} 0.3 {} {} {} {}\n", q.i, q.j, q.k, q.w);
            let m = r.matrix();
            kitti += &format!(
                "{} {} {} {x} {} {} {} {y} {} {} {} 0.3\n",
                m[(0, 0)],
                m[(0, 1)],
                m[(0, 2)],
                m[(1, 0)],
                m[(1, 1)],
                m[(1, 2)],
                m[(2, 0)],
                m[(2, 1)],
                m[(2, 2)]
            );
        }
        let want = read_odometry(&write("plane.txt", &plane), &names).unwrap();
        for (file, text) in [("tum.txt", &tum), ("kitti.txt", &kitti)] {
            let got = read_odometry(&write(file, text), &names).unwrap();
            for (g, w) in got.iter().zip(&want) {
                assert!(g.distance_to(w) < 1e-9, "{file}: {g:?} {w:?}");
                assert!(angle_diff(g.yaw_rad, w.yaw_rad).abs() < 1e-9, "{file}");
            }
        }
    }

    #[test]
    fn odometry_layouts_are_checked() {
        let names: Vec<String> = (0..3).map(|i| format!("{i}.ply")).collect();
        let e = |name: &str, text: &str| {
            read_odometry(&write(name, text), &names)
                .unwrap_err()
                .to_string()
        };
        let mixed = e("mixed.txt", "0 0 0\n0.1 1 0 0 0 0 0 1\n2 0 0\n");
        assert!(
            mixed.contains("mixed.txt:2") && mixed.contains("same layout"),
            "{mixed}"
        );
        let norm = e(
            "norm.txt",
            "0 0 0 0 0 0 0 2\n1 1 0 0 0 0 0 1\n2 2 0 0 0 0 0 1\n",
        );
        assert!(
            norm.contains("norm.txt:1") && norm.contains("norm 2.0000"),
            "{norm}"
        );
        // KITTI's camera convention: the track runs along z.
        let camera: String = (0..3)
            .map(|k| format!("1 0 0 0 0 1 0 0 0 0 1 {}\n", 6 * k))
            .collect();
        let camera = e("camera.txt", &camera);
        assert!(
            camera.contains("camera.txt:3") && camera.contains("along z"),
            "{camera}"
        );
        let up = e("up.txt", "0 0 -1 0 0 1 0 0 1 0 0 0\n");
        assert!(
            up.contains("up.txt:1") && up.contains("x axis points along z"),
            "{up}"
        );
        let bad = e("bad.txt", "0 0 0 0 0 0 0 x\n");
        assert!(bad.contains("bad.txt:1") && bad.contains("qw `x`"), "{bad}");
    }

    #[test]
    fn random_odometry_drift_stays_within_its_bounds_and_repeats_with_its_seed() {
        let truth: Vec<Pose2> = (0..30)
            .map(|i| Pose2 {
                x: 12.0 * i as f64,
                y: (i as f64 * 0.3).sin() * 20.0,
                yaw_rad: i as f64 * 0.05,
            })
            .collect();
        let (scale, yaw) = (0.02, 1f64.to_radians() / 50.0);
        let a = randomly_drifted_odometry(&truth, scale, yaw, 5);
        assert_eq!(a, randomly_drifted_odometry(&truth, scale, yaw, 5));
        assert_ne!(a, randomly_drifted_odometry(&truth, scale, yaw, 6));
        let (mut larger, mut smaller) = (0, 0);
        for i in 1..truth.len() {
            let (t, o) = (step_into(&truth, i).unwrap(), step_into(&a, i).unwrap());
            let (dt, d_o) = (t.x.hypot(t.y), o.x.hypot(o.y));
            assert!((d_o / dt - 1.0).abs() <= scale + 1e-9, "step {i}");
            assert!(
                angle_diff(o.yaw_rad, t.yaw_rad).abs() <= yaw * dt + 1e-9,
                "step {i}"
            );
            if d_o > dt {
                larger += 1;
            } else {
                smaller += 1;
            }
        }
        // Drawn per step: some steps too long, some too short (a systematic drift: all alike).
        assert!(larger > 3 && smaller > 3, "{larger} {smaller}");
    }
}
