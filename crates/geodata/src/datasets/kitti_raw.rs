//! KITTI raw (Geiger et al., IJRR 2013) drives: Velodyne HDL-64E scans with the OXTS
//! GPS/IMU record of each frame and the IMU → Velodyne calibration. No labels.
//!
//! Layout: `velodyne_points/NNNNNNNNNN.bin`, `oxts/NNNNNNNNNN.txt` (30 values: lat lon alt
//! roll pitch yaw …, see `oxts/dataformat.txt`), `calib/calib_imu_to_velo.txt` (`R:` 9
//! values, `T:` 3 values: x_velo = R·x_imu + T).
//!
//! Pose, after the devkit's `convertOxtsToPose.m`: the world frame is a scaled Mercator
//! whose scale *and origin* are frame 0's latitude/longitude, with z = alt − alt₀;
//! world_T_imu = [Rz(yaw)·Ry(pitch)·Rx(roll) | (x, y, z)], and world_T_velo =
//! world_T_imu · (velo_T_imu)⁻¹. Unlike the devkit, poses are not premultiplied by the
//! inverse of frame 0's pose, so world x stays east and y north (a georeferenced frame).

use super::{check_rotation, floats, frames_in, iso_from_rows, read_text};
use super::{DatasetError, Georeference, LidarSequence, Result, Scan, SequenceKind};
use crate::cloud::kitti::read_kitti_bin;
use crate::cloud::ReadOptions;
use crate::mercator::ScaledMercator;
use nalgebra::{Isometry3, Matrix4, Translation3, UnitQuaternion};
use std::path::{Path, PathBuf};

/// The navigation part of one OXTS record.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OxtsRecord {
    /// Latitude of the OXTS unit, degrees.
    pub lat_deg: f64,
    /// Longitude of the OXTS unit, degrees.
    pub lon_deg: f64,
    /// Altitude, metres.
    pub alt_m: f64,
    /// Roll, radians (0 = level, positive = left side up).
    pub roll_rad: f64,
    /// Pitch, radians (0 = level, positive = front down).
    pub pitch_rad: f64,
    /// Heading, radians (0 = east, positive counter-clockwise).
    pub yaw_rad: f64,
}

/// Reads an OXTS record file (one line of 30 numbers; the first six are used).
pub fn read_oxts(path: &Path) -> Result<OxtsRecord> {
    let text = read_text(path)?;
    let line = text.lines().next().unwrap_or("");
    let v = floats(path, 1, line, ' ')?;
    if v.len() < 25 {
        return Err(DatasetError::Parse {
            path: path.to_path_buf(),
            line: 1,
            message: format!(
                "an OXTS record has 30 values (at least 25), found {}",
                v.len()
            ),
        });
    }
    let g = |k: usize| v.get(k).copied().unwrap_or(0.0);
    Ok(OxtsRecord {
        lat_deg: g(0),
        lon_deg: g(1),
        alt_m: g(2),
        roll_rad: g(3),
        pitch_rad: g(4),
        yaw_rad: g(5),
    })
}

/// Reads a KITTI `R: …` / `T: …` calibration file as the transform it describes (to ← from).
pub fn read_calib_rt(path: &Path) -> Result<Isometry3<f64>> {
    let text = read_text(path)?;
    let mut r = None;
    let mut t = None;
    for (i, line) in text.lines().enumerate() {
        if let Some(rest) = line.strip_prefix("R:") {
            r = Some((i + 1, floats(path, i + 1, rest, ' ')?));
        } else if let Some(rest) = line.strip_prefix("T:") {
            t = Some((i + 1, floats(path, i + 1, rest, ' ')?));
        }
    }
    let missing = |what: &str| DatasetError::Parse {
        path: path.to_path_buf(),
        line: text.lines().count(),
        message: format!(
            "no {what} line with {} values",
            if what == "R:" { 9 } else { 3 }
        ),
    };
    let (r_line, r) = r
        .filter(|(_, r)| r.len() == 9)
        .ok_or_else(|| missing("R:"))?;
    let (_, t) = t
        .filter(|(_, t)| t.len() == 3)
        .ok_or_else(|| missing("T:"))?;
    let mut m = Matrix4::identity();
    for (k, x) in r.iter().enumerate() {
        m[(k / 3, k % 3)] = *x;
    }
    for (k, x) in t.iter().enumerate() {
        m[(k, 3)] = *x;
    }
    check_rotation(&m, path, r_line, 1e-4)?;
    Ok(iso_from_rows(&m))
}

/// world_T_imu of an OXTS record in `georef`'s world, z relative to `alt0_m`.
pub fn world_from_imu(georef: &ScaledMercator, oxts: &OxtsRecord, alt0_m: f64) -> Isometry3<f64> {
    let [x, y] = georef.to_world(oxts.lat_deg, oxts.lon_deg);
    let rotation = UnitQuaternion::from_euler_angles(oxts.roll_rad, oxts.pitch_rad, oxts.yaw_rad);
    Isometry3::from_parts(Translation3::new(x, y, oxts.alt_m - alt0_m), rotation)
}

/// One KITTI raw drive directory (`*_sync` layout flattened as in the shared data).
#[derive(Debug, Clone)]
pub struct KittiRawDrive {
    dir: PathBuf,
    imu_from_velo: Isometry3<f64>,
    first: OxtsRecord,
    georef: ScaledMercator,
}

impl KittiRawDrive {
    /// Opens `dir`: reads the IMU → Velodyne calibration and frame 0's OXTS record.
    pub fn open(dir: impl AsRef<Path>) -> Result<Self> {
        let dir = dir.as_ref().to_path_buf();
        let velo_from_imu = read_calib_rt(&dir.join("calib").join("calib_imu_to_velo.txt"))?;
        let first_frame = frames_in(&dir.join("oxts"), "txt")?
            .first()
            .copied()
            .unwrap_or(0);
        let first = read_oxts(&dir.join("oxts").join(format!("{first_frame:010}.txt")))?;
        let georef = ScaledMercator::new(first.lat_deg, first.lon_deg)?;
        Ok(Self {
            dir,
            imu_from_velo: velo_from_imu.inverse(),
            first,
            georef,
        })
    }

    /// Frame numbers that have a scan file, sorted.
    pub fn frames(&self) -> Result<Vec<u64>> {
        frames_in(&self.dir.join("velodyne_points"), "bin")
    }

    /// The georeference of the world frame (origin and scale from the first OXTS record).
    pub fn georef(&self) -> ScaledMercator {
        self.georef
    }

    /// The OXTS record of a frame.
    pub fn oxts(&self, frame: u64) -> Result<OxtsRecord> {
        read_oxts(&self.dir.join("oxts").join(format!("{frame:010}.txt")))
    }

    /// world_T_imu of a frame.
    pub fn world_from_imu(&self, frame: u64) -> Result<Isometry3<f64>> {
        Ok(world_from_imu(
            &self.georef,
            &self.oxts(frame)?,
            self.first.alt_m,
        ))
    }

    /// world_T_velodyne of a frame.
    pub fn world_from_velodyne(&self, frame: u64) -> Result<Isometry3<f64>> {
        Ok(self.world_from_imu(frame)? * self.imu_from_velo)
    }

    /// Loads a scan (no labels) with its Velodyne pose.
    pub fn load_scan(&self, frame: u64) -> Result<Scan> {
        let path = self
            .dir
            .join("velodyne_points")
            .join(format!("{frame:010}.bin"));
        let (cloud, _) = read_kitti_bin(&path, &ReadOptions::default())?;
        let world_from_sensor = self.world_from_velodyne(frame)?;
        Ok(Scan {
            frame,
            path,
            cloud,
            world_from_sensor,
            georef: Georeference::ScaledMercator(self.georef),
        })
    }
}

impl LidarSequence for KittiRawDrive {
    fn kind(&self) -> Option<SequenceKind> {
        Some(SequenceKind::KittiRaw)
    }

    fn name(&self) -> &'static str {
        SequenceKind::KittiRaw.name()
    }

    fn dir(&self) -> &Path {
        &self.dir
    }

    fn labelled(&self) -> bool {
        false
    }

    fn frames(&self) -> Result<Vec<u64>> {
        KittiRawDrive::frames(self)
    }

    /// Frames with an OXTS record.
    fn pose_frames(&self) -> Result<Vec<u64>> {
        frames_in(&self.dir.join("oxts"), "txt")
    }

    fn world_from_sensor(&self, frame: u64) -> Result<Isometry3<f64>> {
        self.world_from_velodyne(frame)
    }

    fn georeference(&self) -> Georeference {
        Georeference::ScaledMercator(self.georef)
    }

    fn load_scan(&self, frame: u64) -> Result<Scan> {
        KittiRawDrive::load_scan(self, frame)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn yaw_turns_the_imu_x_axis() {
        let g = ScaledMercator::new(49.0, 8.4).unwrap();
        let o = OxtsRecord {
            lat_deg: 49.0,
            lon_deg: 8.4,
            alt_m: 100.0,
            roll_rad: 0.0,
            pitch_rad: 0.0,
            yaw_rad: std::f64::consts::FRAC_PI_2,
        };
        let p = world_from_imu(&g, &o, 100.0);
        let x = p.rotation * nalgebra::Vector3::x();
        assert!((x.y - 1.0).abs() < 1e-12, "{x}");
        assert!(p.translation.vector.norm() < 1e-9);
    }
}
