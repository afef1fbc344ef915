//! Localization along a track: candidates of consecutive scans tied by odometry (issue 15).
//!
//! A robot rarely has one scan. Every scan is searched alone over the whole map; its states
//! are its best candidates plus the previous scan's states carried forward by the odometry
//! step and refined on its own walls (so a place that one scan cannot single out is still
//! followed). Scan i's candidates are then ranked by the cheapest chain of states through
//! the window of scans i−K+1 … i whose consecutive steps agree with the odometry within a
//! gate (a Viterbi pass over at most 40 states per scan): the longest consistent chain
//! first, then the smallest mean cost. Odometry drifts (2 % of the distance and 1° per 50 m
//! assumed), so the gate grows with the step length; the odometry constrains, it does not
//! dictate. A first version searched the window's segments as one scan (slower, and its top-1
//! was worse: README).
//!
//! Odometry files have one line per scan, `x_m y_m yaw_rad` (optionally preceded by the scan
//! file name, which must then match), in any local frame; `#` starts a comment.

use crate::pipeline::{Candidate, Localization, Localizer, ScanSegments};
use crate::rank::confidence;
use crate::refine::refine_pose;
use crate::{LocalizeError, Pose2, Result};
use rayon::prelude::*;
use std::path::Path;

/// Reads an odometry file for scans named `names` (in order): one pose per scan.
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
    let mut last_line = 0;
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        last_line = line_no;
        let fields: Vec<&str> = line.split_whitespace().collect();
        let (name, numbers) = match fields.len() {
            3 => (None, &fields[..]),
            4 => (Some(fields[0]), &fields[1..]),
            n => {
                return Err(err(
                    line_no,
                    format!("{n} fields; expected `x_m y_m yaw_rad` or `scan x_m y_m yaw_rad`"),
                ))
            }
        };
        let mut v = [0.0; 3];
        for (k, (f, what)) in numbers.iter().zip(["x_m", "y_m", "yaw_rad"]).enumerate() {
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
        poses.push(Pose2 {
            x: v[0],
            y: v[1],
            yaw_rad: v[2],
        });
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
    Ok(poses)
}

/// The odometry drift the track targets assume: 2 % of the distance travelled.
pub const ODOMETRY_SCALE_DRIFT: f64 = 0.02;
/// The odometry heading drift the track targets assume, degrees per 50 m travelled.
pub const ODOMETRY_YAW_DRIFT_DEG_PER_50M: f64 = 1.0;

/// Odometry from true poses with drift: every step's translation scaled by `1 + scale_error`
/// and its heading turned by `yaw_rad_per_m` per metre travelled (a systematic drift, the
/// worst case of a random one), starting at the origin.
pub fn drifted_odometry(truth: &[Pose2], scale_error: f64, yaw_rad_per_m: f64) -> Vec<Pose2> {
    let mut out = Vec::with_capacity(truth.len());
    let mut odo = Pose2 {
        x: 0.0,
        y: 0.0,
        yaw_rad: 0.0,
    };
    for (i, t) in truth.iter().enumerate() {
        if i > 0 {
            let rel = truth[i - 1].inverse().compose(t);
            let d = rel.x.hypot(rel.y);
            let step = Pose2 {
                x: rel.x * (1.0 + scale_error),
                y: rel.y * (1.0 + scale_error),
                yaw_rad: rel.yaw_rad + yaw_rad_per_m * d,
            };
            odo = odo.compose(&step);
        }
        out.push(odo);
    }
    out
}

/// How the candidates of consecutive scans are tied by odometry in [`Localizer::localize_track`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackOptions {
    /// Scans per window (the scan and the K − 1 before it).
    pub window: usize,
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
}

impl Default for TrackOptions {
    fn default() -> Self {
        TrackOptions {
            window: 5,
            own_states: 20,
            carried_states: 20,
            gate_m: 1.5,
            gate_per_m: 0.05,
            gate_rad: 3f64.to_radians(),
            gate_rad_per_m: 4f64.to_radians() / 50.0,
        }
    }
}

impl Localizer<'_> {
    /// Localizes every scan of a track (segments per scan, sensor frame) with the window of
    /// `options.window` scans ending at it: every scan is searched alone, the states of each
    /// scan are its best candidates plus the previous scan's states carried forward by the
    /// odometry and refined on its walls, and a scan's candidates are ranked by the cheapest
    /// chain of states through its window whose consecutive steps agree with the odometry
    /// within the gates (the sum of the scans' costs along the chain; a Viterbi pass).
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
        let o = &self.options;
        let mut out: Vec<Localization> = Vec::with_capacity(scans.len());
        let mut states: Vec<Vec<Candidate>> = Vec::with_capacity(scans.len());
        for (i, scan) in scans.iter().enumerate() {
            let segs = &scan.segments;
            let single = self.localize_segments_seen_from(segs, &[[0.0, 0.0]]);
            let t = std::time::Instant::now();
            let mut mine: Vec<Candidate> = single
                .candidates
                .iter()
                .take(options.own_states)
                .copied()
                .collect();
            if i > 0 && !segs.is_empty() {
                let step = odometry[i - 1].inverse().compose(&odometry[i]);
                let carried: Vec<Candidate> = states[i - 1]
                    .iter()
                    .take(options.carried_states)
                    .map(|prev| prev.pose.compose(&step))
                    .filter(|p| {
                        !mine.iter().any(|c| {
                            c.pose.distance_to(p) < o.distinct_m
                                && c.pose.yaw_error_to(p) < o.distinct_rad
                        })
                    })
                    .collect::<Vec<Pose2>>()
                    .into_par_iter()
                    .filter_map(|p| {
                        let visible = self.visible_from_views(&p, &[[0.0, 0.0]]);
                        let pose = refine_pose(segs, &visible, p, &o.refine);
                        self.pose_allowed(&pose).then(|| Candidate {
                            pose,
                            costs: self.costs_at(segs, pose, f64::INFINITY),
                            refined: true,
                            confidence: 0.0,
                        })
                    })
                    .collect();
                mine.extend(carried);
            }
            self.sort(&mut mine);
            states.push(mine);
            let ranked = self
                .chain_rank(&states, odometry, i, options)
                .into_iter()
                .map(|(c, _)| c)
                .collect();
            let mut result = single;
            result.candidates = ranked;
            let poses: Vec<Pose2> = result.candidates.iter().map(|c| c.pose).collect();
            // Confidence from the chain costs (stored in `confidence` by chain_rank, lower is better).
            let chain: Vec<f64> = result.candidates.iter().map(|c| c.confidence).collect();
            result.confidence = if chain.is_empty() {
                0.0
            } else {
                confidence(&chain, &poses, o.distinct_m, o.distinct_rad)
            };
            for c in &mut result.candidates {
                c.confidence = 0.0;
            }
            if let Some(first) = result.candidates.first_mut() {
                first.confidence = result.confidence;
            }
            result.seconds.refine += t.elapsed().as_secs_f64();
            result.seconds.total += t.elapsed().as_secs_f64();
            result.record_extraction(scan);
            out.push(result);
        }
        Ok(out)
    }

    /// Scan i's states ranked by the cheapest gated chain through its window; each returned
    /// candidate's `confidence` holds its chain cost (mean cost per scan of the chain).
    fn chain_rank(
        &self,
        states: &[Vec<Candidate>],
        odometry: &[Pose2],
        i: usize,
        options: &TrackOptions,
    ) -> Vec<(Candidate, usize)> {
        let kind = self.options.rank_by;
        let start = (i + 1).saturating_sub(options.window.max(1));
        // best[s]: cheapest chain cost ending in state s of scan j, and its length.
        let mut best: Vec<(f64, usize)> = states[start]
            .iter()
            .map(|c| (c.costs.get(kind), 1))
            .collect();
        for j in start + 1..=i {
            let step = odometry[j - 1].inverse().compose(&odometry[j]);
            let len = step.x.hypot(step.y);
            let gate_m = options.gate_m + options.gate_per_m * len;
            let gate_rad = options.gate_rad + options.gate_rad_per_m * len;
            let next: Vec<(f64, usize)> = states[j]
                .iter()
                .map(|c| {
                    let own = c.costs.get(kind);
                    let mut b = (own, 1);
                    for (prev, &(cost, n)) in states[j - 1].iter().zip(&best) {
                        let pred = prev.pose.compose(&step);
                        if pred.distance_to(&c.pose) <= gate_m
                            && pred.yaw_error_to(&c.pose) <= gate_rad
                        {
                            let total = cost + own;
                            // Longer consistent chains win; among equals, the cheaper.
                            if n + 1 > b.1 || (n + 1 == b.1 && total < b.0) {
                                b = (total, n + 1);
                            }
                        }
                    }
                    b
                })
                .collect();
            best = next;
        }
        let mut order: Vec<usize> = (0..states[i].len()).collect();
        let key = |s: usize| {
            let (cost, n) = best[s];
            (std::cmp::Reverse(n), cost / n as f64)
        };
        order.sort_by(|&a, &b| {
            let (na, ca) = key(a);
            let (nb, cb) = key(b);
            na.cmp(&nb).then(ca.total_cmp(&cb))
        });
        order
            .into_iter()
            .map(|s| {
                let mut c = states[i][s];
                let (cost, n) = best[s];
                c.confidence = cost / n as f64;
                (c, n)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(x: f64, y: f64, yaw_rad: f64) -> Pose2 {
        Pose2 { x, y, yaw_rad }
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
}
