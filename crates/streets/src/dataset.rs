//! The `streets` dataset format written by `geosim` (`urbansem sim dataset --kind streets`).
//!
//! `DIR/dataset.json` (`{"kind": "streets", "map": "<path>", …}`), `DIR/cloud.ply` (labelled
//! points in the map's local frame) and `DIR/segments.json` (one entry per segment of
//! `map.streets.segments`, in order: `segment`, `offset_m`, `width_m`, optional
//! `sidewalk_m` and `drivable`, `observed`, `points`).

use crate::{Result, StreetsError};
use geodata::cloud::{read_cloud, PointCloud};
use geodata::osm::OsmMap;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The true geometry of one segment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SegmentTruth {
    /// Segment index in `map.streets.segments`.
    pub segment: usize,
    /// Offset of the true centre from the OSM centre line, left of a→b positive, metres.
    pub offset_m: f64,
    /// Driving-area width, metres.
    pub width_m: f64,
    /// Sidewalk width on each side, metres (0 when the dataset has none).
    #[serde(default)]
    pub sidewalk_m: f64,
    /// Offset of the driving area with sidewalk, when it differs from `offset_m` (real data:
    /// sidewalks of unequal width); `None`: the same as `offset_m`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub outer_offset_m: Option<f64>,
    /// Whether the driving area with sidewalk has a truth (real data: its edges were seen).
    #[serde(default = "yes")]
    pub outer_observed: bool,
    /// Whether the segment is a street for cars (footways are not).
    #[serde(default = "yes")]
    pub drivable: bool,
    /// Whether the scans observed the segment.
    pub observed: bool,
    /// Driving-area points of the segment in the cloud.
    #[serde(default)]
    pub points: usize,
}

fn yes() -> bool {
    true
}

#[derive(Deserialize)]
struct DatasetJson {
    kind: String,
    map: String,
    #[serde(default)]
    route_m: Option<f64>,
}

/// A loaded `streets` dataset.
pub struct StreetsDataset {
    /// The dataset folder.
    pub dir: PathBuf,
    /// The map file as resolved.
    pub map_path: PathBuf,
    /// The map.
    pub map: OsmMap,
    /// The registered labelled cloud.
    pub cloud: PointCloud,
    /// Truth per segment of `map.streets.segments`.
    pub segments: Vec<SegmentTruth>,
    /// Length of the simulated route, metres, when given.
    pub route_m: Option<f64>,
}

fn read_json<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|cause| StreetsError::Io {
        path: path.to_path_buf(),
        cause,
    })?;
    serde_json::from_str(&text).map_err(|e| StreetsError::Dataset {
        path: path.to_path_buf(),
        message: format!("line {} column {}: {e}", e.line(), e.column()),
    })
}

impl StreetsDataset {
    /// Loads `dir`; the map path in `dataset.json` is tried as given, then relative to `dir`.
    pub fn load(dir: impl AsRef<Path>) -> Result<StreetsDataset> {
        let dir = dir.as_ref().to_path_buf();
        let meta_path = dir.join("dataset.json");
        let meta: DatasetJson = read_json(&meta_path)?;
        if meta.kind != "streets" {
            return Err(StreetsError::Dataset {
                path: meta_path,
                message: format!("kind is {:?}, expected \"streets\"", meta.kind),
            });
        }
        let given = PathBuf::from(&meta.map);
        // Relative to the dataset folder first (how `sim dataset` records its own map),
        // then as given (relative to the working directory).
        let map_path = if dir.join(&given).exists() {
            dir.join(&given)
        } else if given.exists() {
            given
        } else {
            return Err(StreetsError::Dataset {
                path: meta_path,
                message: format!(
                    "map {} not found (tried as given and relative to {})",
                    meta.map,
                    dir.display()
                ),
            });
        };
        let map = OsmMap::load(&map_path)?;
        let seg_path = dir.join("segments.json");
        let segments: Vec<SegmentTruth> = read_json(&seg_path)?;
        if segments.len() != map.streets.segments.len() {
            return Err(StreetsError::Dataset {
                path: seg_path,
                message: format!(
                    "{} entries but the map {} has {} segments",
                    segments.len(),
                    map_path.display(),
                    map.streets.segments.len()
                ),
            });
        }
        for (i, s) in segments.iter().enumerate() {
            let ok = s.segment == i
                && s.offset_m.is_finite()
                && s.width_m.is_finite()
                && s.width_m >= 0.0
                && s.sidewalk_m.is_finite()
                && s.sidewalk_m >= 0.0;
            if !ok {
                return Err(StreetsError::Dataset {
                    path: seg_path,
                    message: format!("entry {i} is out of order or has a bad value: {s:?}"),
                });
            }
        }
        let cloud_path = dir.join("cloud.ply");
        let cloud = read_cloud(&cloud_path)?;
        if cloud.label.is_none() {
            return Err(StreetsError::NoLabels {
                path: cloud_path.display().to_string(),
            });
        }
        Ok(StreetsDataset {
            dir,
            map_path,
            map,
            cloud,
            segments,
            route_m: meta.route_m,
        })
    }
}
