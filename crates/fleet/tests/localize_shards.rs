//! Issue 19: a localization job split into shards over a tiled map, run shard by shard in
//! any order the stages allow, merges into the rows one process computes; re-running a
//! finished shard is a no-op, a corrupt or half-written shard is run again, and the merge
//! names shards without a result.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use fleet::merge::merge;
use fleet::plan::{plan_localize, JobOptions, Plan};
use fleet::run::run_shard;
use fleet::FleetError;
use geodata::cloud::{read_cloud, write_cloud, PointCloud};
use geodata::osm::OsmMap;
use localize::eval::mcd_scans;
use localize::pipeline::scan_segments;
use localize::report::TrackRow;
use localize::tiles::{build_tiles, localize_tiled, read_crop, resolve, Manifest, TileOptions};
use std::path::{Path, PathBuf};

fn data_file(rel: &str) -> PathBuf {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data")).join(rel);
    assert!(p.exists(), "missing shared data: {}", p.display());
    p
}

/// The rows one process computes ([`localize_tiled`] per scan file).
fn single_process(manifest: &Path, inputs: &[PathBuf], options: &JobOptions) -> Vec<TrackRow> {
    let m = Manifest::read(manifest).unwrap();
    let o = options.localize_options(m.grid_m, manifest).unwrap();
    inputs
        .iter()
        .map(|p| {
            let cloud = read_cloud(p).unwrap();
            let e = scan_segments(&o, &cloud.positions).unwrap();
            let mut t = localize_tiled(manifest, &e, &o, None).unwrap();
            t.result.record_extraction(&e);
            let frame = read_crop(&resolve(manifest, &m.tiles[0].crop)).unwrap();
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            TrackRow::new(&frame, &name, &t.result, &e, options.top)
        })
        .collect()
}

#[test]
fn sharded_localization_equals_one_process_and_survives_reruns() {
    let dir = tempfile::tempdir().unwrap();
    let map_path = data_file("osm/kth_campus_stockholm.osm");
    let map = OsmMap::load(&map_path).unwrap();
    let options = JobOptions::default();
    let lo = options.localize_options(0.5, &map_path).unwrap();
    let tiles = dir.path().join("tiles");
    build_tiles(
        &map_path,
        &tiles,
        TileOptions {
            tile_m: 300.0,
            overlap_m: 100.0,
        },
        &lo,
    )
    .unwrap();
    let manifest = tiles.join("manifest.json");
    let inputs = dir.path().join("scans");
    std::fs::create_dir_all(&inputs).unwrap();
    let scans = mcd_scans(&data_file("lidar/mcd_kth_day_06"), &map, 10).unwrap();
    let mut files = Vec::new();
    for s in &scans {
        let path = inputs.join(format!("{}.ply", s.name));
        let cloud = PointCloud {
            positions: s.points.clone(),
            ..Default::default()
        };
        write_cloud(&path, &cloud).unwrap();
        files.push(path);
    }
    files.sort();
    assert!(files.len() >= 3);

    let out = dir.path().join("results");
    let plan = plan_localize(&manifest, &inputs, &out, 2, options.clone()).unwrap();
    let plan_path = dir.path().join("plan.json");
    plan.write(&plan_path).unwrap();
    let (plan, _) = Plan::read(&plan_path).unwrap();
    // extract, three capped minimum rounds, the last minimum round, poses.
    assert_eq!(plan.stages.len(), 6);
    let waves = plan.waves();
    let poses = &waves[5];

    // A later stage before an earlier one: an error naming the missing shards.
    let early = poses[0];
    match run_shard(&plan_path, early, None) {
        Err(e @ FleetError::NotReady { .. }) => assert!(e.to_string().contains("extract"), "{e}"),
        other => panic!("expected NotReady, got {other:?}"),
    }
    // The stages in order, each wave's shards in reverse (any order within a stage).
    for wave in &waves {
        for &id in wave.iter().rev() {
            let o = run_shard(&plan_path, id, None).unwrap();
            assert!(!o.skipped);
        }
    }
    let merged = merge(&plan_path).unwrap();
    let reference = single_process(&manifest, &files, &options);
    assert_eq!(merged.scans, reference);
    assert!(merged.scans.iter().filter(|r| r.lat.is_some()).count() >= 2);

    // Re-running a finished shard: a no-op, the file untouched.
    let id = *poses
        .iter()
        .max_by_key(|&&i| std::fs::metadata(plan.result_path(i)).unwrap().len())
        .unwrap();
    let before = std::fs::read(plan.result_path(id)).unwrap();
    let again = run_shard(&plan_path, id, None).unwrap();
    assert!(again.skipped);
    assert!(std::fs::read(plan.result_path(id)).unwrap() == before);

    // A corrupt result is run again; a shard that died before its completion record is
    // missing in the merge, named, and runs again.
    assert!(!before.is_empty());
    let mut bad = before.clone();
    bad[0] ^= 1;
    std::fs::write(plan.result_path(id), &bad).unwrap();
    let redo = run_shard(&plan_path, id, None).unwrap();
    assert!(!redo.skipped);
    assert!(std::fs::read(plan.result_path(id)).unwrap() == before);
    std::fs::remove_file(plan.done_path(id)).unwrap();
    let e = merge(&plan_path).unwrap_err().to_string();
    assert!(
        e.contains("the merge") && e.contains(&id.to_string()),
        "{e}"
    );
    run_shard(&plan_path, id, None).unwrap();
    assert_eq!(merge(&plan_path).unwrap().scans, reference);

    // A plan that is not one, a shard that does not exist: errors naming the file.
    let e = run_shard(&plan_path, plan.shards.len(), None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("plan.json") && e.contains("no shard"), "{e}");
    let not = dir.path().join("not.json");
    std::fs::write(&not, b"[]").unwrap();
    let e = run_shard(&not, 0, None).unwrap_err().to_string();
    assert!(e.contains("not.json") && e.contains("shard plan"), "{e}");
}
