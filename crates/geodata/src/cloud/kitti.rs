//! KITTI Velodyne scans (`.bin`: little-endian f32 `x y z reflectance` per point) and
//! per-point label files (little-endian u32 per point, as in KITTI-360, SemanticKITTI, MCD).
//!
//! A `.bin` holds only f32 positions and reflectance: writing a cloud with other columns
//! keeps positions (rounded to f32) and intensity (0 when absent) and drops the rest; labels
//! go to a separate file through [`write_label_file`].

use super::{io_err, path_buf, read_full, CloudError, Location, PointCloud, PointRecord};
use super::{Columns, Precision, ReadOptions, ReadReport, Result, Sink};
use crate::fsio::AtomicFile;
use std::fs::File;
use std::io::{BufReader, Write};
use std::path::Path;

/// Bytes per point of a KITTI `.bin`.
pub const KITTI_POINT_BYTES: u64 = 16;

/// Reads a KITTI `.bin` scan: f32 positions and `intensity` (reflectance).
pub fn read_kitti_bin(path: &Path, options: &ReadOptions) -> Result<(PointCloud, ReadReport)> {
    let file = File::open(path).map_err(io_err(path))?;
    let len = file.metadata().map_err(io_err(path))?.len();
    let whole = len / KITTI_POINT_BYTES;
    let expected = usize::try_from(whole).unwrap_or(usize::MAX);
    if len % KITTI_POINT_BYTES != 0 {
        return Err(CloudError::Truncated {
            path: path_buf(path),
            at: Location::Byte(whole * KITTI_POINT_BYTES),
            point: expected,
            expected: expected + 1,
        });
    }
    let columns = Columns {
        intensity: true,
        ..Columns::default()
    };
    let mut sink = Sink::new(
        path,
        PointCloud::with_columns(columns, Precision::F32, expected),
        options,
    );
    let mut r = BufReader::with_capacity(1 << 16, file);
    let mut buf = [0u8; 16];
    for i in 0..expected {
        if !read_full(&mut r, &mut buf).map_err(io_err(path))? {
            // The file shrank while we read it.
            return Err(CloudError::Truncated {
                path: path_buf(path),
                at: Location::Byte(i as u64 * KITTI_POINT_BYTES),
                point: i,
                expected,
            });
        }
        let f = |k: usize| {
            f32::from_le_bytes([buf[4 * k], buf[4 * k + 1], buf[4 * k + 2], buf[4 * k + 3]])
        };
        sink.push(&PointRecord {
            position: [f64::from(f(0)), f64::from(f(1)), f64::from(f(2))],
            intensity: f(3),
            ..PointRecord::default()
        })?;
    }
    Ok(sink.finish())
}

/// Writes a KITTI `.bin` scan (positions as f32, intensity or 0).
pub fn write_kitti_bin(path: &Path, cloud: &PointCloud) -> Result<()> {
    cloud.check_columns()?;
    let mut w = AtomicFile::create(path).map_err(io_err(path))?;
    for (i, p) in cloud.positions.iter().enumerate() {
        let intensity = cloud
            .intensity
            .as_ref()
            .and_then(|v| v.get(i))
            .copied()
            .unwrap_or(0.0);
        let mut rec = [0u8; 16];
        for (k, v) in [p[0] as f32, p[1] as f32, p[2] as f32, intensity]
            .iter()
            .enumerate()
        {
            rec[4 * k..4 * k + 4].copy_from_slice(&v.to_le_bytes());
        }
        w.write_all(&rec).map_err(io_err(path))?;
    }
    w.commit().map_err(io_err(path))
}

/// Reads a per-point label file (u32 little-endian per point); `expected_points` checks its size.
pub fn read_label_file(path: &Path, expected_points: Option<usize>) -> Result<Vec<u32>> {
    let bytes = std::fs::read(path).map_err(io_err(path))?;
    if bytes.len() % 4 != 0 {
        let whole = bytes.len() / 4;
        return Err(CloudError::Truncated {
            path: path_buf(path),
            at: Location::Byte((whole * 4) as u64),
            point: whole,
            expected: expected_points.unwrap_or(whole + 1),
        });
    }
    let labels: Vec<u32> = bytes
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    if let Some(n) = expected_points {
        if labels.len() != n {
            return Err(CloudError::Header {
                path: path_buf(path),
                at: Location::Byte(0),
                message: format!("{} labels for a scan of {n} points", labels.len()),
            });
        }
    }
    Ok(labels)
}

/// Writes a per-point label file (u32 little-endian per point).
pub fn write_label_file(path: &Path, labels: &[u32]) -> Result<()> {
    let mut w = AtomicFile::create(path).map_err(io_err(path))?;
    for l in labels {
        w.write_all(&l.to_le_bytes()).map_err(io_err(path))?;
    }
    w.commit().map_err(io_err(path))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_truncation() {
        let dir = std::env::temp_dir().join(format!("urbansem-kitti-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.bin");
        let mut c = PointCloud::with_columns(
            Columns {
                intensity: true,
                ..Columns::default()
            },
            Precision::F32,
            2,
        );
        c.push(&PointRecord {
            position: [1.5, -2.25, 0.125],
            intensity: 0.5,
            ..PointRecord::default()
        });
        write_kitti_bin(&p, &c).unwrap();
        let (back, _) = read_kitti_bin(&p, &ReadOptions::default()).unwrap();
        assert_eq!(back, c);
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..10]).unwrap();
        let e = read_kitti_bin(&p, &ReadOptions::default()).unwrap_err();
        assert!(
            matches!(
                e,
                CloudError::Truncated {
                    at: Location::Byte(0),
                    ..
                }
            ),
            "{e}"
        );
    }

    #[test]
    fn label_files_are_checked_against_the_scan() {
        // KITTI files have no header count: the file's length is the count. A label file is
        // read whole (its size bounds the allocation) and then compared with the scan's.
        let dir = std::env::temp_dir().join(format!("urbansem-kitti-l-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.label");
        write_label_file(&p, &[1, 2, 70_000]).unwrap();
        assert_eq!(read_label_file(&p, Some(3)).unwrap(), vec![1, 2, 70_000]);
        for expected in [2, 4, usize::MAX] {
            let e = read_label_file(&p, Some(expected)).unwrap_err();
            assert!(matches!(e, CloudError::Header { .. }), "{e}");
        }
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..7]).unwrap();
        let e = read_label_file(&p, None).unwrap_err();
        assert!(
            matches!(
                e,
                CloudError::Truncated {
                    at: Location::Byte(4),
                    point: 1,
                    ..
                }
            ),
            "{e}"
        );
    }
}
