//! MCD (Multi-Campus Dataset, mcdviral) sequence `kth_day_06`: Ouster OS1-128 scans of the
//! KTH campus in Stockholm with per-point semantic labels and body poses.
//!
//! Layout (as in `../shared/data/lidar/mcd_kth_day_06/`): `lidar_bin/NNNNNNNNNN.bin`
//! (KITTI-style f32 x y z intensity, 65 536 points), `gt_labels/NNNNNNNNNN.bin` (u32 MCD
//! class per point), `pose_inW.csv` (`num,t,x,y,z,qx,qy,qz,qw`: world_T_body keyed by scan
//! number) and `hhs_calib.yaml` (`body: os_sensor: T`, a 4×4). The lidar pose is
//! world_T_lidar = world_T_body · T: T is body_T_lidar. (arpg/OSM-BKI's
//! `visualize_map_osm.cpp` uses world_T_body · T⁻¹, which doubles the mount's 1.6° roll instead
//! of removing it: the walls of every scan then lean 2.7–4.1° the same way in the sensor frame,
//! while with T they stand within 0.45° of vertical, median over the 30 scans; test
//! `the_walls_of_every_mcd_scan_stand_vertical` in `crates/localize/tests/real_sensors.rs`.)
//!
//! Georeference: world x = east, y = north about lat 59.347671416, lon 18.072069652
//! (scaled Mercator, [`MCD_KTH_ORIGIN`]).
//!
//! Class mapping ([`mcd_class`]; MCD ids from OSM-BKI's `configs/mcd_config.yaml`):
//!
//! | MCD id | name | urbansem |
//! |---|---|---|
//! | 0 | barrier | other |
//! | 1 | bike | bicycle |
//! | 2 | building | building |
//! | 3, 4, 5 | chair, cliff, container | other |
//! | 6 | curb | sidewalk |
//! | 7, 8, 9 | fence, hydrant, infosign | other |
//! | 10 | lanemarking | street |
//! | 11 | noise | unlabelled |
//! | 12 | other | other |
//! | 13 | parkinglot | street |
//! | 14 | pedestrian | other |
//! | 15 | pole | pole |
//! | 16 | road | street |
//! | 17 | shelter | other |
//! | 18, 19 | sidewalk, stairs | sidewalk |
//! | 20, 21, 22, 23 | structure-other, traffic-cone, traffic-sign, trashbin | other |
//! | 24 | treetrunk | tree |
//! | 25 | vegetation (MCD has no separate terrain class) | tree |
//! | 26, 27, 28 | vehicle-dynamic, vehicle-other, vehicle-static | car |
//! | other values | – | unlabelled |

use super::{check_rotation, floats, frames_in, iso_from_rows, load_bin_scan, read_text};
use super::{DatasetError, Georeference, LidarSequence, Result, Scan, SequenceKind};
use crate::classes::Class;
use crate::mercator::ScaledMercator;
use nalgebra::{Isometry3, Matrix4, Quaternion, Translation3, UnitQuaternion};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Georeference origin (lat, lon in degrees) of MCD's KTH sequences (world (0, 0)).
pub const MCD_KTH_ORIGIN: (f64, f64) = (59.347_671_416, 18.072_069_652);

/// MCD class names by id.
pub const MCD_CLASS_NAMES: [&str; 29] = [
    "barrier",
    "bike",
    "building",
    "chair",
    "cliff",
    "container",
    "curb",
    "fence",
    "hydrant",
    "infosign",
    "lanemarking",
    "noise",
    "other",
    "parkinglot",
    "pedestrian",
    "pole",
    "road",
    "shelter",
    "sidewalk",
    "stairs",
    "structure-other",
    "traffic-cone",
    "traffic-sign",
    "trashbin",
    "treetrunk",
    "vegetation",
    "vehicle-dynamic",
    "vehicle-other",
    "vehicle-static",
];

/// urbansem class of an MCD class id (table in the module doc).
pub fn mcd_class(raw: u32) -> Class {
    match raw {
        1 => Class::Bicycle,
        2 => Class::Building,
        6 | 18 | 19 => Class::Sidewalk,
        10 | 13 | 16 => Class::Street,
        15 => Class::Pole,
        24 | 25 => Class::Tree,
        26..=28 => Class::Car,
        0 | 3..=5 | 7..=9 | 12 | 14 | 17 | 20..=23 => Class::Other,
        _ => Class::Unlabelled,
    }
}

/// One MCD sequence directory with its poses and calibration loaded.
#[derive(Debug, Clone)]
pub struct McdSequence {
    dir: PathBuf,
    poses: BTreeMap<u64, Isometry3<f64>>,
    body_from_lidar: Isometry3<f64>,
    georef: ScaledMercator,
}

impl McdSequence {
    /// Opens `dir` (reads `pose_inW.csv` and `hhs_calib.yaml`) with the KTH georeference.
    pub fn open(dir: impl AsRef<Path>) -> Result<Self> {
        let dir = dir.as_ref().to_path_buf();
        let poses = read_poses(&dir.join("pose_inW.csv"))?;
        let t = read_calib_matrix(&dir.join("hhs_calib.yaml"), "os_sensor")?;
        let georef = ScaledMercator::new(MCD_KTH_ORIGIN.0, MCD_KTH_ORIGIN.1)?;
        Ok(Self {
            dir,
            poses,
            body_from_lidar: t,
            georef,
        })
    }

    /// Frame numbers that have a scan file, sorted.
    pub fn frames(&self) -> Result<Vec<u64>> {
        frames_in(&self.dir.join("lidar_bin"), "bin")
    }

    /// Frame numbers that have a pose, sorted.
    pub fn pose_frames(&self) -> impl Iterator<Item = u64> + '_ {
        self.poses.keys().copied()
    }

    /// Number of poses in `pose_inW.csv`.
    pub fn pose_count(&self) -> usize {
        self.poses.len()
    }

    /// world_T_body of a frame.
    pub fn world_from_body(&self, frame: u64) -> Option<Isometry3<f64>> {
        self.poses.get(&frame).copied()
    }

    /// world_T_lidar of a frame.
    pub fn world_from_lidar(&self, frame: u64) -> Option<Isometry3<f64>> {
        self.world_from_body(frame)
            .map(|b| b * self.body_from_lidar)
    }

    /// The georeference of the world frame.
    pub fn georef(&self) -> ScaledMercator {
        self.georef
    }

    /// Loads a scan with its labels (when `gt_labels/` has them) and lidar pose.
    pub fn load_scan(&self, frame: u64) -> Result<Scan> {
        load_bin_scan(self, "lidar_bin", frame, mcd_class)
    }
}

impl LidarSequence for McdSequence {
    fn kind(&self) -> Option<SequenceKind> {
        Some(SequenceKind::Mcd)
    }

    fn name(&self) -> &'static str {
        SequenceKind::Mcd.name()
    }

    fn dir(&self) -> &Path {
        &self.dir
    }

    fn labelled(&self) -> bool {
        true
    }

    fn frames(&self) -> Result<Vec<u64>> {
        McdSequence::frames(self)
    }

    fn pose_frames(&self) -> Result<Vec<u64>> {
        Ok(McdSequence::pose_frames(self).collect())
    }

    /// world_T_lidar of a frame.
    fn world_from_sensor(&self, frame: u64) -> Result<Isometry3<f64>> {
        self.world_from_lidar(frame)
            .ok_or_else(|| DatasetError::MissingPose {
                path: self.dir.join("pose_inW.csv"),
                frame,
            })
    }

    fn georeference(&self) -> Georeference {
        Georeference::ScaledMercator(self.georef)
    }

    fn load_scan(&self, frame: u64) -> Result<Scan> {
        McdSequence::load_scan(self, frame)
    }
}

/// Reads `pose_inW.csv`: `num,t,x,y,z,qx,qy,qz,qw` per line after a header.
pub fn read_poses(path: &Path) -> Result<BTreeMap<u64, Isometry3<f64>>> {
    let text = read_text(path)?;
    let mut poses = BTreeMap::new();
    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        if line.trim().is_empty() || (line_no == 1 && line.starts_with("num")) {
            continue;
        }
        let v = floats(path, line_no, line, ',')?;
        let [num, _t, x, y, z, qx, qy, qz, qw] = v.as_slice() else {
            return Err(DatasetError::Parse {
                path: path.to_path_buf(),
                line: line_no,
                message: format!(
                    "expected 9 values num,t,x,y,z,qx,qy,qz,qw, found {}",
                    v.len()
                ),
            });
        };
        let q = Quaternion::new(*qw, *qx, *qy, *qz);
        if (q.norm() - 1.0).abs() > 1e-3 || *num < 0.0 || num.fract() != 0.0 {
            return Err(DatasetError::Parse {
                path: path.to_path_buf(),
                line: line_no,
                message: format!("bad scan number {num} or quaternion norm {}", q.norm()),
            });
        }
        let pose = Isometry3::from_parts(
            Translation3::new(*x, *y, *z),
            UnitQuaternion::from_quaternion(q),
        );
        poses.insert(*num as u64, pose);
    }
    Ok(poses)
}

/// Reads the 4×4 `T` of sensor `sensor` (e.g. `os_sensor`) from a Kalibr-style YAML.
///
/// Only the subset used by `hhs_calib.yaml` is understood: a `sensor:` key, then a `T:` key
/// indented below it, then four lines `- [a, b, c, d]`.
pub fn read_calib_matrix(path: &Path, sensor: &str) -> Result<Isometry3<f64>> {
    let text = read_text(path)?;
    let lines: Vec<&str> = text.lines().collect();
    let indent = |s: &str| s.len() - s.trim_start().len();
    let key = format!("{sensor}:");
    let start = lines
        .iter()
        .position(|l| l.trim() == key)
        .ok_or_else(|| DatasetError::Parse {
            path: path.to_path_buf(),
            line: lines.len(),
            message: format!("no {key:?} key"),
        })?;
    let base = lines.get(start).map_or(0, |l| indent(l));
    let mut t_line = None;
    for (i, l) in lines.iter().enumerate().skip(start + 1) {
        if !l.trim().is_empty() && indent(l) <= base {
            break;
        }
        if l.trim() == "T:" {
            t_line = Some(i);
            break;
        }
    }
    let t_line = t_line.ok_or_else(|| DatasetError::Parse {
        path: path.to_path_buf(),
        line: start + 1,
        message: format!("{sensor} has no T: matrix"),
    })?;
    let mut m = Matrix4::zeros();
    for r in 0..4 {
        let line_no = t_line + 2 + r;
        let row_text = lines.get(t_line + 1 + r).copied().unwrap_or("");
        let inner = row_text
            .trim()
            .strip_prefix('-')
            .map(str::trim)
            .and_then(|s| s.strip_prefix('['))
            .and_then(|s| s.strip_suffix(']'))
            .ok_or_else(|| DatasetError::Parse {
                path: path.to_path_buf(),
                line: line_no,
                message: format!("expected a matrix row \"- [a, b, c, d]\", found {row_text:?}"),
            })?;
        let v = floats(path, line_no, inner, ',')?;
        if v.len() != 4 {
            return Err(DatasetError::Parse {
                path: path.to_path_buf(),
                line: line_no,
                message: format!("matrix row has {} values, expected 4", v.len()),
            });
        }
        for (c, x) in v.iter().enumerate() {
            m[(r, c)] = *x;
        }
    }
    check_rotation(&m, path, t_line + 2, 1e-4)?;
    Ok(iso_from_rows(&m))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn class_table_covers_all_ids() {
        assert_eq!(mcd_class(2), Class::Building);
        assert_eq!(mcd_class(16), Class::Street);
        assert_eq!(mcd_class(28), Class::Car);
        assert_eq!(mcd_class(11), Class::Unlabelled);
        assert_eq!(mcd_class(29), Class::Unlabelled);
        for id in 0..29u32 {
            let c = mcd_class(id);
            assert!(
                id == 11 || c != Class::Unlabelled,
                "{}",
                MCD_CLASS_NAMES[id as usize]
            );
        }
    }

    #[test]
    fn yaml_subset_and_errors() {
        let dir = std::env::temp_dir().join(format!("urbansem-mcd-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("c.yaml");
        std::fs::write(
            &p,
            "body:\n    a:\n        T:\n        - [1, 0, 0, 9]\n    os_sensor:\n        T:\n        - [1.0, 0.0, 0.0, 0.5]\n        - [0.0, -1.0, 0.0, 0.0]\n        - [0.0, 0.0, -1.0, 2.0]\n        - [0.0, 0.0, 0.0, 1.0]\n",
        )
        .unwrap();
        let t = read_calib_matrix(&p, "os_sensor").unwrap();
        assert_eq!(t.translation.vector.x, 0.5);
        assert!(read_calib_matrix(&p, "a").is_err());
        assert!(read_calib_matrix(&p, "nope").is_err());
    }
}
