//! Point cloud IO: lossless round trips (random clouds and real scans) through every
//! format, and truncated or garbled files give an error naming the file, never a panic.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use geodata::classes::Class;
use geodata::cloud::{
    read_cloud, read_cloud_with, write_cloud, write_cloud_with, CloudError, Columns, Encoding,
    PointCloud, PointRecord, Precision, ReadOptions, WriteOptions,
};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::{Path, PathBuf};

/// A scratch directory removed when dropped.
struct TmpDir(PathBuf);

impl TmpDir {
    fn join(&self, name: impl AsRef<Path>) -> PathBuf {
        self.0.join(name)
    }
}

impl Drop for TmpDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn tmp_dir(name: &str) -> TmpDir {
    let d = std::env::temp_dir().join(format!("urbansem-cloud-io-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    TmpDir(d)
}

fn data_file(rel: &str) -> PathBuf {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data")).join(rel);
    assert!(p.exists(), "missing shared data: {}", p.display());
    p
}

/// An MCD scan with its MCD labels attached (`label` and `raw_label`).
fn mcd_scan_11() -> PointCloud {
    let seq = geodata::datasets::mcd::McdSequence::open(data_file("lidar/mcd_kth_day_06")).unwrap();
    seq.load_scan(11).unwrap().cloud
}

/// (file name, write options) of every format/encoding.
fn formats() -> Vec<(&'static str, Encoding)> {
    vec![
        ("a.ply", Encoding::BinaryLittleEndian),
        ("b.ply", Encoding::BinaryBigEndian),
        ("c.ply", Encoding::Ascii),
        ("d.pcd", Encoding::BinaryLittleEndian),
        ("e.pcd", Encoding::Ascii),
        ("e2.pcd", Encoding::BinaryCompressed),
        ("f.las", Encoding::BinaryLittleEndian),
        ("g.laz", Encoding::BinaryLittleEndian),
    ]
}

/// Checks `back` equals `cloud`: exactly, except LAS positions (0.1 mm grid).
fn assert_same(name: &str, cloud: &PointCloud, back: &PointCloud) {
    let las = name.ends_with(".las") || name.ends_with(".laz");
    if las {
        assert_eq!(back.len(), cloud.len(), "{name}");
        for (a, b) in cloud.positions.iter().zip(&back.positions) {
            for k in 0..3 {
                assert!(
                    (a[k] - b[k]).abs() <= 0.5e-4 + 1e-9 * a[k].abs(),
                    "{name}: {a:?} vs {b:?}"
                );
            }
        }
        let mut b2 = back.clone();
        b2.positions = cloud.positions.clone();
        assert_eq!(&b2, cloud, "{name}");
    } else {
        assert_eq!(back, cloud, "{name}");
    }
}

fn random_cloud(seed: u64, n: usize, columns: Columns, precision: Precision) -> PointCloud {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut c = PointCloud::with_columns(columns, precision, n);
    for _ in 0..n {
        let mut pos = [0.0; 3];
        for v in &mut pos {
            let x: f64 =
                rng.gen_range(-5000.0..5000.0) * if rng.gen_bool(0.1) { 1e-3 } else { 1.0 };
            *v = if precision == Precision::F32 {
                f64::from(x as f32)
            } else {
                x
            };
        }
        c.push(&PointRecord {
            position: pos,
            intensity: if rng.gen_bool(0.5) {
                rng.gen::<f32>()
            } else {
                rng.gen_range(-1e6f32..1e6)
            },
            rgb: rng.gen(),
            label: rng.gen_range(0..Class::COUNT as u8),
            raw_label: rng.gen(),
            object: rng.gen(),
        });
    }
    c
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    #[test]
    fn random_clouds_round_trip_every_format(
        seed in any::<u64>(),
        n in 0usize..200,
        mask in 0u8..32,
        double in any::<bool>(),
    ) {
        let columns = Columns {
            intensity: mask & 1 != 0,
            rgb: mask & 2 != 0,
            label: mask & 4 != 0,
            raw_label: mask & 8 != 0,
            object: mask & 16 != 0,
        };
        let precision = if double { Precision::F64 } else { Precision::F32 };
        let cloud = random_cloud(seed, n, columns, precision);
        let dir = tmp_dir("prop");
        for (name, encoding) in formats() {
            let p = dir.join(name);
            write_cloud_with(&p, &cloud, &WriteOptions { encoding }).unwrap();
            let back = read_cloud(&p).unwrap();
            assert_same(name, &cloud, &back);
        }
        // KITTI .bin holds f32 x y z intensity only.
        let mut kitti = PointCloud::with_columns(Columns { intensity: true, ..Columns::default() }, Precision::F32, n);
        for i in 0..n {
            let p = cloud.get(i).unwrap();
            let f = |v: f64| f64::from(v as f32);
            kitti.push(&PointRecord {
                position: [f(p.position[0]), f(p.position[1]), f(p.position[2])],
                intensity: p.intensity,
                ..PointRecord::default()
            });
        }
        let p = dir.join("h.bin");
        write_cloud(&p, &kitti).unwrap();
        prop_assert_eq!(read_cloud(&p).unwrap(), kitti);
    }
}

#[test]
fn real_scan_round_trips_every_format_and_las_is_idempotent() {
    let cloud = mcd_scan_11();
    assert_eq!(cloud.len(), 65_536);
    let dir = tmp_dir("real");
    for (name, encoding) in formats() {
        let p = dir.join(name);
        write_cloud_with(&p, &cloud, &WriteOptions { encoding }).unwrap();
        let back = read_cloud(&p).unwrap();
        assert_same(name, &cloud, &back);
        if name.ends_with(".las") {
            // LAS → cloud → LAS → cloud reproduces the same cloud exactly.
            let p2 = dir.join("again.las");
            write_cloud(&p2, &back).unwrap();
            assert!(read_cloud(&p2).unwrap() == back, "LAS is not idempotent");
            let same = std::fs::read(&p).unwrap() == std::fs::read(&p2).unwrap();
            assert!(same, "LAS → cloud → LAS changed the file");
        }
    }
    // The real KITTI .bin comes back byte for byte.
    let src = data_file("lidar/mcd_kth_day_06/lidar_bin/0000000011.bin");
    let p = dir.join("scan.bin");
    write_cloud(&p, &read_cloud(&src).unwrap()).unwrap();
    assert!(
        std::fs::read(&src).unwrap() == std::fs::read(&p).unwrap(),
        "KITTI bytes differ"
    );
}

/// Reads `bytes` written to `path`: must not panic; returns the result.
fn read_bytes(path: &Path, bytes: &[u8]) -> Result<PointCloud, CloudError> {
    std::fs::write(path, bytes).unwrap();
    read_cloud(path)
}

#[test]
fn truncated_files_are_errors_naming_the_file() {
    let cloud = random_cloud(
        7,
        300,
        Columns {
            intensity: true,
            rgb: true,
            label: true,
            raw_label: true,
            object: true,
        },
        Precision::F64,
    );
    let dir = tmp_dir("trunc");
    let mut formats = formats();
    formats.push(("k.bin", Encoding::BinaryLittleEndian));
    let mut checked = 0;
    for (name, encoding) in formats {
        let full = dir.join(format!("full-{name}"));
        write_cloud_with(&full, &cloud, &WriteOptions { encoding }).unwrap();
        let bytes = std::fs::read(&full).unwrap();
        let cut = dir.join(format!("cut-{name}"));
        let last_line = bytes[..bytes.len() - 1]
            .iter()
            .rposition(|&b| b == b'\n')
            .map_or(0, |i| i + 1);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut offsets: Vec<usize> = (0..60).map(|_| rng.gen_range(0..bytes.len())).collect();
        offsets.extend([0, 1, 10, bytes.len() - 1, bytes.len() - 2, bytes.len() - 17]);
        for off in offsets {
            match read_bytes(&cut, &bytes[..off]) {
                Err(e) => {
                    let msg = e.to_string();
                    assert!(
                        msg.contains(&cut.display().to_string()),
                        "{name} cut at {off}: {msg}"
                    );
                }
                Ok(c) => {
                    // Only whitespace (an ASCII file's last newline) may be lost harmlessly.
                    // A headerless KITTI .bin cut at a record boundary is a shorter valid scan.
                    if name.ends_with(".bin") && off % 16 == 0 {
                        assert_eq!(c.len(), off / 16);
                        continue;
                    }
                    // PCD ASCII needs no final newline (PCL writes files without one), so a
                    // cut inside the last line's last value cannot be told from a shorter
                    // number: every point but the last is unchanged.
                    if encoding == Encoding::Ascii && name.ends_with(".pcd") && off >= last_line {
                        let n = cloud.len();
                        assert_eq!(c.len(), n, "{name} cut at {off}");
                        let kept = |k: &PointCloud| k.filter(|i| i + 1 < n);
                        assert_eq!(kept(&c), kept(&cloud), "{name} cut at {off}");
                        continue;
                    }
                    let lost = &bytes[off..];
                    assert!(
                        lost.iter().all(u8::is_ascii_whitespace),
                        "{name} cut at {off} read {} points",
                        c.len()
                    );
                }
            }
            checked += 1;
        }
    }
    assert!(checked > 400);
}

#[test]
fn garbled_files_never_panic() {
    let cloud = random_cloud(
        9,
        200,
        Columns {
            intensity: true,
            rgb: true,
            label: true,
            ..Columns::default()
        },
        Precision::F32,
    );
    let dir = tmp_dir("garble");
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let mut errors = 0usize;
    let mut formats = formats();
    formats.push(("k.bin", Encoding::BinaryLittleEndian));
    for (name, encoding) in formats {
        let full = dir.join(format!("full-{name}"));
        write_cloud_with(&full, &cloud, &WriteOptions { encoding }).unwrap();
        let bytes = std::fs::read(&full).unwrap();
        let bad = dir.join(format!("bad-{name}"));
        for round in 0..80 {
            let mut b = bytes.clone();
            // Half the rounds hit the first 400 bytes (headers), half anywhere.
            let hi = if round % 2 == 0 {
                b.len().min(400)
            } else {
                b.len()
            };
            for _ in 0..rng.gen_range(1..4) {
                let i = rng.gen_range(0..hi);
                b[i] = rng.gen();
            }
            if read_bytes(&bad, &b).is_err() {
                errors += 1;
            }
        }
    }
    assert!(errors > 50, "only {errors} garbled files were rejected");
}

#[test]
fn nan_positions_are_errors_or_counted_drops_in_every_format() {
    let mut cloud = random_cloud(
        3,
        50,
        Columns {
            intensity: true,
            ..Columns::default()
        },
        Precision::F32,
    );
    cloud.positions[17][1] = f64::NAN;
    cloud.positions[30][2] = f64::INFINITY;
    let dir = tmp_dir("nan");
    for name in ["a.ply", "b.pcd", "c.bin"] {
        let p = dir.join(name);
        write_cloud(&p, &cloud).unwrap();
        match read_cloud(&p) {
            Err(CloudError::NonFinite { point, path, .. }) => {
                assert_eq!(point, 17, "{name}");
                assert_eq!(path, p);
            }
            other => panic!("{name}: expected NonFinite, got {other:?}"),
        }
        let (c, report) = read_cloud_with(
            &p,
            &ReadOptions {
                drop_non_finite: true,
            },
        )
        .unwrap();
        assert_eq!(
            (c.len(), report.dropped_non_finite, report.points_in_file),
            (48, 2, 50),
            "{name}"
        );
    }
}

#[test]
fn bad_labels_and_headers_are_named() {
    let dir = tmp_dir("labels");
    let p = dir.join("l.ply");
    std::fs::write(
        &p,
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nproperty uchar label\nend_header\n0 0 0 2\n1 1 1 26\n",
    )
    .unwrap();
    assert!(matches!(
        read_cloud(&p),
        Err(CloudError::BadLabel {
            point: 1,
            value: 26,
            ..
        })
    ));
    let p = dir.join("h.pcd");
    std::fs::write(&p, "VERSION .7\nFIELDS x y z\nSIZE 4 4\nTYPE F F F\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n0 0 0\n").unwrap();
    let e = read_cloud(&p).unwrap_err();
    assert!(e.to_string().contains("line 3: bad header: SIZE"), "{e}");
    let p = dir.join("count.pcd");
    std::fs::write(&p, "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 3\nHEIGHT 1\nPOINTS 2\nDATA ascii\n0 0 0\n").unwrap();
    assert!(matches!(read_cloud(&p), Err(CloudError::Header { .. })));
}

#[test]
fn truncated_real_scans_name_the_byte_offset() {
    let src = data_file("lidar/kitti360_2013_05_28_drive_0009/velodyne_points/0000002000.bin");
    let bytes = std::fs::read(&src).unwrap();
    let dir = tmp_dir("real-trunc");
    let cut = dir.join("cut.bin");
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for _ in 0..20 {
        let off = rng.gen_range(1..bytes.len() / 16) * 16 + rng.gen_range(1..16);
        match read_bytes(&cut, &bytes[..off]) {
            Err(CloudError::Truncated { at, point, .. }) => {
                assert_eq!(at, geodata::cloud::Location::Byte((off / 16 * 16) as u64));
                assert_eq!(point, off / 16);
            }
            other => panic!("cut at {off}: {other:?}"),
        }
    }
    let labels = data_file("lidar/kitti360_2013_05_28_drive_0009/gt_labels/0000002000.bin");
    let lbytes = std::fs::read(&labels).unwrap();
    let lcut = dir.join("labels.bin");
    std::fs::write(&lcut, &lbytes[..lbytes.len() - 2]).unwrap();
    assert!(geodata::cloud::kitti::read_label_file(&lcut, None).is_err());
    std::fs::write(&lcut, &lbytes[..lbytes.len() - 4]).unwrap();
    let e = geodata::cloud::kitti::read_label_file(&lcut, Some(bytes.len() / 16)).unwrap_err();
    assert!(e.to_string().contains("labels for a scan of"), "{e}");
    // The real scan converted to each format, then cut.
    let cloud = read_cloud(&src).unwrap();
    for (name, encoding) in formats() {
        let full = dir.join(format!("full-{name}"));
        write_cloud_with(&full, &cloud, &WriteOptions { encoding }).unwrap();
        let b = std::fs::read(&full).unwrap();
        let cut = dir.join(format!("cut-{name}"));
        for _ in 0..8 {
            let off = rng.gen_range(0..b.len() - 1);
            let r = read_bytes(&cut, &b[..off]);
            assert!(
                r.is_err() || b[off..].iter().all(u8::is_ascii_whitespace),
                "{name} cut at {off}"
            );
        }
    }
}

#[test]
fn binary_ply_skips_unknown_properties_and_elements_by_type() {
    let dir = tmp_dir("ply-unknown");
    let p = dir.join("u.ply");
    let mut bytes = b"ply\nformat binary_little_endian 1.0\ncomment other tool\nelement camera 1\nproperty double fx\n\
property list uint short ids\nelement vertex 2\nproperty uchar flags\nproperty float x\nproperty short nx\n\
property float y\nproperty double quality\nproperty float z\nproperty list uchar uint nbrs\nproperty int label\n\
element face 1\nproperty list uchar int vertex_indices\nend_header\n"
        .to_vec();
    // camera: fx, 3 ids
    bytes.extend_from_slice(&500.0f64.to_le_bytes());
    bytes.extend_from_slice(&3u32.to_le_bytes());
    for id in [1i16, 2, 3] {
        bytes.extend_from_slice(&id.to_le_bytes());
    }
    for (i, (x, y, z)) in [(1.5f32, 2.5f32, 3.5f32), (-1.0, -2.0, -3.0)]
        .iter()
        .enumerate()
    {
        bytes.push(7);
        bytes.extend_from_slice(&x.to_le_bytes());
        bytes.extend_from_slice(&(-5i16).to_le_bytes());
        bytes.extend_from_slice(&y.to_le_bytes());
        bytes.extend_from_slice(&0.9f64.to_le_bytes());
        bytes.extend_from_slice(&z.to_le_bytes());
        bytes.push(i as u8); // i neighbours
        for k in 0..i as u32 {
            bytes.extend_from_slice(&k.to_le_bytes());
        }
        bytes.extend_from_slice(&(Class::Tree.id() as i32).to_le_bytes());
    }
    bytes.push(3);
    for v in [0i32, 1, 0] {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    std::fs::write(&p, &bytes).unwrap();
    let c = read_cloud(&p).unwrap();
    assert_eq!(c.positions, vec![[1.5, 2.5, 3.5], [-1.0, -2.0, -3.0]]);
    assert_eq!(c.label, Some(vec![Class::Tree.id(); 2]));
    assert_eq!(c.columns().names(), vec!["x", "y", "z", "label"]);
    // One byte more than announced is trailing data, named with its offset.
    bytes.push(0);
    std::fs::write(&p, &bytes).unwrap();
    match read_cloud(&p) {
        Err(CloudError::TrailingData { at, extra: 1, .. }) => {
            assert_eq!(at, geodata::cloud::Location::Byte(bytes.len() as u64 - 1));
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn foreign_las_without_urbansem_vlr_maps_classification_colour_and_intensity() {
    use las::{Builder, Color, Point, Writer};
    let dir = tmp_dir("las-foreign");
    let p = dir.join("foreign.las");
    let mut builder = Builder::from((1, 2));
    builder.point_format = las::point::Format::new(3).unwrap();
    let header = builder.into_header().unwrap();
    let mut w = Writer::from_path(&p, header).unwrap();
    for (i, code) in [2u8, 6, 5, 11, 9].iter().enumerate() {
        w.write_point(Point {
            x: i as f64,
            y: 0.5,
            z: -1.25,
            intensity: 1000 + i as u16,
            classification: las::point::Classification::new(*code).unwrap(),
            color: Some(Color {
                red: 0xff00,
                green: 0x1234,
                blue: 0,
            }),
            gps_time: Some(0.0),
            ..Point::default()
        })
        .unwrap();
    }
    w.close().unwrap();
    drop(w);
    let c = read_cloud(&p).unwrap();
    assert_eq!(c.len(), 5);
    assert_eq!(c.raw_label, Some(vec![2, 6, 5, 11, 9]));
    let classes: Vec<Class> = (0..5).map(|i| c.class(i)).collect();
    assert_eq!(
        classes,
        vec![
            Class::Unlabelled,
            Class::Building,
            Class::Tree,
            Class::Street,
            Class::Other
        ]
    );
    assert_eq!(c.rgb.as_ref().unwrap()[0], [0xff, 0x12, 0]);
    assert_eq!(c.intensity.as_ref().unwrap()[4], 1004.0);
    assert_eq!(c.positions[3], [3.0, 0.5, -1.25]);
}
