//! Poses from a bag: `nav_msgs/msg/Odometry`, `geometry_msgs/msg/PoseStamped` and
//! `tf2_msgs/msg/TFMessage` messages decoded from CDR (only the fields up to the pose are
//! read; covariances and twists are skipped).
//!
//! ```text
//! Odometry          header, string child_frame_id, pose.pose {position xyz f64, orientation xyzw f64}, …
//! PoseStamped       header, pose {position, orientation}
//! TFMessage         sequence<TransformStamped>: header, string child_frame_id,
//!                   transform {translation xyz f64, rotation xyzw f64}
//! header            stamp {int32 sec, uint32 nanosec}, string frame_id
//! ```

use super::cdr::{Cdr, CdrResult};
use serde::Serialize;

/// The schema name of ROS 2 odometry messages.
pub const ODOMETRY: &str = "nav_msgs/msg/Odometry";
/// The schema name of ROS 2 stamped poses.
pub const POSE_STAMPED: &str = "geometry_msgs/msg/PoseStamped";
/// The schema name of ROS 2 transform trees (`/tf`, `/tf_static`).
pub const TF_MESSAGE: &str = "tf2_msgs/msg/TFMessage";

/// The schemas [`super::read_bag_poses`] decodes.
pub const POSE_SCHEMAS: [&str; 3] = [ODOMETRY, POSE_STAMPED, TF_MESSAGE];

/// One stamped pose of a bag: the transform from `child_frame_id` to `frame_id`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BagPose {
    /// `header.stamp` in nanoseconds since the epoch.
    pub stamp_ns: i64,
    /// The message's log time in the bag, nanoseconds since the epoch.
    pub log_time_ns: u64,
    /// The parent frame (`header.frame_id`, e.g. `odom`, `map`).
    pub frame_id: String,
    /// The moving frame (`child_frame_id`; empty for PoseStamped).
    pub child_frame_id: String,
    /// Position of the child frame's origin in the parent frame, metres.
    pub translation: [f64; 3],
    /// Orientation as a unit quaternion `[x, y, z, w]`.
    pub rotation: [f64; 4],
}

impl BagPose {
    /// Heading about the parent frame's z axis, radians (from the quaternion, any roll/pitch).
    pub fn yaw(&self) -> f64 {
        let [x, y, z, w] = self.rotation;
        (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
    }
}

/// The pose at `t_ns` (a stamp) on a track sorted by stamp: linear in the translation and
/// spherical-linear in the rotation between the two stamps around it; `None` outside the
/// track, or more than `max_gap_ns` from both neighbours.
pub fn interpolate(track: &[BagPose], t_ns: i64, max_gap_ns: i64) -> Option<BagPose> {
    let after = track.partition_point(|p| p.stamp_ns < t_ns);
    let b = track.get(after)?;
    if b.stamp_ns == t_ns {
        return Some(b.clone());
    }
    let a = track.get(after.checked_sub(1)?)?;
    if t_ns - a.stamp_ns > max_gap_ns && b.stamp_ns - t_ns > max_gap_ns {
        return None;
    }
    let s = (t_ns - a.stamp_ns) as f64 / (b.stamp_ns - a.stamp_ns) as f64;
    let lerp = |x: f64, y: f64| x + s * (y - x);
    Some(BagPose {
        stamp_ns: t_ns,
        log_time_ns: a.log_time_ns,
        frame_id: a.frame_id.clone(),
        child_frame_id: a.child_frame_id.clone(),
        translation: std::array::from_fn(|i| lerp(a.translation[i], b.translation[i])),
        rotation: slerp(a.rotation, b.rotation, s),
    })
}

/// Spherical linear interpolation of unit quaternions (the shorter arc).
fn slerp(a: [f64; 4], b: [f64; 4], s: f64) -> [f64; 4] {
    let mut dot: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
    let b = if dot < 0.0 {
        dot = -dot;
        b.map(|v| -v)
    } else {
        b
    };
    let (wa, wb) = if dot > 0.9995 {
        (1.0 - s, s)
    } else {
        let theta = dot.clamp(-1.0, 1.0).acos();
        let sin = theta.sin();
        (((1.0 - s) * theta).sin() / sin, (s * theta).sin() / sin)
    };
    let q: [f64; 4] = std::array::from_fn(|i| wa * a[i] + wb * b[i]);
    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    q.map(|v| v / norm)
}

impl BagPose {
    /// The rotation as a row-major 3×3 matrix.
    pub fn matrix(&self) -> [[f64; 3]; 3] {
        let [x, y, z, w] = self.rotation;
        [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - z * w),
                2.0 * (x * z + y * w),
            ],
            [
                2.0 * (x * y + z * w),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - x * w),
            ],
            [
                2.0 * (x * z - y * w),
                2.0 * (y * z + x * w),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ]
    }

    /// A point of the child frame in the parent frame.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let m = self.matrix();
        std::array::from_fn(|i| {
            m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2] + self.translation[i]
        })
    }
}

fn header(c: &mut Cdr<'_>) -> CdrResult<(i64, String)> {
    let stamp = c.time_ns("header.stamp")?;
    let frame = c.string("header.frame_id")?;
    Ok((stamp, frame))
}

fn xyz(c: &mut Cdr<'_>, field: &'static str) -> CdrResult<[f64; 3]> {
    Ok([c.f64(field)?, c.f64(field)?, c.f64(field)?])
}

fn xyzw(c: &mut Cdr<'_>, field: &'static str) -> CdrResult<[f64; 4]> {
    Ok([c.f64(field)?, c.f64(field)?, c.f64(field)?, c.f64(field)?])
}

/// Decodes the poses of one message of a schema in [`POSE_SCHEMAS`] (a TFMessage may hold
/// several); `None` for another schema.
pub(super) fn decode_poses(
    schema: &str,
    message: &[u8],
    log_time_ns: u64,
) -> CdrResult<Option<Vec<BagPose>>> {
    let mut c = Cdr::new(message)?;
    let pose = |c: &mut Cdr<'_>, stamp_ns, frame_id, child_frame_id| -> CdrResult<BagPose> {
        Ok(BagPose {
            stamp_ns,
            log_time_ns,
            frame_id,
            child_frame_id,
            translation: xyz(c, "the position")?,
            rotation: xyzw(c, "the orientation")?,
        })
    };
    Ok(Some(match schema {
        ODOMETRY => {
            let (stamp, frame) = header(&mut c)?;
            let child = c.string("child_frame_id")?;
            vec![pose(&mut c, stamp, frame, child)?]
        }
        POSE_STAMPED => {
            let (stamp, frame) = header(&mut c)?;
            vec![pose(&mut c, stamp, frame, String::new())?]
        }
        TF_MESSAGE => {
            let n = c.u32("the transform count")?;
            let mut out = Vec::new();
            // Each transform takes ≥ 72 bytes: a count beyond the message ends in an error.
            for _ in 0..n {
                let (stamp, frame) = header(&mut c)?;
                let child = c.string("child_frame_id")?;
                out.push(pose(&mut c, stamp, frame, child)?);
            }
            out
        }
        _ => return Ok(None),
    }))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    /// CDR little-endian writer for the tests.
    struct W(Vec<u8>);
    impl W {
        fn new() -> Self {
            W(vec![0, 1, 0, 0])
        }
        fn align(&mut self, n: usize) {
            while (self.0.len() - 4) % n != 0 {
                self.0.push(0);
            }
        }
        fn u32(&mut self, v: u32) {
            self.align(4);
            self.0.extend(v.to_le_bytes());
        }
        fn f64(&mut self, v: f64) {
            self.align(8);
            self.0.extend(v.to_le_bytes());
        }
        fn string(&mut self, s: &str) {
            self.u32(s.len() as u32 + 1);
            self.0.extend(s.as_bytes());
            self.0.push(0);
        }
        fn header(&mut self, sec: i32, nsec: u32, frame: &str) {
            self.u32(sec as u32);
            self.u32(nsec);
            self.string(frame);
        }
        fn pose(&mut self, t: [f64; 3], q: [f64; 4]) {
            t.iter().chain(q.iter()).for_each(|&v| self.f64(v));
        }
    }

    fn quat(yaw: f64) -> [f64; 4] {
        [0.0, 0.0, (yaw / 2.0).sin(), (yaw / 2.0).cos()]
    }

    #[test]
    fn odometry_pose_stamped_and_tf_decode() {
        let mut w = W::new();
        w.header(10, 5, "odom");
        w.string("base_link");
        w.pose([1.0, 2.0, 3.0], quat(0.5));
        for _ in 0..36 {
            w.f64(0.0); // covariance, not read
        }
        let p = decode_poses(ODOMETRY, &w.0, 7).unwrap().unwrap();
        assert_eq!(p.len(), 1);
        assert_eq!(p[0].stamp_ns, 10_000_000_005);
        assert_eq!(
            (p[0].frame_id.as_str(), p[0].child_frame_id.as_str()),
            ("odom", "base_link")
        );
        assert_eq!(p[0].translation, [1.0, 2.0, 3.0]);
        assert!((p[0].yaw() - 0.5).abs() < 1e-12);

        let mut w = W::new();
        w.header(1, 0, "map");
        w.pose([4.0, 5.0, 6.0], quat(-2.0));
        let p = decode_poses(POSE_STAMPED, &w.0, 0).unwrap().unwrap();
        assert_eq!(p[0].translation, [4.0, 5.0, 6.0]);
        assert!((p[0].yaw() + 2.0).abs() < 1e-12);

        let mut w = W::new();
        w.u32(2);
        for (i, child) in ["base_link", "velodyne"].iter().enumerate() {
            w.header(3, 0, "odom");
            w.string(child);
            w.pose([i as f64, 0.0, 0.0], quat(0.1 * i as f64));
        }
        let p = decode_poses(TF_MESSAGE, &w.0, 0).unwrap().unwrap();
        assert_eq!(p.len(), 2);
        assert_eq!(p[1].child_frame_id, "velodyne");
        assert!((p[1].yaw() - 0.1).abs() < 1e-12);

        assert!(decode_poses("std_msgs/msg/String", &w.0, 0)
            .unwrap()
            .is_none());
    }

    fn at(stamp_ns: i64, x: f64, yaw: f64) -> BagPose {
        BagPose {
            stamp_ns,
            log_time_ns: 0,
            frame_id: "odom".into(),
            child_frame_id: "base_link".into(),
            translation: [x, 2.0 * x, 0.0],
            rotation: quat(yaw),
        }
    }

    #[test]
    fn interpolation_and_transforms() {
        let track = [at(0, 0.0, 0.0), at(10, 1.0, 1.0), at(20, 3.0, -3.0)];
        let p = interpolate(&track, 5, 100).unwrap();
        assert!((p.translation[0] - 0.5).abs() < 1e-12 && (p.translation[1] - 1.0).abs() < 1e-12);
        assert!((p.yaw() - 0.5).abs() < 1e-12);
        // −3 rad and 1 rad are 2.28 rad apart the short way round (through ±π).
        let q = interpolate(&track, 15, 100).unwrap();
        let mid = 1.0 + 0.5 * (2.0 * std::f64::consts::PI - 4.0);
        assert!((q.yaw() - mid).abs() < 1e-9, "{}", q.yaw());
        assert_eq!(interpolate(&track, 10, 100).unwrap(), track[1]);
        assert!(interpolate(&track, -1, 100).is_none());
        assert!(interpolate(&track, 21, 100).is_none());
        assert!(interpolate(&track, 5, 4).is_none());
        let r = at(0, 1.0, std::f64::consts::FRAC_PI_2);
        let p = r.apply([1.0, 0.0, 0.5]);
        assert!(
            (p[0] - 1.0).abs() < 1e-12 && (p[1] - 3.0).abs() < 1e-12 && (p[2] - 0.5).abs() < 1e-12
        );
    }

    #[test]
    fn truncated_and_lying_messages_are_errors() {
        let mut w = W::new();
        w.header(10, 5, "odom");
        w.string("base_link");
        w.pose([1.0, 2.0, 3.0], quat(0.5));
        for cut in [0, 3, 10, 20, w.0.len() - 1] {
            assert!(decode_poses(ODOMETRY, &w.0[..cut], 0).is_err(), "cut {cut}");
        }
        let mut w = W::new();
        w.u32(u32::MAX); // claims 4 G transforms
        w.header(1, 0, "odom");
        assert!(decode_poses(TF_MESSAGE, &w.0, 0).is_err());
    }
}
