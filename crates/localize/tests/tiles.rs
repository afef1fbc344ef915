//! Tiled maps (issue 19): a map small enough for one tensor gives the same ranked candidates
//! tiled and untiled, bit for bit; tile files are checked like indexes.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use geodata::osm::OsmMap;
use localize::eval::mcd_scans;
use localize::eval::run::{run_eval, EvalJob};
use localize::eval::RankMethod;
use localize::pipeline::{LocalizeOptions, Localizer};
use localize::sensor::Vehicle;
use localize::tiles::{
    build_tiles, localize_tiled_batch, read_crop, Manifest, TileOptions, MINIMUM_CAPS_M,
};
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
    // All scans together (each tile read once per round; `localize_tiled` is a batch of one).
    let segments: Vec<_> = scans
        .iter()
        .map(|s| whole.scan_segments(&s.points).unwrap().segments)
        .collect();
    let mut steps = 0;
    let batch = localize_tiled_batch(
        &manifest_path,
        &segments,
        &vec![false; segments.len()],
        &options,
        &MINIMUM_CAPS_M,
        None,
        &mut |_| steps += 1,
    )
    .unwrap();
    assert_eq!(batch.results.len(), scans.len());
    assert!(steps >= 2 * manifest.tiles.len(), "{steps} progress steps");
    // Two scans under caps so tight that they need every round: the same answers.
    let caps = [0.01, 0.02];
    let other = localize_tiled_batch(
        &manifest_path,
        &segments[..2],
        &[false, false],
        &options,
        &caps,
        None,
        &mut |_| {},
    )
    .unwrap();
    for (a, b) in batch.results.iter().zip(&other.results) {
        assert_eq!(a.candidates, b.candidates, "caps {caps:?}");
        assert_eq!(a.raw_poses, b.raw_poses, "caps {caps:?}");
    }
    // Caps must increase and be positive.
    for caps in [&[0.5, 0.4][..], &[0.0], &[f64::NAN]] {
        let e = localize_tiled_batch(
            &manifest_path,
            &segments,
            &vec![false; segments.len()],
            &options,
            caps,
            None,
            &mut |_| {},
        )
        .err()
        .unwrap()
        .to_string();
        assert!(e.contains("minimum caps"), "{e}");
    }
    let mut compared = 0;
    for (n, s) in scans.iter().enumerate() {
        let extracted = whole.scan_segments(&s.points).unwrap();
        let a = whole.localize_segments(&extracted.segments);
        let b = &batch.results[n];
        assert!(!a.candidates.is_empty(), "{}", s.name);
        if !batch.exact[n] {
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

    // The same scans as a car's (poses head along a street): each tile's heading mask flags
    // a pose as the whole map's does, so the answers are the whole map's again.
    let car = LocalizeOptions {
        vehicle: Vehicle::Car,
        ..options.clone()
    };
    let whole_car = Localizer::new(&map, car.clone()).unwrap();
    let car_batch = localize_tiled_batch(
        &manifest_path,
        &segments,
        &vec![true; segments.len()],
        &car,
        &MINIMUM_CAPS_M,
        None,
        &mut |_| {},
    )
    .unwrap();
    let mut fewer_boxes = 0;
    for (n, s) in scans.iter().enumerate() {
        let a = whole_car.localize_segments(&segments[n]);
        let free = whole.localize_segments(&segments[n]);
        fewer_boxes += usize::from(a.search.boxes < free.search.boxes);
        if !car_batch.exact[n] {
            continue;
        }
        let b = &car_batch.results[n];
        assert_eq!(a.raw_poses, b.raw_poses, "car {}", s.name);
        assert_eq!(a.filtered, b.filtered, "car {}", s.name);
        assert_eq!(a.candidates, b.candidates, "car {}", s.name);
    }
    // The mask is on: a car's search bounds fewer boxes.
    assert_eq!(fewer_boxes, scans.len());

    // `localize eval` of the real MCD sequence on the manifest: the scans' truth in the map
    // frame (taken from a tile's crop), and the same top-1 errors as on the map itself.
    let job = |map: &std::path::Path| EvalJob {
        dataset: data_file("lidar/mcd_kth_day_06"),
        map: Some(map.to_path_buf()),
        methods: vec![RankMethod::Reverse],
        options: options.clone(),
        distractors: None,
        limit: Some(2),
        select: None,
        track: None,
        figures: None,
    };
    let on_map = run_eval(&job(&map_path), &mut |_| {}, &mut |_| {}).unwrap();
    let on_tiles = run_eval(&job(&manifest_path), &mut |_| {}, &mut |_| {}).unwrap();
    assert_eq!(on_tiles.scans, 2);
    assert_eq!(on_map.top1_within_2m_3deg, on_tiles.top1_within_2m_3deg);
    assert!(on_tiles.tiled_exact_scans.is_some() && on_map.tiled_exact_scans.is_none());
    for (a, b) in on_map.per_scan.iter().zip(&on_tiles.per_scan) {
        assert_eq!(a.truth, b.truth, "{}", a.scan);
        if on_tiles.tiled_exact_scans == Some(2) {
            assert_eq!(a.top1["reverse"], b.top1["reverse"], "{}", a.scan);
        }
    }

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
