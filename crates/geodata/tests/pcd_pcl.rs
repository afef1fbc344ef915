//! PCD files written by the Point Cloud Library itself (`../shared/data/pcd-pcl`, issue 16):
//! each reads with exactly its header's point count and the values PCL stored.
//!
//! The oracles are independent of the reader: the ASCII files are parsed again by a tiny
//! parser below, and the binary ones are checked against numbers decoded by hand (Python's
//! `struct` plus a separate LZF decoder, see [`BINARY`]). The files are read from the shared
//! folder, never copied into the repository.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use geodata::cloud::{read_cloud, read_cloud_with, CloudError, Location, PointCloud, ReadOptions};
use std::path::{Path, PathBuf};

/// The PCL files of the shared folder (see its `SOURCES.md`).
const FILES: [&str; 10] = [
    "2d_erosion_binary.pcd",
    "brisk_keypoints_gt.pcd",
    "bun0.pcd",
    "car6.pcd",
    "curve_close.pcd",
    "milk_color.pcd",
    "nhood_test.pcd",
    "noisy_slice_displaced.pcd",
    "office1_keypoints.pcd",
    "pcl_logo.pcd",
];

fn pcl_dir() -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/pcd-pcl"
    ))
}

/// A file of the shared PCL folder; a missing one fails with its path named.
fn pcl_file(name: &str) -> PathBuf {
    let p = pcl_dir().join(name);
    assert!(p.exists(), "missing shared data: {}", p.display());
    p
}

/// What a tiny parser, separate from the reader, finds in a PCD header.
struct PlainHeader {
    fields: Vec<String>,
    counts: Vec<usize>,
    points: usize,
    data: String,
    /// Byte offset of the body.
    body: usize,
}

fn plain_header(bytes: &[u8]) -> PlainHeader {
    let mut h = PlainHeader {
        fields: Vec::new(),
        counts: Vec::new(),
        points: usize::MAX,
        data: String::new(),
        body: 0,
    };
    let mut at = 0;
    while h.data.is_empty() {
        let end = at + bytes[at..].iter().position(|&b| b == b'\n').unwrap() + 1;
        let line = std::str::from_utf8(&bytes[at..end]).unwrap();
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.first().copied() {
            Some("FIELDS") => h.fields = words[1..].iter().map(|s| s.to_string()).collect(),
            Some("COUNT") => h.counts = words[1..].iter().map(|s| s.parse().unwrap()).collect(),
            Some("POINTS") => h.points = words[1].parse().unwrap(),
            Some("DATA") => h.data = words[1].to_string(),
            _ => {}
        }
        at = end;
    }
    if h.counts.is_empty() {
        h.counts = vec![1; h.fields.len()];
    }
    h.body = at;
    h
}

/// Sums of x, y and z over all points, added in file order.
fn position_sums(c: &PointCloud) -> [f64; 3] {
    c.positions
        .iter()
        .fold([0.0; 3], |s, p| [s[0] + p[0], s[1] + p[1], s[2] + p[2]])
}

#[test]
fn issue_16_every_pcl_file_reads_with_its_header_point_count() {
    // Every .pcd of the folder, not only the ones named here.
    let mut listed: Vec<String> = std::fs::read_dir(pcl_dir())
        .unwrap_or_else(|e| panic!("missing shared data: {}: {e}", pcl_dir().display()))
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".pcd"))
        .collect();
    listed.sort();
    assert_eq!(listed, FILES, "the shared folder changed");
    for name in FILES {
        let path = pcl_file(name);
        let header = plain_header(&std::fs::read(&path).unwrap());
        let (cloud, report) = read_cloud_with(&path, &ReadOptions::default())
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(cloud.len(), header.points, "{name}");
        assert_eq!(report.points_in_file, header.points, "{name}");
        assert_eq!(report.dropped_non_finite, 0, "{name}");
        cloud.check_columns().unwrap();
    }
}

#[test]
fn issue_16_ascii_files_match_an_independent_parser() {
    // nhood_test.pcd ends without a newline after its last point; bun0.pcd has normals and
    // curvature, which the reader skips.
    for (name, columns) in [
        ("nhood_test.pcd", vec!["x", "y", "z", "intensity"]),
        ("bun0.pcd", vec!["x", "y", "z"]),
    ] {
        let path = pcl_file(name);
        let bytes = std::fs::read(&path).unwrap();
        let h = plain_header(&bytes);
        assert_eq!(h.data, "ascii");
        assert!(h.counts.iter().all(|&c| c == 1));
        let body = std::str::from_utf8(&bytes[h.body..]).unwrap();
        let rows: Vec<Vec<f32>> = body
            .lines()
            .filter(|l| !l.trim().is_empty())
            .take(h.points)
            .map(|l| l.split_whitespace().map(|t| t.parse().unwrap()).collect())
            .collect();
        assert_eq!(rows.len(), h.points, "{name}");
        let col = |field: &str| h.fields.iter().position(|f| f == field).unwrap();
        let cloud = read_cloud(&path).unwrap();
        assert_eq!(cloud.columns().names(), columns, "{name}");
        for (i, row) in rows.iter().enumerate() {
            let want = [row[col("x")], row[col("y")], row[col("z")]].map(f64::from);
            assert_eq!(cloud.positions[i], want, "{name} point {i}");
            if let Some(intensity) = &cloud.intensity {
                assert_eq!(intensity[i], row[col("intensity")], "{name} point {i}");
            }
        }
    }
}

/// Values of the binary files, decoded by hand: Python's `struct.unpack_from("<f", …)` on the
/// bytes after `DATA` (binary: records of Σ SIZE × COUNT bytes; binary_compressed: u32 sizes,
/// then an LZF block decoded by a separate 20-line Python decoder written from the liblzf
/// format, holding the fields column by column). Each f32 is printed as the f64 it widens to,
/// so the comparisons are exact. Sums add x (y, z) over all points in file order.
struct Binary {
    name: &'static str,
    points: usize,
    first: [f64; 3],
    last: [f64; 3],
    sums: [f64; 3],
    columns: &'static [&'static str],
}

const BINARY: [Binary; 8] = [
    Binary {
        name: "2d_erosion_binary.pcd",
        points: 65_536,
        first: [1.0, 1.0, 0.0],
        last: [256.0, 256.0, 0.0],
        sums: [8_421_376.0, 8_421_376.0, 0.0],
        columns: &["x", "y", "z", "intensity"],
    },
    Binary {
        name: "brisk_keypoints_gt.pcd",
        points: 1860,
        first: [228.09454345703125, 3.1916348934173584, 0.0],
        last: [573.159423828125, 390.09423828125, 0.0],
        sums: [535693.2068240643, 542857.5115981102, 0.0],
        // The extra field `scale` is skipped.
        columns: &["x", "y", "z"],
    },
    Binary {
        name: "car6.pcd",
        points: 10_031,
        first: [-36.63999938964844, -61.93000030517578, -6.340000152587891],
        last: [-39.5099983215332, -65.47000122070312, -6.949999809265137],
        sums: [-375096.4949645996, -647618.8002090454, -63155.11009502411],
        columns: &["x", "y", "z"],
    },
    Binary {
        name: "curve_close.pcd",
        points: 110,
        first: [0.26186829805374146, 0.0, 0.0],
        last: [0.4157775044441223, 0.0, 0.0],
        sums: [51.50032071539681, 55.000000044703484, 0.0],
        columns: &["x", "y", "z"],
    },
    Binary {
        name: "milk_color.pcd",
        points: 13_704,
        first: [
            -0.13160760700702667,
            -0.2095429003238678,
            0.7720000147819519,
        ],
        last: [
            0.013806669972836971,
            -0.18820670247077942,
            0.7630000114440918,
        ],
        sums: [-770.3041106266319, -1874.077319541946, 10610.029351890087],
        columns: &["x", "y", "z", "rgb"],
    },
    Binary {
        name: "noisy_slice_displaced.pcd",
        points: 3782,
        first: [1.0356245040893555, 0.7439574599266052, 1.2688339948654175],
        last: [0.9826229810714722, 0.7702863812446594, 1.2959223985671997],
        sums: [3780.9182045459747, 2821.7020642757416, 4847.998939394951],
        columns: &["x", "y", "z"],
    },
    Binary {
        name: "office1_keypoints.pcd",
        points: 1318,
        first: [3.6486306190490723, 4.24565315246582, 0.45956555008888245],
        last: [-10.837611198425293, -5.448917865753174, 0.34905552864074707],
        sums: [408.1211923509836, -1397.7022200096399, 282.80942551861517],
        columns: &["x", "y", "z", "intensity"],
    },
    Binary {
        name: "pcl_logo.pcd",
        points: 12_909,
        first: [-0.961899995803833, 0.24660000205039978, 0.0],
        last: [0.9997000098228455, 0.2168000042438507, 0.0],
        sums: [200.17899521940853, 1943.2658042293042, 0.0],
        columns: &["x", "y", "z", "rgb"],
    },
];

#[test]
fn issue_16_binary_files_match_values_decoded_by_hand() {
    for want in &BINARY {
        let c = read_cloud(pcl_file(want.name)).unwrap_or_else(|e| panic!("{}: {e}", want.name));
        assert_eq!(c.len(), want.points, "{}", want.name);
        assert_eq!(c.positions[0], want.first, "{}", want.name);
        assert_eq!(c.positions[want.points - 1], want.last, "{}", want.name);
        assert_eq!(position_sums(&c), want.sums, "{}", want.name);
        assert_eq!(c.columns().names(), want.columns, "{}", want.name);
    }
    let sum_f32 = |v: &[f32]| v.iter().fold(0.0f64, |s, &x| s + f64::from(x));
    let rgb_sums = |v: &[[u8; 3]]| {
        v.iter().fold([0u64; 3], |s, c| {
            [
                s[0] + u64::from(c[0]),
                s[1] + u64::from(c[1]),
                s[2] + u64::from(c[2]),
            ]
        })
    };
    // Intensity (F4): first, last and sum.
    let c = read_cloud(pcl_file("2d_erosion_binary.pcd")).unwrap();
    let i = c.intensity.as_deref().unwrap();
    assert_eq!((i[0], i[65_535], sum_f32(i)), (255.0, 0.0, 9_820_560.0));
    let c = read_cloud(pcl_file("office1_keypoints.pcd")).unwrap();
    let i = c.intensity.as_deref().unwrap();
    assert_eq!(
        (f64::from(i[0]), f64::from(i[1317]), sum_f32(i)),
        (0.9396741986274719, 0.5670833587646484, 652.1921992003918)
    );
    // `rgba` U4 0xAARRGGBB (milk_color) and `rgb` as the bits of an F4 (pcl_logo; the float's
    // bits 0x4a92ba64 at point 2820 are the colour 146 186 100, its value 4.8e6 is not).
    let c = read_cloud(pcl_file("milk_color.pcd")).unwrap();
    let rgb = c.rgb.as_deref().unwrap();
    assert_eq!((rgb[0], rgb[13_703]), ([103, 90, 85], [89, 83, 78]));
    assert_eq!(rgb_sums(rgb), [1_253_588, 1_270_390, 1_299_452]);
    let c = read_cloud(pcl_file("pcl_logo.pcd")).unwrap();
    let rgb = c.rgb.as_deref().unwrap();
    assert_eq!((rgb[0], rgb[2820]), ([128, 128, 128], [146, 186, 100]));
    assert_eq!(rgb_sums(rgb), [1_761_558, 2_004_238, 1_482_476]);
}

/// Writes `bytes` to a scratch file named `name` and reads it.
fn read_variant(dir: &Path, name: &str, bytes: &[u8]) -> Result<PointCloud, CloudError> {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    read_cloud(&p)
}

#[test]
fn issue_16_padding_is_ignored_but_a_cut_body_is_refused() {
    let dir = std::env::temp_dir().join(format!("urbansem-pcd-pcl-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // curve_close.pcd: binary, 110 points of 12 bytes, then 3928 bytes of PCL's padding.
    let bytes = std::fs::read(pcl_file("curve_close.pcd")).unwrap();
    let h = plain_header(&bytes);
    let end = h.body + 110 * 12;
    let whole = read_cloud(pcl_file("curve_close.pcd")).unwrap();
    assert_eq!(
        read_variant(&dir, "exact.pcd", &bytes[..end]).unwrap(),
        whole
    );
    let mut more = bytes.clone();
    more.extend_from_slice(b"anything at all");
    assert_eq!(read_variant(&dir, "more.pcd", &more).unwrap(), whole);
    match read_variant(&dir, "cut.pcd", &bytes[..end - 5]) {
        Err(CloudError::Truncated {
            at,
            point,
            expected,
            ..
        }) => {
            assert_eq!(at, Location::Byte((h.body + 109 * 12) as u64));
            assert_eq!((point, expected), (109, 110));
        }
        other => panic!("{other:?}"),
    }
    // car6.pcd: binary_compressed; the LZF block ends 3913 bytes before the file does.
    let bytes = std::fs::read(pcl_file("car6.pcd")).unwrap();
    let h = plain_header(&bytes);
    let compressed = u32::from_le_bytes(bytes[h.body..h.body + 4].try_into().unwrap()) as usize;
    let end = h.body + 8 + compressed;
    assert_eq!(bytes.len() - end, 3913);
    let whole = read_cloud(pcl_file("car6.pcd")).unwrap();
    assert_eq!(
        read_variant(&dir, "exact.pcd", &bytes[..end]).unwrap(),
        whole
    );
    for cut in [end - 1, h.body + 8, h.body + 3] {
        let e = read_variant(&dir, "cut.pcd", &bytes[..cut]).unwrap_err();
        assert!(e.to_string().contains("cut.pcd"), "{e}");
    }
    // nhood_test.pcd: ASCII without a final newline; with one, or with lines after the
    // announced points (PCL reads POINTS lines), the same cloud.
    let bytes = std::fs::read(pcl_file("nhood_test.pcd")).unwrap();
    assert_ne!(bytes.last(), Some(&b'\n'));
    let whole = read_cloud(pcl_file("nhood_test.pcd")).unwrap();
    let mut more = bytes.clone();
    more.extend_from_slice(b"\n1 2 3 4\nnot a point\n");
    assert_eq!(read_variant(&dir, "more.pcd", &more).unwrap(), whole);
    // One line short: a truncated file, named with the line where the data ran out.
    let last_line = bytes.iter().rposition(|&b| b == b'\n').unwrap();
    match read_variant(&dir, "cut.pcd", &bytes[..last_line + 1]) {
        Err(CloudError::Truncated {
            at: Location::Line(line),
            point: 35,
            expected: 36,
            ..
        }) => assert_eq!(
            line,
            bytes[..last_line + 1]
                .iter()
                .filter(|&&b| b == b'\n')
                .count()
                + 1
        ),
        other => panic!("{other:?}"),
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn issue_16_a_pcl_file_without_xyz_is_a_clear_error() {
    let dir = std::env::temp_dir().join(format!("urbansem-pcd-pcl-xyz-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // bun0.pcd with its `z` renamed: PCL reads it as a cloud without z; urbansem needs positions.
    let bytes = std::fs::read(pcl_file("bun0.pcd")).unwrap();
    let text = String::from_utf8(bytes).unwrap();
    let renamed = text.replacen("FIELDS x y z ", "FIELDS x y height ", 1);
    assert_ne!(renamed, text);
    match read_variant(&dir, "noz.pcd", renamed.as_bytes()) {
        Err(
            e @ CloudError::Header {
                at: Location::Line(3),
                ..
            },
        ) => {
            let msg = e.to_string();
            assert!(
                msg.contains("noz.pcd") && msg.contains("no field z"),
                "{msg}"
            );
        }
        other => panic!("{other:?}"),
    }
    let _ = std::fs::remove_dir_all(&dir);
}
