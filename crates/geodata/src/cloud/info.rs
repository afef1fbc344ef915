//! What a point cloud file holds (`urbansem cloud info`): size, columns, bounds, classes.

use super::{Format, PointCloud, Precision, ReadReport};
use crate::classes::Class;
use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

/// Axis-aligned bounds of the positions, metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BoundsInfo {
    /// Smallest x, y, z.
    pub min: [f64; 3],
    /// Largest x, y, z.
    pub max: [f64; 3],
}

/// The statistics of one point cloud file (`cloud info --json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CloudInfo {
    /// The file.
    pub file: String,
    /// Its format's short name.
    pub format: String,
    /// File size in bytes.
    pub bytes: u64,
    /// Points read.
    pub points: usize,
    /// Points in the file.
    pub points_in_file: usize,
    /// Points skipped for a non-finite coordinate.
    pub dropped_non_finite: usize,
    /// Column names.
    pub columns: Vec<String>,
    /// `f32` or `f64` positions.
    pub precision: String,
    /// Bounds of the positions (`None` for an empty cloud).
    pub bounds: Option<BoundsInfo>,
    /// Points per class name (empty without labels).
    pub classes: BTreeMap<String, usize>,
    /// Seconds spent reading.
    pub read_seconds: f64,
    /// Points read per second.
    pub points_per_second: f64,
}

impl CloudInfo {
    /// The statistics of `cloud`, read from `file` (`bytes` long, `format`) in `read_seconds`.
    pub fn new(
        file: &Path,
        format: Format,
        bytes: u64,
        cloud: &PointCloud,
        report: &ReadReport,
        read_seconds: f64,
    ) -> Self {
        let hist = cloud.class_histogram();
        let classes = if cloud.label.is_some() {
            Class::ALL
                .iter()
                .map(|c| (c.name().to_string(), hist[c.id() as usize]))
                .collect()
        } else {
            BTreeMap::new()
        };
        Self {
            file: file.display().to_string(),
            format: format.name().to_owned(),
            bytes,
            points: cloud.len(),
            points_in_file: report.points_in_file,
            dropped_non_finite: report.dropped_non_finite,
            columns: cloud
                .columns()
                .names()
                .into_iter()
                .map(str::to_owned)
                .collect(),
            precision: match cloud.precision {
                Precision::F32 => "f32",
                Precision::F64 => "f64",
            }
            .to_owned(),
            bounds: cloud.bounds().map(|b| BoundsInfo {
                min: b.min,
                max: b.max,
            }),
            classes,
            read_seconds,
            points_per_second: if read_seconds > 0.0 {
                cloud.len() as f64 / read_seconds
            } else {
                f64::INFINITY
            },
        }
    }

    /// A readable summary, one line per topic (classes in [`Class::ALL`] order).
    pub fn text(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(out, "{}", self.file);
        let _ = writeln!(out, "  format     {} ({} bytes)", self.format, self.bytes);
        let _ = writeln!(out, "  points     {}", self.points);
        if self.dropped_non_finite > 0 {
            let _ = writeln!(
                out,
                "  dropped    {} of {} points with non-finite coordinates",
                self.dropped_non_finite, self.points_in_file
            );
        }
        let _ = writeln!(
            out,
            "  columns    {} (positions {})",
            self.columns.join(" "),
            self.precision
        );
        if let Some(b) = self.bounds {
            let _ = writeln!(
                out,
                "  bounds     x {:.3} .. {:.3}, y {:.3} .. {:.3}, z {:.3} .. {:.3} m",
                b.min[0], b.max[0], b.min[1], b.max[1], b.min[2], b.max[2]
            );
        }
        if !self.classes.is_empty() {
            let _ = writeln!(out, "  classes");
            for c in Class::ALL {
                let n = self.classes.get(c.name()).copied().unwrap_or(0);
                if n > 0 {
                    let pct = 100.0 * n as f64 / self.points.max(1) as f64;
                    let _ = writeln!(out, "    {:<11} {n:>10} ({pct:5.1} %)", c.name());
                }
            }
        }
        let _ = writeln!(
            out,
            "  read       {:.3} s ({:.2} M points/s)",
            self.read_seconds,
            self.points_per_second / 1e6
        );
        out
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn classes_are_listed_in_class_order_and_empty_ones_left_out() {
        let cloud = PointCloud {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 2.0, 3.0],
                [2.0, 0.0, 1.0],
                [0.0, 1.0, 0.0],
            ],
            label: Some(vec![
                Class::Tree.id(),
                Class::Car.id(),
                Class::Car.id(),
                Class::Tree.id(),
            ]),
            ..PointCloud::default()
        };
        let report = ReadReport {
            points_in_file: 4,
            dropped_non_finite: 0,
        };
        let info = CloudInfo::new(Path::new("c.ply"), Format::Ply, 100, &cloud, &report, 0.0);
        assert_eq!(info.classes.len(), Class::ALL.len());
        assert_eq!(info.classes["car"], 2);
        assert_eq!(info.points_per_second, f64::INFINITY);
        assert_eq!(
            info.bounds,
            Some(BoundsInfo {
                min: [0.0; 3],
                max: [2.0, 2.0, 3.0]
            })
        );
        let text = info.text();
        let car = text.find("    car ").unwrap();
        let tree = text.find("    tree ").unwrap();
        assert!(car < tree, "Class::ALL order: {text}");
        assert!(
            !text.contains("building"),
            "empty classes are left out: {text}"
        );
        assert!(
            text.contains("  car                  2 ( 50.0 %)\n"),
            "{text}"
        );
    }

    #[test]
    fn a_cloud_without_labels_has_no_classes() {
        let cloud = PointCloud {
            positions: vec![[0.0, 0.0, 0.0]],
            ..PointCloud::default()
        };
        let report = ReadReport {
            points_in_file: 1,
            dropped_non_finite: 0,
        };
        let info = CloudInfo::new(
            Path::new("c.bin"),
            Format::KittiBin,
            16,
            &cloud,
            &report,
            1.0,
        );
        assert!(info.classes.is_empty());
        assert!(!info.text().contains("classes"));
        assert_eq!(info.points_per_second, 1.0);
    }
}
