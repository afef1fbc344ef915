//! KITTI-360 (Liao, Xie, Geiger, TPAMI 2022) sequence `2013_05_28_drive_0009`: Velodyne
//! HDL-64E scans with per-point semantic labels and velodyne → world poses.
//!
//! Layout: `velodyne_points/NNNNNNNNNN.bin` (f32 x y z reflectance), `gt_labels/NNNNNNNNNN.bin`
//! (u32 KITTI-360 semantic id per point, 65535 = unlabelled) and `velodyne_poses*.txt`
//! (`frame r11 r12 r13 tx r21 … tz [0 0 0 1]`, row-major world_T_velodyne).
//!
//! Georeference: world x/y is a scaled-Mercator east/north about lat 48.9843445,
//! lon 8.4295857 ([`KITTI360_ORIGIN`], the devkit's origin).
//!
//! Class mapping ([`kitti360_class`]; ids of the KITTI-360 devkit's `labels.py`):
//!
//! | KITTI-360 id | name | urbansem |
//! |---|---|---|
//! | 0–3, 23, 65535 | unlabeled, ego vehicle, rectification border, out of roi, sky, unlabelled | unlabelled |
//! | 4, 5, 6 | static, dynamic, ground | other |
//! | 7, 9 | road, parking | street |
//! | 8 | sidewalk | sidewalk |
//! | 10 | rail track | other |
//! | 11, 34 | building, garage | building |
//! | 12–16 | wall, fence, guard rail, bridge, tunnel | other |
//! | 17, 18, 19, 37, 38 | pole, polegroup, traffic light, smallpole, lamp | pole |
//! | 20 | traffic sign | other |
//! | 21 | vegetation | tree |
//! | 22 | terrain | grass |
//! | 24, 25 | person, rider | other |
//! | 26–30, 43 | car, truck, bus, caravan, trailer, unknown vehicle | car |
//! | 31 | train | other |
//! | 32, 33 | motorcycle, bicycle | bicycle |
//! | 35, 36, 39–42, 44 | gate, stop, trash bin, vending machine, box, unknown construction, unknown object | other |
//! | other values | – | unlabelled |

use super::{check_rotation, floats, frames_in, iso_from_rows, load_bin_scan, read_text};
use super::{DatasetError, Georeference, LidarSequence, Result, Scan, SequenceKind};
use crate::classes::Class;
use crate::mercator::ScaledMercator;
use nalgebra::{Isometry3, Matrix4};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Georeference origin (lat, lon in degrees) of KITTI-360's world frame.
pub const KITTI360_ORIGIN: (f64, f64) = (48.984_344_5, 8.429_585_7);

/// urbansem class of a KITTI-360 semantic id (table in the module doc).
pub fn kitti360_class(raw: u32) -> Class {
    match raw {
        7 | 9 => Class::Street,
        8 => Class::Sidewalk,
        11 | 34 => Class::Building,
        17 | 18 | 19 | 37 | 38 => Class::Pole,
        21 => Class::Tree,
        22 => Class::Grass,
        26..=30 | 43 => Class::Car,
        32 | 33 => Class::Bicycle,
        4..=6 | 10 | 12..=16 | 20 | 24 | 25 | 31 | 35 | 36 | 39..=42 | 44 => Class::Other,
        _ => Class::Unlabelled,
    }
}

/// One KITTI-360 sequence directory with its poses loaded.
#[derive(Debug, Clone)]
pub struct Kitti360Sequence {
    dir: PathBuf,
    poses: BTreeMap<u64, Isometry3<f64>>,
    georef: ScaledMercator,
}

impl Kitti360Sequence {
    /// Opens `dir`, reading its `velodyne_poses*.txt`.
    pub fn open(dir: impl AsRef<Path>) -> Result<Self> {
        let dir = dir.as_ref().to_path_buf();
        let pose_path = find_pose_file(&dir)?;
        let poses = read_velodyne_poses(&pose_path)?;
        let georef = ScaledMercator::new(KITTI360_ORIGIN.0, KITTI360_ORIGIN.1)?;
        Ok(Self { dir, poses, georef })
    }

    /// Frame numbers that have a scan file, sorted.
    pub fn frames(&self) -> Result<Vec<u64>> {
        frames_in(&self.dir.join("velodyne_points"), "bin")
    }

    /// Frame numbers that have a pose, sorted.
    pub fn pose_frames(&self) -> impl Iterator<Item = u64> + '_ {
        self.poses.keys().copied()
    }

    /// Number of poses read.
    pub fn pose_count(&self) -> usize {
        self.poses.len()
    }

    /// world_T_velodyne of a frame.
    pub fn world_from_velodyne(&self, frame: u64) -> Option<Isometry3<f64>> {
        self.poses.get(&frame).copied()
    }

    /// The georeference of the world frame.
    pub fn georef(&self) -> ScaledMercator {
        self.georef
    }

    /// Loads a scan with its labels (when `gt_labels/` has them) and pose.
    pub fn load_scan(&self, frame: u64) -> Result<Scan> {
        load_bin_scan(self, "velodyne_points", frame, kitti360_class)
    }
}

impl LidarSequence for Kitti360Sequence {
    fn kind(&self) -> Option<SequenceKind> {
        Some(SequenceKind::Kitti360)
    }

    fn name(&self) -> &'static str {
        SequenceKind::Kitti360.name()
    }

    fn dir(&self) -> &Path {
        &self.dir
    }

    fn labelled(&self) -> bool {
        true
    }

    fn frames(&self) -> Result<Vec<u64>> {
        Kitti360Sequence::frames(self)
    }

    fn pose_frames(&self) -> Result<Vec<u64>> {
        Ok(Kitti360Sequence::pose_frames(self).collect())
    }

    fn world_from_sensor(&self, frame: u64) -> Result<Isometry3<f64>> {
        self.world_from_velodyne(frame)
            .ok_or_else(|| DatasetError::MissingPose {
                path: self.dir.clone(),
                frame,
            })
    }

    fn georeference(&self) -> Georeference {
        Georeference::ScaledMercator(self.georef)
    }

    fn load_scan(&self, frame: u64) -> Result<Scan> {
        Kitti360Sequence::load_scan(self, frame)
    }
}

fn find_pose_file(dir: &Path) -> Result<PathBuf> {
    let exact = dir.join("velodyne_poses.txt");
    if exact.exists() {
        return Ok(exact);
    }
    let entries = std::fs::read_dir(dir).map_err(|source| DatasetError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut found: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("velodyne_poses") && n.ends_with(".txt"))
        })
        .collect();
    found.sort();
    found.into_iter().next().ok_or_else(|| DatasetError::Io {
        path: exact,
        source: std::io::Error::new(
            std::io::ErrorKind::NotFound,
            "no velodyne_poses*.txt in the sequence directory",
        ),
    })
}

/// Reads a KITTI-360 pose file: `frame` then 12 (3×4) or 16 (4×4) row-major values per line.
pub fn read_velodyne_poses(path: &Path) -> Result<BTreeMap<u64, Isometry3<f64>>> {
    let text = read_text(path)?;
    let mut poses = BTreeMap::new();
    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        if line.trim().is_empty() {
            continue;
        }
        let v = floats(path, line_no, line, ' ')?;
        let (Some(&frame), Some(rest)) = (v.first(), v.get(1..)) else {
            continue;
        };
        if !(rest.len() == 12 || rest.len() == 16) || frame < 0.0 || frame.fract() != 0.0 {
            return Err(DatasetError::Parse {
                path: path.to_path_buf(),
                line: line_no,
                message: format!(
                    "expected a frame number and 12 or 16 matrix values, found {} values",
                    v.len()
                ),
            });
        }
        let mut m = Matrix4::identity();
        for (k, x) in rest.iter().take(12).enumerate() {
            m[(k / 4, k % 4)] = *x;
        }
        check_rotation(&m, path, line_no, 1e-3)?;
        poses.insert(frame as u64, iso_from_rows(&m));
    }
    Ok(poses)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn class_table_by_hand() {
        assert_eq!(kitti360_class(7), Class::Street);
        assert_eq!(kitti360_class(11), Class::Building);
        assert_eq!(kitti360_class(22), Class::Grass);
        assert_eq!(kitti360_class(33), Class::Bicycle);
        assert_eq!(kitti360_class(65535), Class::Unlabelled);
        assert_eq!(kitti360_class(44), Class::Other);
    }

    #[test]
    fn pose_lines_and_errors() {
        let dir = std::env::temp_dir().join(format!("urbansem-k360-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("velodyne_poses.txt");
        std::fs::write(&p, "5 1 0 0 10 0 1 0 20 0 0 1 30\n").unwrap();
        let poses = read_velodyne_poses(&p).unwrap();
        assert_eq!(poses[&5].translation.vector.x, 10.0);
        std::fs::write(&p, "5 1 0 0 10 0 1 0 20 0 0 1\n").unwrap();
        let e = read_velodyne_poses(&p).unwrap_err();
        assert!(e.to_string().contains(":1:"), "{e}");
    }
}
