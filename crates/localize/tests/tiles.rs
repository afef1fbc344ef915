//! Tiled maps (issue 19): a map small enough for one tensor gives the same ranked candidates
//! tiled and untiled, bit for bit; tile files are checked like indexes.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use geodata::osm::OsmMap;
use localize::eval::mcd_scans;
use localize::pipeline::{LocalizeOptions, Localizer};
use localize::tiles::{build_tiles, localize_tiled, read_crop, Manifest, TileOptions};
use localize::LocalizeError;
use std::path::PathBuf;

fn data_file(rel: &str) -> PathBuf {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data")).join(rel);
    assert!(p.exists(), "missing shared data: {}", p.display());
    p
}

#[test]
fn tiled_and_untiled_maps_give_the_same_ranked_candidates() {
    let dir = tempfile::tempdir().unwrap();
    let map_path = data_file("osm/kth_campus_stockholm.osm");
    let map = OsmMap::load(&map_path).unwrap();
    let options = LocalizeOptions::default();
    let whole = Localizer::new(&map, options.clone()).unwrap();
    // Tiles of 150 m: the 0.6 × 0.7 km campus is cut into ~25 tiles, so many candidates lie
    // near tile borders; the overlap covers the scans' reach and the visibility range.
    let out = dir.path().join("tiles");
    let report = build_tiles(
        &map_path,
        &out,
        TileOptions {
            tile_m: 150.0,
            overlap_m: 130.0,
        },
        &options,
    )
    .unwrap();
    assert!(report.tiles >= 12, "{report:?}");
    let manifest_path = out.join("manifest.json");
    let manifest = Manifest::read(&manifest_path).unwrap();
    assert_eq!(manifest.tiles.len(), report.tiles);
    assert!(report.max_tile_memory_bytes > 0);
    // Every tile's tensor is smaller than the whole map's.
    let whole_bytes = whole.dt.bytes() as u64;
    assert!(manifest.tiles.iter().all(|t| t.memory_bytes < whole_bytes));

    let scans = mcd_scans(&data_file("lidar/mcd_kth_day_06"), &map, 5).unwrap();
    assert!(scans.len() >= 3);
    let mut compared = 0;
    for s in &scans {
        let extracted = whole.scan_segments(&s.points).unwrap();
        let a = whole.localize_segments(&extracted.segments);
        let tiled = localize_tiled(&manifest_path, &extracted.segments, &options, None).unwrap();
        let b = &tiled.result;
        assert!(!a.candidates.is_empty(), "{}", s.name);
        if !tiled.exact {
            continue;
        }
        compared += 1;
        assert_eq!(a.raw_poses, b.raw_poses, "{}", s.name);
        assert_eq!(a.after_suppression, b.after_suppression, "{}", s.name);
        assert_eq!(a.filtered, b.filtered, "{}", s.name);
        assert_eq!(a.candidates, b.candidates, "{}", s.name);
        assert_eq!(a.confidence, b.confidence, "{}", s.name);
        assert_eq!(a.message, b.message, "{}", s.name);
    }
    assert!(compared >= 3, "only {compared} scans within the overlap");

    // A crop round-trips; a flipped byte is an error naming the file.
    let crop_path = out.join(&manifest.tiles[0].crop.path);
    let crop = read_crop(&crop_path).unwrap();
    assert!(!crop.buildings.is_empty());
    let mut bytes = std::fs::read(&crop_path).unwrap();
    let k = bytes.len() / 2;
    bytes[k] ^= 0x40;
    let bad = dir.path().join("bad.umap");
    std::fs::write(&bad, &bytes).unwrap();
    match read_crop(&bad) {
        Err(e @ LocalizeError::Index { .. }) => assert!(e.to_string().contains("bad.umap"), "{e}"),
        other => panic!(
            "expected an index error, got {:?}",
            other.map(|m| m.buildings.len())
        ),
    }
    // A manifest that is not one: an error naming it.
    let not = dir.path().join("not.json");
    std::fs::write(&not, b"{\"format\": 3}").unwrap();
    let e = Manifest::read(&not).unwrap_err().to_string();
    assert!(e.contains("not.json") && e.contains("tile manifest"), "{e}");
}
