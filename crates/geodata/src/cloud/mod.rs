//! The column-wise [`PointCloud`] and its file formats: PLY, PCD, LAS/LAZ, KITTI `.bin`, and
//! ROS 2 bags (`.mcap`, read only: see [`mcap`]).
//!
//! A cloud is one vector of positions plus optional columns of the same length:
//! `intensity` (f32), `rgb` ([u8; 3]), `label` (urbansem [`Class`] id), `raw_label` (the
//! dataset's own class id, kept so that no information is lost), `object` (u32 object id).
//! [`Precision`] records whether the positions were stored as f32 or f64, so that writing
//! a cloud back gives the same bytes it was read from.
//!
//! [`read_cloud`] and [`write_cloud`] pick the format from the extension. Every reader
//! streams through a `BufReader` and checks each position: a NaN or infinite coordinate is
//! a [`CloudError::NonFinite`] naming the file and the point, unless
//! [`ReadOptions::drop_non_finite`] is set, in which case the point is skipped and counted
//! in [`ReadReport::dropped_non_finite`].
//!
//! Every reader takes time linear in its file and never allocates or loops for a count the
//! file's length cannot hold: header counts (PLY `element`, PCD `POINTS`, the uncompressed
//! size of PCD `binary_compressed`, the LAS point count, EVLR and LAZ chunk-table sizes) are
//! checked against the bytes that follow before anything is sized by them, and a count too
//! large is an error naming the file and the line or byte.
//!
//! | format | positions | intensity | rgb | label | raw_label | object |
//! |---|---|---|---|---|---|---|
//! | PLY (ascii, binary LE/BE) | float/double | float | uchar red green blue | uchar | uint | uint |
//! | PCD (ascii, binary, binary_compressed; read as PCL does, see [`pcd`]) | F4/F8 (read: any numeric) | F4 | U4 `rgb` (0x00RRGGBB; F4-packed `rgb`/`rgba` and U1 `r g b` read) | U1 | U4 (read: also a wider `label`) | U4 |
//! | LAS/LAZ 1.4 (format 6/7) | integer grid, 0.1 mm | u16 field + exact f32 in extra bytes | u16 ×257 | classification (see [`las`]) | extra bytes | extra bytes |
//! | KITTI `.bin` | f32 | f32 reflectance | – | separate uint32 label file | separate | – |
//! | ROS 2 bag `.mcap` (read only; `sensor_msgs/msg/PointCloud2`, see [`mcap`]) | any numeric `x y z` | any numeric `intensity` | – | UINT8 `label` | wider `label`, `raw_label` | `object` |
//!
//! ```
//! use geodata::cloud::{read_cloud, write_cloud, Columns, PointCloud, PointRecord, Precision};
//! let columns = Columns { intensity: true, ..Columns::default() };
//! let mut cloud = PointCloud::with_columns(columns, Precision::F32, 1);
//! cloud.push(&PointRecord { position: [1.0, 2.5, -3.0], intensity: 0.25, ..PointRecord::default() });
//! let path = std::env::temp_dir().join(format!("urbansem-doc-{}.ply", std::process::id()));
//! write_cloud(&path, &cloud)?;
//! assert_eq!(read_cloud(&path)?, cloud);
//! # std::fs::remove_file(&path)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod error;
mod guard;
pub mod info;
pub mod kitti;
pub mod las;
pub mod lzf;
pub mod mcap;
pub mod pcd;
pub mod ply;

pub use error::{CloudError, Location, Result};

use crate::classes::Class;
use nalgebra::{Isometry3, Point3};
use std::path::{Path, PathBuf};

/// How positions are (or were) stored in a file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Precision {
    /// 32-bit floats (KITTI, most scanners).
    #[default]
    F32,
    /// 64-bit floats (georeferenced clouds).
    F64,
}

/// Axis-aligned bounds of a cloud's positions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounds {
    /// Smallest x, y, z.
    pub min: [f64; 3],
    /// Largest x, y, z.
    pub max: [f64; 3],
}

/// One point's values, used to push into or read out of a [`PointCloud`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PointRecord {
    /// Position (x, y, z) in metres.
    pub position: [f64; 3],
    /// Intensity / reflectance.
    pub intensity: f32,
    /// Colour.
    pub rgb: [u8; 3],
    /// urbansem class id ([`Class::id`]).
    pub label: u8,
    /// Dataset class id.
    pub raw_label: u32,
    /// Object id.
    pub object: u32,
}

/// Which optional columns a cloud has.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Columns {
    /// `intensity` present.
    pub intensity: bool,
    /// `rgb` present.
    pub rgb: bool,
    /// `label` present.
    pub label: bool,
    /// `raw_label` present.
    pub raw_label: bool,
    /// `object` present.
    pub object: bool,
}

impl Columns {
    /// Names of the present columns, positions first (`x`, `y`, `z`).
    pub fn names(&self) -> Vec<&'static str> {
        let mut v = vec!["x", "y", "z"];
        let flags = [
            (self.intensity, "intensity"),
            (self.rgb, "rgb"),
            (self.label, "label"),
            (self.raw_label, "raw_label"),
            (self.object, "object"),
        ];
        v.extend(flags.iter().filter(|(on, _)| *on).map(|(_, n)| *n));
        v
    }
}

/// A point cloud stored column-wise: positions plus optional per-point columns.
///
/// Invariant checked by [`PointCloud::check_columns`] (and by every writer): each present
/// column has exactly one value per position.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PointCloud {
    /// Positions (x, y, z) in metres.
    pub positions: Vec<[f64; 3]>,
    /// How positions are stored in files.
    pub precision: Precision,
    /// Intensity / reflectance per point.
    pub intensity: Option<Vec<f32>>,
    /// sRGB colour per point.
    pub rgb: Option<Vec<[u8; 3]>>,
    /// urbansem class id per point ([`Class::id`]).
    pub label: Option<Vec<u8>>,
    /// The dataset's own class id per point.
    pub raw_label: Option<Vec<u32>>,
    /// Object (instance) id per point.
    pub object: Option<Vec<u32>>,
}

impl PointCloud {
    /// An empty cloud with the given columns.
    pub fn with_columns(columns: Columns, precision: Precision, capacity: usize) -> Self {
        Self {
            positions: Vec::with_capacity(capacity),
            precision,
            intensity: columns.intensity.then(|| Vec::with_capacity(capacity)),
            rgb: columns.rgb.then(|| Vec::with_capacity(capacity)),
            label: columns.label.then(|| Vec::with_capacity(capacity)),
            raw_label: columns.raw_label.then(|| Vec::with_capacity(capacity)),
            object: columns.object.then(|| Vec::with_capacity(capacity)),
        }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// True when the cloud has no points.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Which optional columns are present.
    pub fn columns(&self) -> Columns {
        Columns {
            intensity: self.intensity.is_some(),
            rgb: self.rgb.is_some(),
            label: self.label.is_some(),
            raw_label: self.raw_label.is_some(),
            object: self.object.is_some(),
        }
    }

    /// Checks that every present column has one value per point.
    pub fn check_columns(&self) -> Result<()> {
        let n = self.positions.len();
        let check = |column: &'static str, len: Option<usize>| match len {
            Some(len) if len != n => Err(CloudError::ColumnLength {
                column,
                len,
                points: n,
            }),
            _ => Ok(()),
        };
        check("intensity", self.intensity.as_ref().map(Vec::len))?;
        check("rgb", self.rgb.as_ref().map(Vec::len))?;
        check("label", self.label.as_ref().map(Vec::len))?;
        check("raw_label", self.raw_label.as_ref().map(Vec::len))?;
        check("object", self.object.as_ref().map(Vec::len))
    }

    /// Appends a point; values of columns the cloud does not have are ignored.
    pub fn push(&mut self, p: &PointRecord) {
        self.positions.push(p.position);
        if let Some(c) = &mut self.intensity {
            c.push(p.intensity);
        }
        if let Some(c) = &mut self.rgb {
            c.push(p.rgb);
        }
        if let Some(c) = &mut self.label {
            c.push(p.label);
        }
        if let Some(c) = &mut self.raw_label {
            c.push(p.raw_label);
        }
        if let Some(c) = &mut self.object {
            c.push(p.object);
        }
    }

    /// The values of point `i` (absent columns give 0), or `None` past the end.
    pub fn get(&self, i: usize) -> Option<PointRecord> {
        let position = *self.positions.get(i)?;
        fn col<T: Copy + Default>(c: &Option<Vec<T>>, i: usize) -> T {
            c.as_ref()
                .and_then(|v| v.get(i).copied())
                .unwrap_or_default()
        }
        Some(PointRecord {
            position,
            intensity: col(&self.intensity, i),
            rgb: col(&self.rgb, i),
            label: col(&self.label, i),
            raw_label: col(&self.raw_label, i),
            object: col(&self.object, i),
        })
    }

    /// The class of point `i` (`Unlabelled` without a label column or for a bad id).
    pub fn class(&self, i: usize) -> Class {
        self.label
            .as_ref()
            .and_then(|l| l.get(i))
            .and_then(|&id| Class::from_id(id))
            .unwrap_or(Class::Unlabelled)
    }

    /// Axis-aligned bounds, `None` for an empty cloud.
    pub fn bounds(&self) -> Option<Bounds> {
        let first = *self.positions.first()?;
        let mut b = Bounds {
            min: first,
            max: first,
        };
        for p in &self.positions {
            for (k, v) in p.iter().enumerate() {
                b.min[k] = b.min[k].min(*v);
                b.max[k] = b.max[k].max(*v);
            }
        }
        Some(b)
    }

    /// Number of points per [`Class`], indexed by class id (all zero without labels).
    pub fn class_histogram(&self) -> [usize; Class::COUNT] {
        let mut h = [0usize; Class::COUNT];
        if let Some(labels) = &self.label {
            for &l in labels {
                if let Some(slot) = h.get_mut(usize::from(l)) {
                    *slot += 1;
                }
            }
        }
        h
    }

    /// Applies a rigid transform `target_from_cloud` to every position.
    ///
    /// The cloud becomes [`Precision::F64`] when it was f32, since moved f32 coordinates
    /// are in general no longer representable as f32.
    pub fn transform(&mut self, target_from_cloud: &Isometry3<f64>) {
        for p in &mut self.positions {
            let q = target_from_cloud.transform_point(&Point3::new(p[0], p[1], p[2]));
            *p = [q.x, q.y, q.z];
        }
        self.precision = Precision::F64;
    }

    /// A new cloud with the points whose index satisfies `keep`, all columns kept.
    pub fn filter(&self, mut keep: impl FnMut(usize) -> bool) -> PointCloud {
        let mut out = PointCloud::with_columns(self.columns(), self.precision, 0);
        for i in 0..self.len() {
            if keep(i) {
                if let Some(p) = self.get(i) {
                    out.push(&p);
                }
            }
        }
        out
    }

    /// Appends `other`; columns present in only one cloud are filled with 0 for the other's points.
    ///
    /// The result is f64 precision if either input is.
    pub fn extend(&mut self, other: &PointCloud) {
        let n = self.len();
        fn merge<T: Copy + Default>(
            a: &mut Option<Vec<T>>,
            b: &Option<Vec<T>>,
            n: usize,
            m: usize,
        ) {
            match (a.as_mut(), b) {
                (Some(a), Some(b)) => a.extend_from_slice(b),
                (Some(a), None) => a.extend(std::iter::repeat_n(T::default(), m)),
                (None, Some(b)) => {
                    let mut v = vec![T::default(); n];
                    v.extend_from_slice(b);
                    *a = Some(v);
                }
                (None, None) => {}
            }
        }
        let m = other.len();
        merge(&mut self.intensity, &other.intensity, n, m);
        merge(&mut self.rgb, &other.rgb, n, m);
        merge(&mut self.label, &other.label, n, m);
        merge(&mut self.raw_label, &other.raw_label, n, m);
        merge(&mut self.object, &other.object, n, m);
        self.positions.extend_from_slice(&other.positions);
        if other.precision == Precision::F64 {
            self.precision = Precision::F64;
        }
    }

    /// The concatenation of several clouds (see [`PointCloud::extend`]).
    pub fn concat<'a>(clouds: impl IntoIterator<Item = &'a PointCloud>) -> PointCloud {
        let mut out = PointCloud::default();
        for c in clouds {
            out.extend(c);
        }
        out
    }
}

/// Options for reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ReadOptions {
    /// Skip points with a NaN/infinite coordinate instead of failing (they are counted).
    pub drop_non_finite: bool,
}

/// What a reader did besides returning the cloud.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ReadReport {
    /// Points in the file.
    pub points_in_file: usize,
    /// Points skipped because of a non-finite coordinate.
    pub dropped_non_finite: usize,
}

/// Text or binary encoding for formats that offer both.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Encoding {
    /// Human-readable text.
    Ascii,
    /// Binary little-endian (the default).
    #[default]
    BinaryLittleEndian,
    /// Binary big-endian (PLY only; PCD binary is always little-endian).
    BinaryBigEndian,
    /// PCD `binary_compressed` (LZF); other formats write their binary little-endian form.
    BinaryCompressed,
}

/// Options for writing.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct WriteOptions {
    /// PLY/PCD encoding.
    pub encoding: Encoding,
}

/// A file format, chosen from the extension by [`Format::from_path`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// Stanford PLY.
    Ply,
    /// PCL's PCD.
    Pcd,
    /// ASPRS LAS.
    Las,
    /// LASzip-compressed LAS.
    Laz,
    /// KITTI Velodyne `.bin` (f32 x y z reflectance).
    KittiBin,
    /// A ROS 2 bag (rosbag2 MCAP), read only: the first message of its only PointCloud2 topic.
    Mcap,
}

impl Format {
    /// The format named by the path's extension (case-insensitive).
    pub fn from_path(path: &Path) -> Result<Format> {
        let extension = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        match extension.as_str() {
            "ply" => Ok(Format::Ply),
            "pcd" => Ok(Format::Pcd),
            "las" => Ok(Format::Las),
            "laz" => Ok(Format::Laz),
            "bin" => Ok(Format::KittiBin),
            "mcap" => Ok(Format::Mcap),
            _ => Err(CloudError::UnknownFormat {
                path: path.to_path_buf(),
                extension,
            }),
        }
    }

    /// Short lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Format::Ply => "ply",
            Format::Pcd => "pcd",
            Format::Las => "las",
            Format::Laz => "laz",
            Format::KittiBin => "kitti-bin",
            Format::Mcap => "mcap",
        }
    }
}

/// Reads a cloud, format by extension; a non-finite position is an error. A `.mcap` bag
/// gives the first message of its only PointCloud2 topic ([`mcap::read_bag_cloud`] picks others).
pub fn read_cloud(path: impl AsRef<Path>) -> Result<PointCloud> {
    read_cloud_with(path, &ReadOptions::default()).map(|(c, _)| c)
}

/// Reads a cloud with options, returning what was dropped.
pub fn read_cloud_with(
    path: impl AsRef<Path>,
    options: &ReadOptions,
) -> Result<(PointCloud, ReadReport)> {
    let path = path.as_ref();
    match Format::from_path(path)? {
        Format::Ply => ply::read_ply(path, options),
        Format::Pcd => pcd::read_pcd(path, options),
        Format::Las | Format::Laz => las::read_las(path, options),
        Format::KittiBin => kitti::read_kitti_bin(path, options),
        Format::Mcap => mcap::read_bag_cloud(path, None, 0, options),
    }
}

/// Writes a cloud, format by extension, with default options (binary where possible).
pub fn write_cloud(path: impl AsRef<Path>, cloud: &PointCloud) -> Result<()> {
    write_cloud_with(path, cloud, &WriteOptions::default())
}

/// Writes a cloud with options.
pub fn write_cloud_with(
    path: impl AsRef<Path>,
    cloud: &PointCloud,
    options: &WriteOptions,
) -> Result<()> {
    let path = path.as_ref();
    cloud.check_columns()?;
    match Format::from_path(path)? {
        Format::Ply => ply::write_ply(path, cloud, options.encoding),
        Format::Pcd => pcd::write_pcd(path, cloud, options.encoding),
        Format::Las | Format::Laz => las::write_las(path, cloud),
        Format::KittiBin => kitti::write_kitti_bin(path, cloud),
        Format::Mcap => Err(CloudError::Unsupported {
            path: path.to_path_buf(),
            what: "writing ROS 2 bags (.mcap is read only)".into(),
        }),
    }
}

/// Collects points from a reader, enforcing finite positions and label ids.
pub(crate) struct Sink<'a> {
    pub(crate) cloud: PointCloud,
    path: &'a Path,
    options: ReadOptions,
    index: usize,
    dropped: usize,
}

impl<'a> Sink<'a> {
    pub(crate) fn new(path: &'a Path, cloud: PointCloud, options: &ReadOptions) -> Self {
        Self {
            cloud,
            path,
            options: *options,
            index: 0,
            dropped: 0,
        }
    }

    pub(crate) fn push(&mut self, p: &PointRecord) -> Result<()> {
        let i = self.index;
        self.index += 1;
        if self.cloud.label.is_some() && Class::from_id(p.label).is_none() {
            return Err(CloudError::BadLabel {
                path: self.path.to_path_buf(),
                point: i,
                value: u64::from(p.label),
            });
        }
        if !p.position.iter().all(|v| v.is_finite()) {
            if self.options.drop_non_finite {
                self.dropped += 1;
                return Ok(());
            }
            return Err(CloudError::NonFinite {
                path: self.path.to_path_buf(),
                point: i,
                position: p.position,
            });
        }
        self.cloud.push(p);
        Ok(())
    }

    pub(crate) fn finish(self) -> (PointCloud, ReadReport) {
        let report = ReadReport {
            points_in_file: self.index,
            dropped_non_finite: self.dropped,
        };
        (self.cloud, report)
    }
}

/// Writes `x y z` as ASCII text at the cloud's stored precision (f32 values print as f32,
/// so that reading them back gives the same numbers).
pub(crate) fn write_ascii_position(
    w: &mut impl std::io::Write,
    precision: Precision,
    position: [f64; 3],
) -> std::io::Result<()> {
    match precision {
        Precision::F32 => write!(
            w,
            "{} {} {}",
            position[0] as f32, position[1] as f32, position[2] as f32
        ),
        Precision::F64 => write!(w, "{} {} {}", position[0], position[1], position[2]),
    }
}

/// Reads the ASCII line of point `point` (of `expected`) into `line` (cleared first): a
/// line that is missing or lacks its line end is a cut file; non-UTF-8 text is a bad value
/// of `field`.
pub(crate) fn read_point_line(
    r: &mut impl std::io::BufRead,
    line: &mut String,
    path: &Path,
    line_no: usize,
    field: &str,
    point: usize,
    expected: usize,
) -> Result<()> {
    line.clear();
    let n = r.read_line(line).map_err(|e| match e.kind() {
        std::io::ErrorKind::InvalidData => CloudError::BadValue {
            path: path_buf(path),
            at: Location::Line(line_no),
            field: field.to_owned(),
            value: "non-UTF-8 text".into(),
        },
        _ => io_err(path)(e),
    })?;
    // A point line without its line end is a cut file (the last number may be partial).
    if n == 0 || !line.ends_with('\n') {
        return Err(CloudError::Truncated {
            path: path_buf(path),
            at: Location::Line(line_no),
            point,
            expected,
        });
    }
    Ok(())
}

pub(crate) fn io_err(path: &Path) -> impl Fn(std::io::Error) -> CloudError + '_ {
    move |source| CloudError::Io {
        path: path.to_path_buf(),
        source,
    }
}

pub(crate) fn path_buf(path: &Path) -> PathBuf {
    path.to_path_buf()
}

/// Reads exactly `buf.len()` bytes, or reports whether the data ended early.
///
/// Returns `Ok(false)` at a clean or partial end of data (the caller turns it into
/// [`CloudError::Truncated`]).
pub(crate) fn read_full(r: &mut impl std::io::Read, buf: &mut [u8]) -> std::io::Result<bool> {
    let mut filled = 0;
    while filled < buf.len() {
        match r.read(&mut buf[filled..]) {
            Ok(0) => return Ok(false),
            Ok(n) => filled += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small() -> PointCloud {
        let mut c = PointCloud::with_columns(
            Columns {
                intensity: true,
                label: true,
                ..Columns::default()
            },
            Precision::F32,
            3,
        );
        for i in 0..3 {
            c.push(&PointRecord {
                position: [i as f64, 2.0 * i as f64, -1.0],
                intensity: i as f32,
                label: Class::Building.id(),
                ..PointRecord::default()
            });
        }
        c
    }

    #[test]
    fn bounds_filter_concat() {
        let c = small();
        let b = c.bounds().unwrap();
        assert_eq!(b.min, [0.0, 0.0, -1.0]);
        assert_eq!(b.max, [2.0, 4.0, -1.0]);
        let f = c.filter(|i| i != 1);
        assert_eq!(f.len(), 2);
        assert_eq!(f.intensity.as_deref(), Some(&[0.0f32, 2.0][..]));
        let mut other = PointCloud::default();
        other.push(&PointRecord::default());
        other.rgb = Some(vec![[1, 2, 3]]);
        let all = PointCloud::concat([&c, &other]);
        all.check_columns().unwrap();
        assert_eq!(all.len(), 4);
        assert_eq!(all.rgb.as_ref().unwrap()[0], [0, 0, 0]);
        assert_eq!(all.rgb.as_ref().unwrap()[3], [1, 2, 3]);
        assert_eq!(all.class_histogram()[Class::Building.id() as usize], 3);
    }

    #[test]
    fn transform_moves_points() {
        let mut c = small();
        let iso = Isometry3::translation(1.0, 0.0, 0.0)
            * Isometry3::rotation(nalgebra::Vector3::z() * std::f64::consts::FRAC_PI_2);
        c.transform(&iso);
        let p = c.positions[1];
        assert!(
            (p[0] - -1.0).abs() < 1e-12 && (p[1] - 1.0).abs() < 1e-12,
            "{p:?}"
        );
        assert_eq!(c.precision, Precision::F64);
    }

    #[test]
    fn column_length_mismatch_is_reported() {
        let mut c = small();
        c.intensity = Some(vec![1.0]);
        assert!(matches!(
            c.check_columns(),
            Err(CloudError::ColumnLength {
                column: "intensity",
                ..
            })
        ));
    }

    #[test]
    fn unknown_extension() {
        assert!(matches!(
            Format::from_path(Path::new("a.xyz")),
            Err(CloudError::UnknownFormat { .. })
        ));
    }
}
