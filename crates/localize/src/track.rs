//! Localization along a track: the scans of a sliding window, tied by odometry, are searched
//! as one scan (issue 15).
//!
//! A robot rarely has one scan. For scan i the window holds scans i−K+1 … i; each scan's
//! segments are moved into scan i's frame by the odometry between them, and the union is
//! localized by the single-scan chain (FDCM search over the whole map, then the costs, with
//! the map edges visible from any of the window's sensor positions). The window sees more
//! walls from more places than one scan, which singles out one place in streets of similar
//! houses. Odometry drifts (a few per cent of the distance): within a window of K scans
//! spaced d apart, the far scan's segments are off by about 0.02 · K · d, well inside the
//! chamfer search's tolerance for the windows used here (K · d ≤ 50 m).
//!
//! Odometry files have one line per scan, `x_m y_m yaw_rad` (optionally preceded by the scan
//! file name, which must then match), in any local frame; `#` starts a comment.

use crate::pipeline::{Localization, Localizer};
use crate::{LocalizeError, Pose2, Result, Segment};
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

/// The segments of the window of `window` scans ending at scan `i`, in scan i's frame, and
/// the window's sensor positions in that frame.
pub fn window_segments(
    segments: &[Vec<Segment>],
    odometry: &[Pose2],
    i: usize,
    window: usize,
) -> (Vec<Segment>, Vec<[f64; 2]>) {
    let start = (i + 1).saturating_sub(window.max(1));
    let to_ref = odometry[i].inverse();
    let mut segs = Vec::new();
    let mut views = Vec::new();
    for j in start..=i {
        let rel = to_ref.compose(&odometry[j]);
        segs.extend(segments[j].iter().map(|s| s.transformed(&rel)));
        views.push([rel.x, rel.y]);
    }
    (segs, views)
}

impl Localizer<'_> {
    /// Localizes every scan of a track (segments per scan, sensor frame) with the window of
    /// `window` scans ending at it.
    pub fn localize_track(
        &self,
        segments: &[Vec<Segment>],
        odometry: &[Pose2],
        window: usize,
    ) -> Result<Vec<Localization>> {
        if segments.len() != odometry.len() {
            return Err(LocalizeError::InvalidOption {
                name: "odometry",
                value: odometry.len() as f64,
                expected: "one odometry pose per scan",
            });
        }
        Ok((0..segments.len())
            .map(|i| {
                let (segs, views) = window_segments(segments, odometry, i, window);
                self.localize_segments_seen_from(&segs, &views)
            })
            .collect())
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
    fn exact_odometry_puts_the_window_in_the_reference_frame() {
        // Two poses of a robot seeing the same wall point; the window maps scan 0's
        // observation onto scan 1's.
        let truth = [p(10.0, 5.0, 0.3), p(18.0, 9.0, 0.9)];
        let wall = [25.0, 20.0];
        let seen: Vec<Vec<Segment>> = truth
            .iter()
            .map(|t| {
                let q = t.inverse().apply(wall);
                vec![Segment::new(q, [q[0] + 1.0, q[1]])]
            })
            .collect();
        let odo = drifted_odometry(&truth, 0.0, 0.0);
        let (segs, views) = window_segments(&seen, &odo, 1, 5);
        assert_eq!(segs.len(), 2);
        assert!((segs[0].a[0] - segs[1].a[0]).abs() < 1e-9);
        assert!((segs[0].a[1] - segs[1].a[1]).abs() < 1e-9);
        assert!(views[1][0].abs() < 1e-12 && views[1][1].abs() < 1e-12);
        let back = truth[1].inverse().apply([truth[0].x, truth[0].y]);
        assert!((views[0][0] - back[0]).abs() < 1e-9 && (views[0][1] - back[1]).abs() < 1e-9);
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
