//! Issue 19: the streets job split into shards, one per street tile with a halo of its
//! owned segments' whole coupling components, run in any order, merges into exactly the
//! estimates `StreetModel::estimate` gives on the whole map (and the same GeoJSON);
//! re-running a finished shard is a no-op and the merge names shards without a result.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use fleet::merge::{merge, merge_job, Merged};
use fleet::plan::{Job, Plan};
use fleet::run::run_shard;
use fleet::streets::plan_streets;
use fleet::FleetError;
use geodata::cloud::{read_cloud, write_cloud};
use geodata::osm::OsmMap;
use std::collections::BTreeSet;
use streets::model::{network_edges, StreetModel};

#[test]
fn sharded_streets_equal_the_whole_map_estimate_and_survive_reruns() {
    let dir = tempfile::tempdir().unwrap();
    let map_path = dir.path().join("lattice.osm");
    std::fs::write(&map_path, streets::synthetic::lattice_osm_xml()).unwrap();
    let map = OsmMap::load(&map_path).unwrap();
    let lattice = streets::synthetic::lattice().unwrap();
    let cloud = lattice.cloud.clone();
    let cloud_path = dir.path().join("cloud.ply");
    write_cloud(&cloud_path, &cloud).unwrap();
    let model = streets::synthetic::lattice_model(&lattice).unwrap();
    let model_path = dir.path().join("model.json");
    std::fs::write(&model_path, serde_json::to_vec(&model).unwrap()).unwrap();
    // The model and the cloud as every shard reads them back.
    let model = StreetModel::from_json(&std::fs::read(&model_path).unwrap(), &model_path).unwrap();
    let cloud = read_cloud(&cloud_path).unwrap();
    let whole = model.estimate(&map, &cloud, "lattice", "cloud").unwrap();
    assert!(whole.segments.len() >= 20, "{}", whole.segments.len());

    // 40 m tiles: many shards, and coupling components crossing tile borders.
    let plan_path = dir.path().join("plan.json");
    let results = dir.path().join("plan.d");
    let plan = plan_streets(&map_path, &cloud_path, &model_path, None, &results, 40.0).unwrap();
    plan.write(&plan_path).unwrap();
    let (read, _) = Plan::read(&plan_path).unwrap();
    assert_eq!(read, plan);
    assert_eq!(plan.job, Job::Streets);
    assert_eq!(plan.stages.len(), 1);
    assert_eq!(plan.stages[0].name, "tiles");
    assert_eq!(plan.shards.len(), plan.street_tiles.len());
    assert!(plan.shards.len() >= 9, "{} shards", plan.shards.len());
    assert_eq!(
        plan.street_tiles,
        streets::tiles::plan_tiles(&map, 40.0).unwrap()
    );

    // Some coupling component of the whole map spans more than one tile.
    let observed: Vec<usize> = whole.segments.iter().map(|e| e.segment).collect();
    let owner = |s: usize| {
        plan.street_tiles
            .iter()
            .position(|t| t.owned.contains(&s))
            .unwrap()
    };
    let crossing = network_edges(&map, &observed, &model.geometry)
        .iter()
        .filter(|e| owner(observed[e.s1]) != owner(observed[e.s2]))
        .count();
    assert!(crossing > 0, "no coupling crosses a tile border");

    // The merge names the shards still missing.
    let ids: Vec<usize> = plan.shards.iter().map(|s| s.id).rev().collect();
    run_shard(&plan_path, ids[0], None).unwrap();
    match merge_job(&plan_path) {
        Err(FleetError::NotReady { missing, stage, .. }) => {
            assert_eq!(missing.len(), plan.shards.len() - 1);
            assert_eq!(stage, "tiles");
        }
        other => panic!("expected NotReady, got {other:?}"),
    }
    // Every shard, in reverse order; a second run of each is a no-op.
    let mut halo_total = 0;
    for &id in &ids {
        let first = run_shard(&plan_path, id, None).unwrap();
        assert_eq!(first.skipped, id == ids[0]);
        assert_eq!(first.records, 1);
        let again = run_shard(&plan_path, id, None).unwrap();
        assert!(again.skipped);
        assert_eq!((again.bytes, again.crc32), (first.bytes, first.crc32));
        let line = std::fs::read_to_string(&first.result).unwrap();
        let part: streets::tiles::TileEstimates = serde_json::from_str(line.trim_end()).unwrap();
        halo_total += part.halo.len();
    }
    assert!(halo_total > 0, "no tile read a halo");

    let Merged::Streets(merged) = merge_job(&plan_path).unwrap() else {
        panic!("a streets plan merged as localization");
    };
    assert_eq!(merged.estimates, whole, "merged tiles ≠ whole-map estimate");
    assert_eq!(merged.shards, plan.shards.len());
    let geojson = streets::geojson::feature_collection(&map, &whole.segments, model.target);
    assert_eq!(merged.geojson, geojson);
    streets::geojson::validate(&merged.geojson).unwrap();
    // Every estimated segment is in the GeoJSON exactly once.
    let features = merged.geojson["features"].as_array().unwrap();
    assert_eq!(features.len(), whole.segments.len());
    let segments: BTreeSet<usize> = whole.segments.iter().map(|e| e.segment).collect();
    assert_eq!(segments.len(), whole.segments.len());

    // The localization merge refuses a streets plan by name.
    let err = merge(&plan_path).unwrap_err().to_string();
    assert!(
        err.contains("Streets") && err.contains("merge_job"),
        "{err}"
    );

    // A changed model is refused by a shard that has to run.
    let mut bytes = std::fs::read(&model_path).unwrap();
    bytes.push(b'\n');
    std::fs::write(&model_path, &bytes).unwrap();
    std::fs::remove_file(plan.done_path(ids[0])).unwrap();
    let err = run_shard(&plan_path, ids[0], None).unwrap_err().to_string();
    assert!(err.contains("street model changed"), "{err}");
}

#[test]
fn a_with_sidewalk_model_with_margins_runs_the_driving_area_first_and_equals_the_whole_map() {
    let dir = tempfile::tempdir().unwrap();
    let map_path = dir.path().join("lattice.osm");
    std::fs::write(&map_path, streets::synthetic::lattice_osm_xml()).unwrap();
    let map = OsmMap::load(&map_path).unwrap();
    let lattice = streets::synthetic::lattice().unwrap();
    let cloud_path = dir.path().join("cloud.ply");
    write_cloud(&cloud_path, &lattice.cloud).unwrap();
    let write_model = |name: &str, m: &StreetModel| {
        let path = dir.path().join(name);
        std::fs::write(&path, serde_json::to_vec(m).unwrap()).unwrap();
        let back = StreetModel::from_json(&std::fs::read(&path).unwrap(), &path).unwrap();
        (path, back)
    };
    let (driving_path, driving) = write_model(
        "driving.json",
        &streets::synthetic::lattice_model(&lattice).unwrap(),
    );
    let (sidewalk_path, sidewalk) = write_model(
        "sidewalk.json",
        &streets::synthetic::lattice_sidewalk_model(&lattice).unwrap(),
    );
    assert!(sidewalk.wants_driving_area());
    let cloud = read_cloud(&cloud_path).unwrap();
    let whole = sidewalk
        .estimate_with_driving(Some(&driving), &map, &cloud, ("lattice", "cloud"), 0)
        .unwrap();
    assert!(whole.segments.len() >= 20, "{}", whole.segments.len());
    // The driving area matters: without it the same model estimates otherwise.
    let plain = sidewalk.estimate(&map, &cloud, "lattice", "cloud").unwrap();
    assert_ne!(plain.segments, whole.segments);

    // Without a driving model, and with a driving model of the wrong kind: refused by name.
    let results = dir.path().join("plan.d");
    let err = plan_streets(&map_path, &cloud_path, &sidewalk_path, None, &results, 40.0)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("sidewalk.json") && err.contains("--driving-model"),
        "{err}"
    );
    let err = plan_streets(
        &map_path,
        &cloud_path,
        &sidewalk_path,
        Some(&sidewalk_path),
        &results,
        40.0,
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("not a driving-area model") || err.contains("driving-area"),
        "{err}"
    );
    let err = plan_streets(
        &map_path,
        &cloud_path,
        &driving_path,
        Some(&driving_path),
        &results,
        40.0,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("driving.json"), "{err}");

    let plan = plan_streets(
        &map_path,
        &cloud_path,
        &sidewalk_path,
        Some(&driving_path),
        &results,
        40.0,
    )
    .unwrap();
    let plan_path = dir.path().join("plan.json");
    plan.write(&plan_path).unwrap();
    let n = plan.street_tiles.len();
    assert!(n >= 9, "{n} tiles");
    let names: Vec<&str> = plan.stages.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["driving", "tiles"]);
    assert_eq!(plan.shards.len(), 2 * n);
    assert_eq!(plan.stages[1].shards, (n..2 * n).collect::<Vec<_>>());

    // A with-sidewalk tile before the driving area is done names the stage it waits for.
    match run_shard(&plan_path, n, None) {
        Err(FleetError::NotReady { stage, missing, .. }) => {
            assert_eq!(stage, "driving");
            assert_eq!(missing.len(), n);
        }
        other => panic!("expected NotReady, got {other:?}"),
    }
    for wave in plan.waves() {
        for id in wave.into_iter().rev() {
            run_shard(&plan_path, id, None).unwrap();
        }
    }
    let Merged::Streets(merged) = merge_job(&plan_path).unwrap() else {
        panic!("a streets plan merged as another job");
    };
    assert_eq!(merged.shards, n);
    assert_eq!(merged.estimates, whole, "merged tiles ≠ whole-map estimate");
    let geojson = streets::geojson::feature_collection(&map, &whole.segments, sidewalk.target);
    assert_eq!(merged.geojson, geojson);
    // The driving-area model is checked like every file of the plan.
    let mut bytes = std::fs::read(&driving_path).unwrap();
    bytes.push(b'\n');
    std::fs::write(&driving_path, &bytes).unwrap();
    std::fs::remove_file(plan.done_path(0)).unwrap();
    let err = run_shard(&plan_path, 0, None).unwrap_err().to_string();
    assert!(err.contains("driving-area model changed"), "{err}");
}
