//! A simulated `localization` dataset read back as a [`LidarSequence`], so code written for the
//! real sequences (KITTI-360, MCD, KITTI raw) runs on simulated scans unchanged.
//!
//! The files are those [`crate::dataset::write_localization`] writes: `dataset.json` (its
//! `kind` must be `localization`; `frame_origin` is the map's [`LocalFrame`] origin),
//! `truth.json` (scan file name → [`TruthPose`]) and `scan_NNN.ply`. Frame `i` is
//! `scan_{i:03}.ply`. The world frame is the map's local frame
//! ([`Georeference::TransverseMercator`]); a scan's pose is its true pose in the *map*
//! (`x`, `y`, `z`, heading `yaw_grid`; the truth the localizer is scored against), with the
//! scan's levelled sensor frame turned about z only. Points carry the simulator's `label`.

use geodata::cloud::read_cloud;
use geodata::datasets::{DatasetError, Georeference, LidarSequence, Result, Scan, SequenceKind};
use geodata::projection::LocalFrame;
use geodata::simfiles::TruthPose;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Name of a simulated localization sequence ([`LidarSequence::name`]).
pub const SIM_LOCALIZATION: &str = "sim_localization";

/// A simulated `localization` dataset folder with its poses loaded.
#[derive(Debug, Clone)]
pub struct SimLocalization {
    dir: PathBuf,
    frame: LocalFrame,
    /// Frame number → (scan file name, true pose).
    scans: BTreeMap<u64, (String, TruthPose)>,
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|source| DatasetError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    serde_json::from_str(&text).map_err(|e| DatasetError::Parse {
        path: path.to_path_buf(),
        line: e.line(),
        message: e.to_string(),
    })
}

fn parse_err(path: &Path, message: String) -> DatasetError {
    DatasetError::Parse {
        path: path.to_path_buf(),
        line: 1,
        message,
    }
}

impl SimLocalization {
    /// Whether `dir` holds a simulated dataset (`dataset.json`).
    pub fn is_sim(dir: &Path) -> bool {
        dir.join("dataset.json").is_file()
    }

    /// Opens `dir`: reads `dataset.json` (kind and frame origin) and `truth.json`.
    pub fn open(dir: impl AsRef<Path>) -> Result<Self> {
        let dir = dir.as_ref().to_path_buf();
        let meta_path = dir.join("dataset.json");
        let meta: Value = read_json(&meta_path)?;
        let kind = meta.get("kind").and_then(Value::as_str).unwrap_or("");
        if kind != "localization" {
            return Err(parse_err(
                &meta_path,
                format!("\"kind\" is {kind:?}, expected \"localization\""),
            ));
        }
        let origin = |k: &str| {
            meta.get("frame_origin")
                .and_then(|o| o.get(k))
                .and_then(Value::as_f64)
                .ok_or_else(|| parse_err(&meta_path, format!("missing \"frame_origin\".{k:?}")))
        };
        let frame = LocalFrame::new(origin("lat")?, origin("lon")?)?;
        let truth_path = dir.join("truth.json");
        let truth: BTreeMap<String, TruthPose> = read_json(&truth_path)?;
        let mut scans = BTreeMap::new();
        for (name, pose) in truth {
            let number = name
                .strip_prefix("scan_")
                .and_then(|s| s.strip_suffix(".ply"))
                .and_then(|s| s.parse::<u64>().ok())
                .ok_or_else(|| {
                    parse_err(
                        &truth_path,
                        format!("scan name {name:?} is not scan_NNN.ply"),
                    )
                })?;
            scans.insert(number, (name, pose));
        }
        Ok(Self { dir, frame, scans })
    }

    /// The map's local frame, the world frame of the poses.
    pub fn frame(&self) -> LocalFrame {
        self.frame
    }

    /// The true pose of a frame as written to `truth.json`.
    pub fn truth(&self, frame: u64) -> Option<&TruthPose> {
        self.scans.get(&frame).map(|(_, p)| p)
    }

    fn entry(&self, frame: u64) -> Result<&(String, TruthPose)> {
        self.scans
            .get(&frame)
            .ok_or_else(|| DatasetError::MissingPose {
                path: self.dir.join("truth.json"),
                frame,
            })
    }
}

/// map_T_sensor of a true pose: the levelled sensor frame at (x, y, z), turned by `yaw_grid`.
fn map_from_sensor(p: &TruthPose) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(p.x, p.y, p.z),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), p.yaw_grid),
    )
}

impl LidarSequence for SimLocalization {
    fn kind(&self) -> Option<SequenceKind> {
        None
    }

    fn name(&self) -> &'static str {
        SIM_LOCALIZATION
    }

    fn dir(&self) -> &Path {
        &self.dir
    }

    fn labelled(&self) -> bool {
        true
    }

    fn frames(&self) -> Result<Vec<u64>> {
        Ok(self.scans.keys().copied().collect())
    }

    fn pose_frames(&self) -> Result<Vec<u64>> {
        LidarSequence::frames(self)
    }

    fn world_from_sensor(&self, frame: u64) -> Result<Isometry3<f64>> {
        self.entry(frame).map(|(_, p)| map_from_sensor(p))
    }

    fn georeference(&self) -> Georeference {
        Georeference::TransverseMercator(self.frame)
    }

    fn load_scan(&self, frame: u64) -> Result<Scan> {
        let (name, pose) = self.entry(frame)?;
        let path = self.dir.join(name);
        let cloud = read_cloud(&path)?;
        Ok(Scan {
            frame,
            path,
            cloud,
            world_from_sensor: map_from_sensor(pose),
            georef: self.georeference(),
        })
    }
}

/// Opens a simulated localization dataset or any real sequence
/// ([`geodata::datasets::open_sequence`]).
pub fn open_sequence(dir: impl AsRef<Path>) -> Result<Box<dyn LidarSequence>> {
    let dir = dir.as_ref();
    if SimLocalization::is_sim(dir) {
        Ok(Box::new(SimLocalization::open(dir)?))
    } else {
        geodata::datasets::open_sequence(dir)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::{write_localization, LocalizationOptions};
    use crate::sensor::SensorOptions;
    use geodata::classes::Class;

    #[test]
    fn written_localization_dataset_reads_back_with_its_truth() {
        let map = crate::scene::tests::small_map(8);
        let dir = std::env::temp_dir().join(format!("urbansem-sim-seq-{}", std::process::id()));
        let options = LocalizationOptions {
            scans: 2,
            sensor: SensorOptions {
                h_step_deg: 2.0,
                v_step_deg: 2.0,
                ..SensorOptions::default()
            },
            ..LocalizationOptions::default()
        };
        write_localization(&map, "city.osm", &dir, &options, 3, &|_, _| {}).unwrap();
        let seq = open_sequence(&dir).unwrap();
        assert_eq!(seq.name(), SIM_LOCALIZATION);
        assert_eq!(seq.frames().unwrap(), vec![0, 1]);
        let truth: BTreeMap<String, TruthPose> =
            serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json")).unwrap())
                .unwrap();
        for (frame, name) in [(0u64, "scan_000.ply"), (1, "scan_001.ply")] {
            let t = &truth[name];
            let scan = seq.load_scan(frame).unwrap();
            let written = read_cloud(dir.join(name)).unwrap();
            assert_eq!(scan.cloud.positions, written.positions);
            let labels = scan.cloud.label.as_ref().unwrap();
            assert!(labels.iter().any(|&l| l == Class::Building.id()));
            // In the map's own frame the pose is the truth, up to the WGS84 round trip.
            let pose = scan.pose_in_local(&map.frame);
            assert!((pose.position_m[0] - t.x).abs() < 1e-6, "{pose:?} {t:?}");
            assert!((pose.position_m[1] - t.y).abs() < 1e-6, "{pose:?} {t:?}");
            let turn = (pose.yaw_rad - t.yaw_grid).rem_euclid(std::f64::consts::TAU);
            assert!(
                turn.min(std::f64::consts::TAU - turn) < 1e-9,
                "{pose:?} {t:?}"
            );
            assert!((pose.lat_deg - t.lat).abs() < 1e-9 && (pose.lon_deg - t.lon).abs() < 1e-9);
        }
        assert!(seq.world_from_sensor(2).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_streets_dataset_is_not_a_localization_sequence() {
        let dir = std::env::temp_dir().join(format!("urbansem-sim-kind-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("dataset.json"), "{\"kind\": \"streets\"}").unwrap();
        let e = open_sequence(&dir).err().unwrap();
        assert!(e.to_string().contains("expected \"localization\""), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
