//! Track poses as trajectory files that `evo` and other odometry tools read: TUM (one line
//! `timestamp tx ty tz qx qy qz qw` per pose) and KITTI (one line per pose, the 12 numbers
//! of the row-major 3×4 matrix `[R | t]`).
//!
//! Poses are in the map's local frame (x east, y north, z up, metres); z is 0 (planar
//! localization) and the rotation is the heading about z (counter-clockwise from grid east).
//! KITTI files have no timestamps: they list the localized scans in order.

use crate::report::TrackReport;
use crate::Pose2;

/// A planar pose at a time (seconds, or the scan's index when the sequence has no times).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StampedPose {
    /// Seconds, or the scan index.
    pub time: f64,
    /// The pose in the map's local frame.
    pub pose: Pose2,
}

/// The unit quaternion `[qx, qy, qz, qw]` of a rotation by `yaw_rad` about z.
pub fn yaw_quaternion(yaw_rad: f64) -> [f64; 4] {
    let (s, c) = (0.5 * yaw_rad).sin_cos();
    [0.0, 0.0, s, c]
}

/// The row-major 3×4 matrix `[R | t]` of a planar pose (z = 0).
pub fn pose_matrix(pose: &Pose2) -> [f64; 12] {
    let (s, c) = pose.yaw_rad.sin_cos();
    [
        c, -s, 0.0, pose.x, //
        s, c, 0.0, pose.y, //
        0.0, 0.0, 1.0, 0.0,
    ]
}

/// The best pose of every scan of a track that has a listed candidate, stamped with the
/// scan's 0-based index (track folders have no times), in the map's local frame.
pub fn track_poses(report: &TrackReport) -> Vec<StampedPose> {
    report
        .scans
        .iter()
        .enumerate()
        .filter_map(|(i, r)| {
            r.candidates.first().map(|c| StampedPose {
                time: i as f64,
                pose: Pose2 {
                    x: c.x,
                    y: c.y,
                    yaw_rad: c.yaw_grid,
                },
            })
        })
        .collect()
}

/// The TUM trajectory file of the poses: one line `timestamp tx ty tz qx qy qz qw` each.
pub fn tum_lines(poses: &[StampedPose]) -> String {
    let mut out = String::new();
    for p in poses {
        let q = yaw_quaternion(p.pose.yaw_rad);
        out.push_str(&format!(
            "{:.6} {:.6} {:.6} {:.6} {:.9} {:.9} {:.9} {:.9}\n",
            p.time, p.pose.x, p.pose.y, 0.0, q[0], q[1], q[2], q[3]
        ));
    }
    out
}

/// The KITTI trajectory file of the poses: the 12 numbers of `[R | t]` per line, row-major.
pub fn kitti_lines(poses: &[StampedPose]) -> String {
    let mut out = String::new();
    for p in poses {
        let m = pose_matrix(&p.pose);
        let fields: Vec<String> = m
            .iter()
            .enumerate()
            .map(|(k, v)| {
                if k % 4 == 3 {
                    format!("{v:.6}")
                } else {
                    format!("{v:.9}")
                }
            })
            .collect();
        out.push_str(&fields.join(" "));
        out.push('\n');
    }
    out
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    fn poses() -> Vec<StampedPose> {
        [
            (0.0, 1.5, -2.25, 0.0),
            (1.0, 100.0, 50.0, 2.5),
            (2.0, -3.0, 7.0, -3.0),
        ]
        .iter()
        .map(|&(time, x, y, yaw_rad)| StampedPose {
            time,
            pose: Pose2 { x, y, yaw_rad },
        })
        .collect()
    }

    fn numbers(line: &str) -> Vec<f64> {
        line.split_whitespace()
            .map(|f| f.parse::<f64>().unwrap())
            .collect()
    }

    fn same_yaw(a: f64, b: f64) -> bool {
        crate::angle_diff(a, b) < 1e-8
    }

    #[test]
    fn tum_parses_back_to_the_poses() {
        let text = tum_lines(&poses());
        assert_eq!(text.lines().count(), 3);
        for (line, p) in text.lines().zip(poses()) {
            let n = numbers(line);
            assert_eq!(n.len(), 8, "{line}");
            assert_eq!(n[0], p.time);
            assert!((n[1] - p.pose.x).abs() < 1e-6 && (n[2] - p.pose.y).abs() < 1e-6);
            assert_eq!(n[3], 0.0);
            let norm = n[4..8].iter().map(|v| v * v).sum::<f64>();
            assert!((norm - 1.0).abs() < 1e-8, "{norm}");
            assert_eq!((n[4], n[5]), (0.0, 0.0));
            let yaw = 2.0 * n[6].atan2(n[7]);
            assert!(same_yaw(yaw, p.pose.yaw_rad), "{yaw} vs {}", p.pose.yaw_rad);
        }
    }

    #[test]
    fn kitti_parses_back_to_rotation_matrices() {
        let text = kitti_lines(&poses());
        for (line, p) in text.lines().zip(poses()) {
            let n = numbers(line);
            assert_eq!(n.len(), 12, "{line}");
            // Orthonormal rotation about z, det 1.
            let r = [[n[0], n[1], n[2]], [n[4], n[5], n[6]], [n[8], n[9], n[10]]];
            for i in 0..3 {
                for j in 0..3 {
                    let dot: f64 = (0..3).map(|k| r[i][k] * r[j][k]).sum();
                    assert!((dot - f64::from(u8::from(i == j))).abs() < 1e-8);
                }
            }
            assert_eq!((r[2][2], n[11]), (1.0, 0.0));
            assert!(same_yaw(r[1][0].atan2(r[0][0]), p.pose.yaw_rad));
            assert!((n[3] - p.pose.x).abs() < 1e-6 && (n[7] - p.pose.y).abs() < 1e-6);
            // The matrix maps a sensor point like the pose does.
            let q = [2.0, -1.0];
            let m = [
                n[0] * q[0] + n[1] * q[1] + n[3],
                n[4] * q[0] + n[5] * q[1] + n[7],
            ];
            let want = p.pose.apply(q);
            assert!((m[0] - want[0]).abs() < 1e-6 && (m[1] - want[1]).abs() < 1e-6);
        }
    }

    #[test]
    fn quaternion_and_matrix_agree() {
        for yaw in [-3.0, -1.0, 0.0, 0.7, 3.1] {
            let [_, _, z, w] = yaw_quaternion(yaw);
            let m = pose_matrix(&Pose2 {
                x: 0.0,
                y: 0.0,
                yaw_rad: yaw,
            });
            // R from the quaternion (about z): cos = w² − z², sin = 2wz.
            assert!((m[0] - (w * w - z * z)).abs() < 1e-12);
            assert!((m[4] - 2.0 * w * z).abs() < 1e-12);
        }
    }

    #[test]
    fn track_poses_skip_scans_without_a_candidate() {
        let map = crate::geojson::tests::map();
        let report = crate::geojson::tests::track_report(&map);
        let p = track_poses(&report);
        let times: Vec<f64> = p.iter().map(|s| s.time).collect();
        assert_eq!(times, [0.0, 2.0, 3.0]);
        assert!((p[2].pose.yaw_rad + 0.3).abs() < 1e-12);
        assert!((p[1].pose.x - 10.0).abs() < 1e-12);
    }
}
