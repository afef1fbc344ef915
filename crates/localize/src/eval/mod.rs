//! Evaluation inputs and measures: simulated `localization` datasets (`dataset.json`,
//! `truth.json`, `scan_NNN.ply`), the real MCD `kth_day_06` scans levelled into the sensor
//! frame with their documented poses, and N_accurate of thesis §5.4.3; [`report`] tabulates
//! a dataset's outcomes; [`run`] is the whole `localize eval` job.

pub mod report;
pub mod run;
pub use report::{EvalReport, EvalSetup, RankMethod, ScanOutcome};

use crate::{LocalizeError, Pose2, Result};
use geodata::datasets::{LidarSequence, SequenceKind};
use geodata::osm::OsmMap;
use serde_json::Value;
use std::path::{Path, PathBuf};

/// One scan of an evaluation set: its name, true pose and points (sensor frame, levelled).
#[derive(Debug, Clone)]
pub struct EvalScan {
    /// Scan file name (or MCD frame number).
    pub name: String,
    /// True pose in the map's local frame (yaw from grid east).
    pub truth: Pose2,
    /// Points in the gravity-levelled sensor frame.
    pub points: Vec<[f64; 3]>,
}

fn dataset_err(path: &Path, message: impl Into<String>) -> LocalizeError {
    LocalizeError::Dataset {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

fn read_json(path: &Path) -> Result<Value> {
    let text = std::fs::read_to_string(path).map_err(|e| dataset_err(path, e.to_string()))?;
    serde_json::from_str(&text).map_err(|e| {
        dataset_err(
            path,
            format!(
                "invalid JSON at line {} column {}: {e}",
                e.line(),
                e.column()
            ),
        )
    })
}

/// A simulated `localization` dataset folder.
#[derive(Debug, Clone)]
pub struct SimDataset {
    /// The folder.
    pub dir: PathBuf,
    /// The map file (resolved: as given, or relative to the folder).
    pub map_path: PathBuf,
    /// Scan names with their true poses, sorted by name.
    pub truth: Vec<(String, Pose2)>,
}

impl SimDataset {
    /// Reads `dataset.json` and `truth.json`.
    pub fn open(dir: impl AsRef<Path>) -> Result<SimDataset> {
        let dir = dir.as_ref().to_path_buf();
        let meta_path = dir.join("dataset.json");
        let meta = read_json(&meta_path)?;
        let kind = meta.get("kind").and_then(Value::as_str).unwrap_or("");
        if kind != "localization" {
            return Err(dataset_err(
                &meta_path,
                format!("\"kind\" is {kind:?}, expected \"localization\""),
            ));
        }
        let map = meta
            .get("map")
            .and_then(Value::as_str)
            .ok_or_else(|| dataset_err(&meta_path, "missing string \"map\""))?;
        // Relative to the dataset folder first (how `sim dataset` records its own map),
        // then as given (relative to the working directory).
        let map_path = if dir.join(map).exists() {
            dir.join(map)
        } else {
            PathBuf::from(map)
        };
        let truth_path = dir.join("truth.json");
        let truth_v = read_json(&truth_path)?;
        let obj = truth_v
            .as_object()
            .ok_or_else(|| dataset_err(&truth_path, "expected an object of scan name → pose"))?;
        let mut truth = Vec::new();
        for (name, v) in obj {
            let num = |k: &str| -> Result<f64> {
                v.get(k)
                    .and_then(Value::as_f64)
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| {
                        dataset_err(
                            &truth_path,
                            format!("{name}: missing or non-finite \"{k}\""),
                        )
                    })
            };
            let yaw = match v.get("yaw_grid").and_then(Value::as_f64) {
                Some(y) => y,
                None => num("yaw")?,
            };
            truth.push((
                name.clone(),
                Pose2 {
                    x: num("x")?,
                    y: num("y")?,
                    yaw_rad: yaw,
                },
            ));
        }
        truth.sort_by(|a, b| a.0.cmp(&b.0));
        Ok(SimDataset {
            dir,
            map_path,
            truth,
        })
    }

    /// Loads one scan's points.
    pub fn load(&self, index: usize) -> Result<EvalScan> {
        let (name, truth) = self
            .truth
            .get(index)
            .ok_or_else(|| dataset_err(&self.dir, format!("no scan {index}")))?;
        let cloud = geodata::cloud::read_cloud(self.dir.join(name))?;
        Ok(EvalScan {
            name: name.clone(),
            truth: *truth,
            points: cloud.positions,
        })
    }
}

/// The layout of a real LiDAR sequence folder (MCD, KITTI-360, KITTI raw), or `None` for a
/// simulated dataset (it has `dataset.json`) or an unknown folder.
pub fn real_sequence(dir: &Path) -> Option<SequenceKind> {
    if dir.join("dataset.json").exists() {
        None
    } else {
        SequenceKind::of(dir)
    }
}

/// The scans of the real `kind` sequence in `dir` (every `stride`-th frame), levelled, with
/// their dataset poses in the map's local frame as truth.
pub fn real_scans(
    dir: &Path,
    kind: SequenceKind,
    map: &OsmMap,
    stride: usize,
) -> Result<Vec<EvalScan>> {
    sequence_scans(kind.open(dir)?.as_ref(), map, stride)
}

/// An error unless some true pose lies within `margin_m` of the box `[min_x, min_y, max_x,
/// max_y]` of the map (its buildings and streets): scans of another place.
pub fn check_overlap(
    dataset: &Path,
    map: &Path,
    scans: &[EvalScan],
    bounds: Option<[f64; 4]>,
    margin_m: f64,
) -> Result<()> {
    let Some(b) = bounds else {
        return Err(dataset_err(
            map,
            "the map has no buildings or streets to localize on",
        ));
    };
    let near = |p: &Pose2| {
        p.x >= b[0] - margin_m
            && p.x <= b[2] + margin_m
            && p.y >= b[1] - margin_m
            && p.y <= b[3] + margin_m
    };
    match scans.iter().find(|s| near(&s.truth)) {
        Some(_) => Ok(()),
        None if scans.is_empty() => Err(dataset_err(dataset, "no scans")),
        None => {
            let t = scans[0].truth;
            Err(dataset_err(
                dataset,
                format!(
                    "none of its {} scan poses lies within {margin_m} m of the map {} (the first is at ({:.0}, {:.0}) m in the map's frame, the map spans x {:.0}…{:.0}, y {:.0}…{:.0} m): is it the map of this sequence?",
                    scans.len(),
                    map.display(),
                    t.x,
                    t.y,
                    b[0],
                    b[2],
                    b[1],
                    b[3]
                ),
            ))
        }
    }
}

/// The box `[min_x, min_y, max_x, max_y]` of a map's buildings and streets (`None`: neither).
pub fn map_bounds(map: &OsmMap) -> Option<[f64; 4]> {
    let points = map
        .buildings
        .iter()
        .flat_map(|b| b.outer.iter().copied())
        .chain(map.streets.segments.iter().flat_map(|s| [s.a, s.b]));
    let mut out: Option<[f64; 4]> = None;
    for p in points {
        let b = out.get_or_insert([p[0], p[1], p[0], p[1]]);
        *b = [
            b[0].min(p[0]),
            b[1].min(p[1]),
            b[2].max(p[0]),
            b[3].max(p[1]),
        ];
    }
    out
}

/// Whether a folder is an MCD sequence (has `pose_inW.csv`).
pub fn is_mcd(dir: &Path) -> bool {
    dir.join("pose_inW.csv").exists()
}

/// The MCD scans of a sequence (every `stride`-th frame), levelled into the sensor frame with
/// their documented poses in the map's local frame.
pub fn mcd_scans(dir: &Path, map: &OsmMap, stride: usize) -> Result<Vec<EvalScan>> {
    sequence_scans(SequenceKind::Mcd.open(dir)?.as_ref(), map, stride)
}

/// The scans of a LiDAR sequence (every `stride`-th frame), levelled into the sensor frame
/// with their dataset poses in the map's local frame as truth.
pub fn sequence_scans(
    seq: &dyn LidarSequence,
    map: &OsmMap,
    stride: usize,
) -> Result<Vec<EvalScan>> {
    let frames = seq.frames()?;
    frames
        .into_iter()
        .step_by(stride.max(1))
        .map(|f| level_scan(seq, map, f).map(|l| l.scan))
        .collect()
}

/// One real scan levelled into the sensor frame ([`level_scan`]).
#[derive(Debug, Clone)]
pub struct LevelledScan {
    /// The scan: name, true pose in the map's local frame, levelled points.
    pub scan: EvalScan,
    /// Its frame number in the sequence.
    pub frame: u64,
    /// The rotation (row-major) from the raw sensor frame into the levelled one: roll and
    /// pitch removed, heading kept at 0 (levelled = `levelling` · raw, up to rounding).
    pub levelling: [[f64; 3]; 3],
}

/// The scan `frame` of a LiDAR sequence levelled into the sensor frame (x forward, z up,
/// origin at the sensor), with its dataset pose in the map's local frame as truth.
pub fn level_scan(seq: &dyn LidarSequence, map: &OsmMap, frame: u64) -> Result<LevelledScan> {
    let scan = seq.load_scan(frame)?;
    let iso = scan.local_from_sensor(&map.frame);
    let (_, _, yaw) = iso.rotation.euler_angles();
    let t = iso.translation.vector;
    let mut cloud = scan.cloud.clone();
    cloud.transform(&iso);
    let (s, c) = yaw.sin_cos();
    let points = cloud
        .positions
        .iter()
        .map(|p| {
            let (dx, dy, dz) = (p[0] - t.x, p[1] - t.y, p[2] - t.z);
            [c * dx + s * dy, -s * dx + c * dy, dz]
        })
        .collect();
    let r = iso.rotation.to_rotation_matrix();
    let r = r.matrix();
    let levelling = crate::levelling_rotation(
        &std::array::from_fn(|i| [r[(i, 0)], r[(i, 1)], r[(i, 2)]]),
        yaw,
    );
    Ok(LevelledScan {
        scan: EvalScan {
            name: format!("{frame:010}"),
            truth: Pose2 {
                x: t.x,
                y: t.y,
                yaw_rad: yaw.rem_euclid(std::f64::consts::TAU),
            },
            points,
        },
        frame,
        levelling,
    })
}

/// The scan `frame` of the MCD sequence in `dir`, levelled ([`level_scan`]).
pub fn mcd_scan(dir: &Path, map: &OsmMap, frame: u64) -> Result<LevelledScan> {
    level_scan(SequenceKind::Mcd.open(dir)?.as_ref(), map, frame)
}

/// The frame numbers of the MCD sequence in `dir` that have a scan file, sorted.
pub fn mcd_frames(dir: &Path) -> Result<Vec<u64>> {
    Ok(SequenceKind::Mcd.open(dir)?.frames()?)
}

pub use crate::Accuracy;

/// Whether one of the `k` best-ranked poses within `w` metres of the truth is accurate
/// (thesis §5.4.3); `ranked` is best first.
pub fn accurate_within(ranked: &[Pose2], truth: &Pose2, k: usize, w: f64, acc: Accuracy) -> bool {
    ranked
        .iter()
        .filter(|p| p.distance_to(truth) <= w)
        .take(k)
        .any(|p| acc.accepts(p, truth))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn n_accurate_counts_within_radius() {
        let truth = Pose2 {
            x: 0.0,
            y: 0.0,
            yaw_rad: 0.0,
        };
        let far = Pose2 {
            x: 300.0,
            y: 0.0,
            yaw_rad: 0.0,
        };
        let near_bad = Pose2 {
            x: 30.0,
            y: 0.0,
            yaw_rad: 0.0,
        };
        let good = Pose2 {
            x: 1.0,
            y: 1.0,
            yaw_rad: 0.1,
        };
        let ranked = [far, near_bad, good];
        assert!(!accurate_within(
            &ranked,
            &truth,
            1,
            f64::INFINITY,
            Accuracy::THESIS
        ));
        assert!(accurate_within(
            &ranked,
            &truth,
            3,
            f64::INFINITY,
            Accuracy::THESIS
        ));
        assert!(!accurate_within(&ranked, &truth, 1, 50.0, Accuracy::THESIS));
        assert!(accurate_within(&ranked, &truth, 1, 10.0, Accuracy::THESIS));
    }

    #[test]
    fn missing_dataset_names_the_file() {
        let err = SimDataset::open("/nonexistent/dir").unwrap_err();
        assert!(err.to_string().contains("dataset.json"), "{err}");
    }
}
