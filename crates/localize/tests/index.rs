//! The map index (`.uloc`, issue 15): a round trip searches exactly as the in-memory map;
//! corrupt, truncated, stale and mismatched indexes are clear errors.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use geodata::osm::OsmMap;
use localize::eval::mcd_scans;
use localize::index::PreparedMap;
use localize::pipeline::{LocalizeOptions, Localizer};
use localize::LocalizeError;
use std::path::PathBuf;

fn data_file(rel: &str) -> PathBuf {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data")).join(rel);
    assert!(p.exists(), "missing shared data: {}", p.display());
    p
}

#[test]
fn index_round_trip_searches_exactly_as_the_map_and_bad_indexes_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let map_path = dir.path().join("kth.osm");
    std::fs::copy(data_file("osm/kth_campus_stockholm.osm"), &map_path).unwrap();
    let map = OsmMap::load(&map_path).unwrap();
    let options = LocalizeOptions::default();
    let direct = Localizer::new(&map, options.clone()).unwrap();

    let index = dir.path().join("kth.uloc");
    let prepared = PreparedMap::build(&map, &options.chamfer, &options.search).unwrap();
    prepared.write(&index, &map_path).unwrap();
    let (read, source) = PreparedMap::read(&index).unwrap();
    assert_eq!(read.edges, prepared.edges);
    assert_eq!(read.dt, prepared.dt);
    assert_eq!(read.pyramid, prepared.pyramid);
    assert_eq!(read.domain, prepared.domain);
    assert_eq!(read.feasible, prepared.feasible);
    let loaded = source.load(&index).unwrap();
    assert_eq!(loaded.buildings.len(), map.buildings.len());
    let indexed = Localizer::with_prepared(&loaded, options.clone(), read).unwrap();

    // The same ranked candidates, bit for bit, on real scans.
    let scans = mcd_scans(&data_file("lidar/mcd_kth_day_06"), &map, 15).unwrap();
    assert!(scans.len() >= 2);
    for s in &scans {
        let a = direct.localize_points(&s.points).unwrap();
        let b = indexed.localize_points(&s.points).unwrap();
        assert!(!a.candidates.is_empty());
        assert_eq!(a.candidates, b.candidates, "{}", s.name);
    }

    // Other preparation options than the index's: an error naming them.
    let mut coarse = options.clone();
    coarse.chamfer.grid_m = 1.0;
    let (again, _) = PreparedMap::read(&index).unwrap();
    match Localizer::with_prepared(&loaded, coarse, again) {
        Err(e @ LocalizeError::PrepMismatch { .. }) => {
            assert!(
                e.to_string().contains("grid_m: index 0.5, requested 1"),
                "{e}"
            )
        }
        other => panic!("expected PrepMismatch, got {:?}", other.err()),
    }

    // Corrupt, truncated, foreign and future files: errors naming the file.
    let bytes = std::fs::read(&index).unwrap();
    let bad = dir.path().join("bad.uloc");
    let expect_err = |b: &[u8], what: &str, needle: &str| {
        std::fs::write(&bad, b).unwrap();
        match PreparedMap::read(&bad) {
            Err(e @ LocalizeError::Index { .. }) => {
                let m = e.to_string();
                assert!(m.contains("bad.uloc") && m.contains(needle), "{what}: {m}");
            }
            Err(e) => panic!("{what}: unexpected error kind {e}"),
            Ok(_) => panic!("{what}: read a bad index"),
        }
    };
    for at in [30, bytes.len() / 2, bytes.len() - 1] {
        let mut b = bytes.clone();
        b[at] ^= 0x10;
        std::fs::write(&bad, &b).unwrap();
        let e = PreparedMap::read(&bad).expect_err("a flipped byte is an error");
        assert!(
            matches!(e, LocalizeError::Index { .. }),
            "flip at {at}: {e}"
        );
    }
    let mut b = bytes.clone();
    b[bytes.len() / 2] ^= 0x01;
    expect_err(&b, "flip in the tensor", "checksum mismatch");
    expect_err(&bytes[..bytes.len() - 100], "truncated", "truncated");
    expect_err(&bytes[..10], "header only", "too short");
    expect_err(
        b"<?xml version='1.0'?><osm></osm>",
        "an OSM file",
        "not a urbansem map index",
    );
    let mut future = bytes.clone();
    future[8] = 9;
    expect_err(&future, "future version", "version 9");
    // A huge count with a valid checksum is refused before allocating.
    let mut huge = bytes.clone();
    let at = 24 + 8 + map_path.to_string_lossy().len() + 12 + 8 * 4 + 4 + 8 + 1 + 8;
    huge[at..at + 8].copy_from_slice(&u64::MAX.to_le_bytes());
    let crc = crc32(&huge[24..]);
    huge[20..24].copy_from_slice(&crc.to_le_bytes());
    expect_err(&huge, "huge edge count", "do not fit");

    // The map changed after indexing: stale.
    let mut changed = std::fs::read(&map_path).unwrap();
    changed.extend_from_slice(b"\n");
    std::fs::write(&map_path, &changed).unwrap();
    let (_, source) = PreparedMap::read(&index).unwrap();
    let e = source.load(&index).expect_err("a changed map is stale");
    assert!(e.to_string().contains("stale"), "{e}");
    // Missing: said so.
    std::fs::remove_file(&map_path).unwrap();
    let e = source.load(&index).expect_err("a missing map is an error");
    assert!(e.to_string().contains("not found"), "{e}");
}

/// CRC-32 (IEEE), as the index stores it.
fn crc32(b: &[u8]) -> u32 {
    let mut c = !0u32;
    for &x in b {
        c ^= u32::from(x);
        for _ in 0..8 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
        }
    }
    !c
}
