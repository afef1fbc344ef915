//! The real labelled scans of `../shared/data/lidar/`, registered with their poses.
//!
//! Two sequences are read: KITTI-360 `2013_05_28_drive_0009` (25 Velodyne HDL-64E scans)
//! and MCD `kth_day_06` (30 Ouster OS1-128 scans). Each scan is moved by its sensor pose
//! into its dataset's world frame, then shifted so the sequence's first sensor position is
//! the origin (metres stay small, so the f32 R-tree keeps millimetre precision). The two
//! sequences are 1 500 km apart; [`combined_cloud`] places sequence `i` at `x + i · 1 km`
//! so that one cloud holds both without overlap. Only the `label` column is kept.
//!
//! Loading is O(points); a scan file with a malformed label file is an error naming it.

use crate::error::{Result, SrtreeError};
use geodata::cloud::{Columns, PointCloud, Precision};
use geodata::datasets::{Scan, SequenceKind};
use nalgebra::{Isometry3, Translation3};
use std::path::{Path, PathBuf};

/// Sub-directory of the KITTI-360 sequence under the lidar folder.
pub const KITTI360_DIR: &str = "kitti360_2013_05_28_drive_0009";
/// Sub-directory of the MCD sequence under the lidar folder.
pub const MCD_DIR: &str = "mcd_kth_day_06";
/// Distance between sequences in [`combined_cloud`], metres.
pub const SEQUENCE_SPACING_M: f64 = 1000.0;

/// One scan in its sequence frame.
#[derive(Debug, Clone)]
pub struct RegisteredScan {
    /// Frame number in its sequence.
    pub frame: u64,
    /// Sensor position in the sequence frame, metres.
    pub origin_m: [f64; 3],
    /// Points in the sequence frame with their `label` column (urbansem class ids).
    pub cloud: PointCloud,
}

/// One registered sequence, scans in frame order.
#[derive(Debug, Clone)]
pub struct Sequence {
    /// Short name (`kitti360`, `mcd`).
    pub name: String,
    /// The scans.
    pub scans: Vec<RegisteredScan>,
}

impl Sequence {
    /// Number of points of all scans.
    pub fn points(&self) -> usize {
        self.scans.iter().map(|s| s.cloud.len()).sum()
    }
}

fn dataset_error(path: &Path, e: geodata::datasets::DatasetError) -> SrtreeError {
    SrtreeError::Dataset {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// Registers scans: `sensor_frame` clouds with their world poses into the sequence frame.
fn register(name: &str, scans: Vec<Scan>) -> Sequence {
    let shift = scans.first().map_or(nalgebra::Vector3::zeros(), |s| {
        -s.world_from_sensor.translation.vector
    });
    let seq_from_world = Isometry3::from_parts(Translation3::from(shift), Default::default());
    let scans = scans
        .into_iter()
        .map(|s| {
            let seq_from_sensor = seq_from_world * s.world_from_sensor;
            let mut cloud = PointCloud::with_columns(
                Columns {
                    label: true,
                    ..Columns::default()
                },
                Precision::F32,
                0,
            );
            cloud.positions = s.cloud.positions;
            let n = cloud.positions.len();
            cloud.label = Some(s.cloud.label.unwrap_or_else(|| vec![0; n]));
            cloud.transform(&seq_from_sensor);
            let t = seq_from_sensor.translation.vector;
            RegisteredScan {
                frame: s.frame,
                origin_m: [t.x, t.y, t.z],
                cloud,
            }
        })
        .collect();
    Sequence {
        name: name.to_string(),
        scans,
    }
}

/// Reads and registers both labelled sequences under `lidar_dir`, at most `max_scans`
/// scans each (evenly spread over the sequence) when given.
pub fn load_sequences(lidar_dir: &Path, max_scans: Option<usize>) -> Result<Vec<Sequence>> {
    let pick = |frames: Vec<u64>| -> Vec<u64> {
        match max_scans {
            Some(m) if m < frames.len() && m > 0 => (0..m)
                .map(|i| frames[i * frames.len() / m])
                .collect::<Vec<_>>(),
            _ => frames,
        }
    };
    let mut out = Vec::new();
    for (kind, sub) in [
        (SequenceKind::Kitti360, KITTI360_DIR),
        (SequenceKind::Mcd, MCD_DIR),
    ] {
        let dir: PathBuf = lidar_dir.join(sub);
        let err = |e| dataset_error(&dir, e);
        let seq = kind.open(&dir).map_err(err)?;
        let scans = pick(seq.frames().map_err(err)?)
            .iter()
            .map(|&f| seq.load_scan(f).map_err(err))
            .collect::<Result<Vec<_>>>()?;
        out.push(register(seq.name(), scans));
    }
    for s in &out {
        if s.scans.is_empty() {
            return Err(SrtreeError::Dataset {
                path: lidar_dir.join(&s.name),
                message: "no scans found".into(),
            });
        }
    }
    Ok(out)
}

/// All scans of all sequences in one cloud (sequence `i` shifted by `i` km along x), with
/// each scan's sensor origin and its point range `[start, end)` in the cloud.
pub fn combined_cloud(sequences: &[Sequence]) -> (PointCloud, Vec<([f64; 3], usize, usize)>) {
    let total: usize = sequences.iter().map(Sequence::points).sum();
    let mut cloud = PointCloud::with_columns(
        Columns {
            label: true,
            ..Columns::default()
        },
        Precision::F64,
        total,
    );
    let mut labels = Vec::with_capacity(total);
    let mut ranges = Vec::new();
    for (i, seq) in sequences.iter().enumerate() {
        let dx = i as f64 * SEQUENCE_SPACING_M;
        for s in &seq.scans {
            let start = cloud.positions.len();
            cloud
                .positions
                .extend(s.cloud.positions.iter().map(|p| [p[0] + dx, p[1], p[2]]));
            if let Some(l) = &s.cloud.label {
                labels.extend_from_slice(l);
            }
            let o = s.origin_m;
            ranges.push(([o[0] + dx, o[1], o[2]], start, cloud.positions.len()));
        }
    }
    cloud.label = Some(labels);
    (cloud, ranges)
}
