//! Readers for the real labelled LiDAR scans in `../shared/data/lidar/`, behind one trait.
//!
//! Every reader is a [`LidarSequence`]: its scan frames, the sensor pose of a frame in the
//! dataset's world frame, that world frame's [`Georeference`], and [`Scan`]s — the cloud in
//! the sensor frame (with `intensity`, and for labelled datasets `label` = urbansem
//! [`crate::classes::Class`] id and `raw_label` = the dataset's id) with its pose.
//! [`open_sequence`] detects a folder's layout ([`SequenceKind::of`]) and opens it, so code
//! that reads scans needs no match per dataset. [`Scan::local_from_sensor`] places a scan in
//! any [`LocalFrame`], the frame OSM maps are read into.
//!
//! - [`mcd`]: MCD `kth_day_06` (Ouster OS1-128, KTH campus, Stockholm).
//! - [`kitti360`]: KITTI-360 `2013_05_28_drive_0009` (Velodyne HDL-64E, Karlsruhe).
//! - [`kitti_raw`]: KITTI raw `2011_09_26_drive_0005` frame 0 (HDL-64E + OXTS).
//!
//! Simulated `localization` datasets are sequences too (`geosim::sequence::SimLocalization`,
//! in the map's [`LocalFrame`]); geodata does not read them, the simulator's crate does.
//!
//! ```no_run
//! use geodata::datasets::{open_sequence, LidarSequence};
//! let seq = open_sequence("../shared/data/lidar/mcd_kth_day_06")?;
//! for frame in seq.frames()? {
//!     let scan = seq.load_scan(frame)?;
//!     println!("{} frame {frame}: {} points", seq.name(), scan.cloud.len());
//! }
//! # Ok::<(), geodata::datasets::DatasetError>(())
//! ```

pub mod kitti360;
pub mod kitti_raw;
pub mod mcd;

use crate::cloud::{CloudError, PointCloud};
use crate::mercator::ScaledMercator;
use crate::projection::LocalFrame;
use nalgebra::{Isometry3, Matrix3, Matrix4, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::Serialize;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// A labelled dataset whose raw class ids (its label files) map to urbansem classes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LabelSet {
    /// MCD ([`mcd::mcd_class`]).
    Mcd,
    /// KITTI-360 ([`kitti360::kitti360_class`]).
    Kitti360,
}

impl LabelSet {
    /// The set named `mcd`, `kitti360` or `kitti-360`.
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "mcd" => Some(LabelSet::Mcd),
            "kitti360" | "kitti-360" => Some(LabelSet::Kitti360),
            _ => None,
        }
    }

    /// Sets `label` (urbansem ids) and `raw_label` of a cloud from this set's ids.
    pub fn attach(self, cloud: &mut PointCloud, raw: Vec<u32>) {
        let map = match self {
            LabelSet::Mcd => mcd::mcd_class,
            LabelSet::Kitti360 => kitti360::kitti360_class,
        };
        attach_labels(cloud, raw, map);
    }
}

/// An error while reading a dataset.
#[derive(Debug, Error)]
pub enum DatasetError {
    /// A file could not be read (a missing file names its path here).
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// A text file (poses, calibration, OXTS) has a malformed line.
    #[error("{path}:{line}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// What is wrong and what was expected.
        message: String,
    },
    /// No pose for a scan's frame.
    #[error("{path}: no pose for frame {frame}")]
    MissingPose {
        /// The pose file.
        path: PathBuf,
        /// The frame number.
        frame: u64,
    },
    /// A scan or label file could not be read.
    #[error(transparent)]
    Cloud(#[from] CloudError),
    /// The georeference origin is invalid.
    #[error("{0}")]
    Mercator(#[from] crate::mercator::MercatorError),
    /// The local frame's origin is invalid.
    #[error("{0}")]
    Projection(#[from] crate::projection::ProjectionError),
    /// A folder holds none of the known sequence layouts.
    #[error("{path}: not a LiDAR sequence: expected velodyne_points/ with velodyne_poses*.txt (KITTI-360) or with oxts/ (KITTI raw), or lidar_bin/ with pose_inW.csv (MCD)")]
    UnknownLayout {
        /// The folder.
        path: PathBuf,
    },
}

/// Shorthand for results of this module.
pub type Result<T> = std::result::Result<T, DatasetError>;

/// One real scan with its pose and georeference.
#[derive(Debug, Clone)]
pub struct Scan {
    /// Frame number in its sequence.
    pub frame: u64,
    /// The scan file it came from.
    pub path: PathBuf,
    /// Points in the sensor frame (metres); `label`/`raw_label` when the dataset has labels.
    pub cloud: PointCloud,
    /// Sensor pose in the dataset's world frame (x east, y north, z up, metres).
    pub world_from_sensor: Isometry3<f64>,
    /// The world frame's georeference.
    pub georef: Georeference,
}

/// How a dataset's world x, y (metres, x east, y north) map to WGS84.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Georeference {
    /// A scaled Mercator about an origin (KITTI-360, MCD, KITTI raw).
    ScaledMercator(ScaledMercator),
    /// A local transverse-Mercator frame (simulated datasets: the frame of their OSM map).
    TransverseMercator(LocalFrame),
}

impl Georeference {
    /// WGS84 (lat, lon) in degrees of a world position.
    pub fn to_wgs84(&self, world_xy_m: [f64; 2]) -> (f64, f64) {
        match self {
            Georeference::ScaledMercator(m) => m.to_wgs84(world_xy_m),
            Georeference::TransverseMercator(f) => f.to_wgs84(world_xy_m),
        }
    }

    /// World position of a WGS84 latitude/longitude in degrees.
    pub fn to_world(&self, lat_deg: f64, lon_deg: f64) -> [f64; 2] {
        match self {
            Georeference::ScaledMercator(m) => m.to_world(lat_deg, lon_deg),
            Georeference::TransverseMercator(f) => f.to_local(lat_deg, lon_deg),
        }
    }

    /// Angle in radians from world +x to grid east of `frame` at a world position (the
    /// correction to add to a world yaw; see [`ScaledMercator::yaw_to_local_rad`]).
    pub fn yaw_to_local_rad(&self, world_xy_m: [f64; 2], frame: &LocalFrame) -> f64 {
        match self {
            Georeference::ScaledMercator(m) => m.yaw_to_local_rad(world_xy_m, frame),
            Georeference::TransverseMercator(world) => {
                // Grid yaw → geographic yaw (+ world convergence) → grid yaw of `frame`.
                let (lat, lon) = world.to_wgs84(world_xy_m);
                world.convergence_rad(world_xy_m) - frame.convergence_rad(frame.to_local(lat, lon))
            }
        }
    }
}

/// The layout of a real sequence folder.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SequenceKind {
    /// KITTI-360 (`velodyne_points/`, `velodyne_poses*.txt`, `gt_labels/`).
    Kitti360,
    /// MCD (`lidar_bin/`, `pose_inW.csv`, `hhs_calib.yaml`, `gt_labels/`).
    Mcd,
    /// KITTI raw (`velodyne_points/`, `oxts/`, `calib/`; no labels).
    KittiRaw,
}

impl SequenceKind {
    /// Short name (`kitti360`, `mcd`, `kitti_raw`).
    pub fn name(self) -> &'static str {
        match self {
            SequenceKind::Kitti360 => "kitti360",
            SequenceKind::Mcd => "mcd",
            SequenceKind::KittiRaw => "kitti_raw",
        }
    }

    /// The layout of `dir`, if it is one of the known ones: MCD when it has `pose_inW.csv`
    /// or `lidar_bin/`, else KITTI raw when it has `velodyne_points/` and `oxts/`, else
    /// KITTI-360 when it has `velodyne_points/`.
    pub fn of(dir: &Path) -> Option<SequenceKind> {
        if dir.join("pose_inW.csv").exists() || dir.join("lidar_bin").is_dir() {
            Some(SequenceKind::Mcd)
        } else if dir.join("velodyne_points").is_dir() {
            if dir.join("oxts").is_dir() {
                Some(SequenceKind::KittiRaw)
            } else {
                Some(SequenceKind::Kitti360)
            }
        } else {
            None
        }
    }

    /// Opens `dir` as a sequence of this layout.
    pub fn open(self, dir: &Path) -> Result<Box<dyn LidarSequence>> {
        Ok(match self {
            SequenceKind::Kitti360 => Box::new(kitti360::Kitti360Sequence::open(dir)?),
            SequenceKind::Mcd => Box::new(mcd::McdSequence::open(dir)?),
            SequenceKind::KittiRaw => Box::new(kitti_raw::KittiRawDrive::open(dir)?),
        })
    }
}

/// A LiDAR sequence: scans by frame number, each with the sensor's pose in the dataset's
/// georeferenced world frame, and per-point labels where the dataset has them.
///
/// Frames are the numbers of the scan files, sorted; [`LidarSequence::pose_frames`] may hold
/// more (poses between the scans, e.g. the whole drive).
pub trait LidarSequence: Send + Sync {
    /// The layout read, or `None` for a sequence that is not one of [`SequenceKind`]'s
    /// (a simulated dataset).
    fn kind(&self) -> Option<SequenceKind>;

    /// Short name of the layout (`kitti360`, `mcd`, `kitti_raw`, `sim_localization`).
    fn name(&self) -> &'static str;

    /// The sequence folder.
    fn dir(&self) -> &Path;

    /// Whether the scans carry per-point labels (`label`, `raw_label`) where label files exist.
    fn labelled(&self) -> bool;

    /// Frame numbers that have a scan, sorted.
    fn frames(&self) -> Result<Vec<u64>>;

    /// Frame numbers that have a sensor pose, sorted.
    fn pose_frames(&self) -> Result<Vec<u64>>;

    /// Sensor pose of a frame in the world frame ([`DatasetError::MissingPose`] if none).
    fn world_from_sensor(&self, frame: u64) -> Result<Isometry3<f64>>;

    /// The world frame's georeference.
    fn georeference(&self) -> Georeference;

    /// Loads a frame's scan with its labels (where the dataset has them) and pose.
    fn load_scan(&self, frame: u64) -> Result<Scan>;
}

/// Opens a sequence folder of any known layout ([`SequenceKind::of`]).
pub fn open_sequence(dir: impl AsRef<Path>) -> Result<Box<dyn LidarSequence>> {
    let dir = dir.as_ref();
    SequenceKind::of(dir)
        .ok_or_else(|| DatasetError::UnknownLayout {
            path: dir.to_path_buf(),
        })?
        .open(dir)
}

/// A sensor pose in a [`LocalFrame`], with its WGS84 position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalPose {
    /// Sensor position east, north in the local frame and the dataset world's z, metres.
    pub position_m: [f64; 3],
    /// Heading of the sensor's x axis, radians counter-clockwise from grid east.
    pub yaw_rad: f64,
    /// WGS84 latitude of the sensor, degrees.
    pub lat_deg: f64,
    /// WGS84 longitude of the sensor, degrees.
    pub lon_deg: f64,
}

impl Scan {
    /// WGS84 (lat, lon) in degrees of the sensor.
    pub fn sensor_wgs84(&self) -> (f64, f64) {
        let t = self.world_from_sensor.translation.vector;
        self.georef.to_wgs84([t.x, t.y])
    }

    /// The rigid transform from the sensor frame into `frame`.
    ///
    /// The sensor position is mapped exactly (world → WGS84 → local); the rotation is the
    /// world rotation turned by the local frame's meridian convergence there. Within a
    /// scan's 100 m range the remaining scale difference between the two projections is
    /// below 10⁻⁴ (< 1 cm).
    pub fn local_from_sensor(&self, frame: &LocalFrame) -> Isometry3<f64> {
        local_from_world_pose(&self.georef, &self.world_from_sensor, frame)
    }

    /// The sensor pose in `frame`.
    pub fn pose_in_local(&self, frame: &LocalFrame) -> LocalPose {
        let iso = self.local_from_sensor(frame);
        let x_axis = iso.rotation * Vector3::x();
        let (lat_deg, lon_deg) = self.sensor_wgs84();
        let t = iso.translation.vector;
        LocalPose {
            position_m: [t.x, t.y, t.z],
            yaw_rad: x_axis.y.atan2(x_axis.x),
            lat_deg,
            lon_deg,
        }
    }

    /// The cloud registered into `frame` (a copy; positions become f64).
    pub fn cloud_in_local(&self, frame: &LocalFrame) -> PointCloud {
        let mut c = self.cloud.clone();
        c.transform(&self.local_from_sensor(frame));
        c
    }
}

/// Moves a world pose of `georef` rigidly into `frame` (see [`Scan::local_from_sensor`]).
pub fn local_from_world_pose(
    georef: &Georeference,
    world_from_sensor: &Isometry3<f64>,
    frame: &LocalFrame,
) -> Isometry3<f64> {
    let t = world_from_sensor.translation.vector;
    let (lat, lon) = georef.to_wgs84([t.x, t.y]);
    let local_xy = frame.to_local(lat, lon);
    let turn = georef.yaw_to_local_rad([t.x, t.y], frame);
    let rotation =
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), turn) * world_from_sensor.rotation;
    Isometry3::from_parts(Translation3::new(local_xy[0], local_xy[1], t.z), rotation)
}

/// A rigid transform from a 3×4 or 4×4 row-major matrix, projecting R onto SO(3).
pub(crate) fn iso_from_rows(m: &Matrix4<f64>) -> Isometry3<f64> {
    let r: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
    let rot = Rotation3::from_matrix_eps(&r, 1e-12, 100, Rotation3::identity());
    Isometry3::from_parts(
        Translation3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]),
        UnitQuaternion::from_rotation_matrix(&rot),
    )
}

/// Checks that the rotation block of `m` is orthonormal to `tol` (a garbled file is not a pose).
pub(crate) fn check_rotation(m: &Matrix4<f64>, path: &Path, line: usize, tol: f64) -> Result<()> {
    let r: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
    let err = (r.transpose() * r - Matrix3::identity()).abs().max();
    let orthonormal = err <= tol && r.determinant() > 0.0;
    if !orthonormal {
        return Err(DatasetError::Parse {
            path: path.to_path_buf(),
            line,
            message: format!(
                "rotation is not orthonormal (|RᵀR − I| = {err:.2e}, det = {:.4})",
                r.determinant()
            ),
        });
    }
    Ok(())
}

pub(crate) fn read_text(path: &Path) -> Result<String> {
    std::fs::read_to_string(path).map_err(|source| DatasetError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Frame numbers of the files `NNNNNNNNNN.<ext>` in `dir`, sorted.
pub(crate) fn frames_in(dir: &Path, ext: &str) -> Result<Vec<u64>> {
    let io = |source| DatasetError::Io {
        path: dir.to_path_buf(),
        source,
    };
    let mut frames = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io)? {
        let p = entry.map_err(io)?.path();
        if p.extension().and_then(|e| e.to_str()) != Some(ext) {
            continue;
        }
        if let Some(n) = p
            .file_stem()
            .and_then(|s| s.to_str())
            .and_then(|s| s.parse::<u64>().ok())
        {
            frames.push(n);
        }
    }
    frames.sort_unstable();
    Ok(frames)
}

/// Parses whitespace- or comma-separated floats of one line.
pub(crate) fn floats(path: &Path, line: usize, text: &str, sep: char) -> Result<Vec<f64>> {
    text.split(|c: char| c == sep || c.is_whitespace())
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| DatasetError::Parse {
                    path: path.to_path_buf(),
                    line,
                    message: format!("bad number {s:?}"),
                })
        })
        .collect()
}

/// A KITTI-layout `.bin` scan `scans/{frame:010}.bin` of `seq` with the labels of
/// `gt_labels/{frame:010}.bin` when there are any (dataset ids mapped by `map`), its pose and
/// the sequence's georeference.
pub(crate) fn load_bin_scan<S: LidarSequence + ?Sized>(
    seq: &S,
    scans: &str,
    frame: u64,
    map: fn(u32) -> crate::classes::Class,
) -> Result<Scan> {
    let dir = seq.dir();
    let path = dir.join(scans).join(format!("{frame:010}.bin"));
    let (mut cloud, _) =
        crate::cloud::kitti::read_kitti_bin(&path, &crate::cloud::ReadOptions::default())?;
    let label_path = dir.join("gt_labels").join(format!("{frame:010}.bin"));
    if label_path.exists() {
        let raw = crate::cloud::kitti::read_label_file(&label_path, Some(cloud.len()))?;
        attach_labels(&mut cloud, raw, map);
    }
    let world_from_sensor = seq.world_from_sensor(frame)?;
    Ok(Scan {
        frame,
        path,
        cloud,
        world_from_sensor,
        georef: seq.georeference(),
    })
}

/// Sets `label` (urbansem ids via `map`) and `raw_label` of a scan cloud from dataset ids.
pub(crate) fn attach_labels(
    cloud: &mut PointCloud,
    raw: Vec<u32>,
    map: fn(u32) -> crate::classes::Class,
) {
    cloud.label = Some(raw.iter().map(|&r| map(r).id()).collect());
    cloud.raw_label = Some(raw);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn label_sets_are_found_by_their_names() {
        assert_eq!(LabelSet::from_name("mcd"), Some(LabelSet::Mcd));
        assert_eq!(LabelSet::from_name("kitti-360"), Some(LabelSet::Kitti360));
        assert_eq!(LabelSet::from_name("kitti360"), Some(LabelSet::Kitti360));
        assert_eq!(LabelSet::from_name("semantickitti"), None);
        let mut cloud = PointCloud {
            positions: vec![[0.0; 3]; 2],
            ..PointCloud::default()
        };
        LabelSet::Kitti360.attach(&mut cloud, vec![7, 26]);
        assert_eq!(cloud.raw_label, Some(vec![7, 26]));
        let want: Vec<u8> = [7, 26]
            .iter()
            .map(|&r| kitti360::kitti360_class(r).id())
            .collect();
        assert_eq!(cloud.label, Some(want));
    }

    #[test]
    fn local_pose_of_a_world_pose_at_the_frame_origin() {
        let georef = Georeference::ScaledMercator(ScaledMercator::new(59.35, 18.07).unwrap());
        let frame = LocalFrame::new(59.35, 18.07).unwrap();
        let pose = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 5.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.3),
        );
        let l = local_from_world_pose(&georef, &pose, &frame);
        assert!(l.translation.vector.xy().norm() < 1e-6);
        assert!((l.translation.vector.z - 5.0).abs() < 1e-12);
        assert!((l.rotation.angle() - 0.3).abs() < 1e-9);
    }

    #[test]
    fn heading_follows_the_meridian_convergence() {
        // A sensor 10 km east of the local origin looking geographic north: in the local
        // frame its x axis must point along the mapped image of that meridian.
        let georef = Georeference::ScaledMercator(ScaledMercator::new(59.35, 18.07).unwrap());
        let frame = LocalFrame::new(59.35, 18.07).unwrap();
        let pose = Isometry3::from_parts(
            Translation3::new(10_000.0, 0.0, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2),
        );
        let l = local_from_world_pose(&georef, &pose, &frame);
        let x = l.rotation * Vector3::x();
        let (lat0, lon0) = georef.to_wgs84([10_000.0, 0.0]);
        let (lat1, lon1) = georef.to_wgs84([10_000.0, 200.0]);
        let (a, b) = (frame.to_local(lat0, lon0), frame.to_local(lat1, lon1));
        let expected = (b[1] - a[1]).atan2(b[0] - a[0]);
        let got = x.y.atan2(x.x);
        assert!((got - expected).abs() < 1e-6, "{got} vs {expected}");
        assert!(
            (expected - std::f64::consts::FRAC_PI_2).abs() > 1e-3,
            "convergence is not trivial here"
        );
        assert!((l.translation.vector.x - a[0]).abs() < 1e-9);
    }

    #[test]
    fn a_transverse_mercator_world_is_its_own_local_frame() {
        let frame = LocalFrame::new(48.98, 8.39).unwrap();
        let georef = Georeference::TransverseMercator(frame);
        let pose = Isometry3::from_parts(
            Translation3::new(2_000.0, -1_500.0, 1.8),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 2.0),
        );
        let same = local_from_world_pose(&georef, &pose, &frame);
        assert!((same.translation.vector - pose.translation.vector).norm() < 1e-6);
        assert!(same.rotation.angle_to(&pose.rotation) < 1e-9);
        // Into another frame: the same position and geographic heading as through WGS84.
        let other = LocalFrame::new(48.99, 8.42).unwrap();
        let moved = local_from_world_pose(&georef, &pose, &other);
        let (lat, lon) = frame.to_wgs84([2_000.0, -1_500.0]);
        let xy = other.to_local(lat, lon);
        assert!((moved.translation.vector.x - xy[0]).abs() < 1e-6);
        let x = moved.rotation * Vector3::x();
        let geo_other = x.y.atan2(x.x) + other.convergence_rad(xy);
        let geo_world = 2.0 + frame.convergence_rad([2_000.0, -1_500.0]);
        assert!(
            (geo_other - geo_world).abs() < 1e-9,
            "{geo_other} vs {geo_world}"
        );
        assert_eq!(georef.to_world(lat, lon)[0], frame.to_local(lat, lon)[0]);
    }

    #[test]
    fn non_orthonormal_rotation_is_rejected() {
        let mut m = Matrix4::identity();
        m[(0, 0)] = 2.0;
        assert!(check_rotation(&m, Path::new("p.txt"), 3, 1e-3).is_err());
        assert!(check_rotation(&Matrix4::identity(), Path::new("p.txt"), 3, 1e-9).is_ok());
    }
}
