#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]
//! Probe: per-tile search sizes and times.
use geodata::osm::OsmMap;
use localize::pipeline::{LocalizeOptions, Localizer};
use localize::tiles::*;
use std::path::Path;
use std::time::Instant;
fn main() {
    let map_path = Path::new("../shared/data/osm/kth_campus_stockholm.osm");
    let map = OsmMap::load(map_path).unwrap();
    let options = LocalizeOptions::default();
    let whole = Localizer::new(&map, options.clone()).unwrap();
    let out = Path::new("target/tiles_probe");
    let t = Instant::now();
    let tile_m: f64 = std::env::args()
        .nth(1)
        .map_or(150.0, |s| s.parse().unwrap());
    let r = build_tiles(
        map_path,
        out,
        TileOptions {
            tile_m,
            overlap_m: 130.0,
        },
        &options,
    )
    .unwrap();
    eprintln!("build {:.2}s {}", t.elapsed().as_secs_f64(), r.text());
    let manifest_path = out.join("manifest.json");
    let manifest = Manifest::read(&manifest_path).unwrap();
    let scans =
        localize::eval::mcd_scans(Path::new("../shared/data/lidar/mcd_kth_day_06"), &map, 2)
            .unwrap();
    for s in &scans {
        let e = whole.scan_segments(&s.points).unwrap();
        let t = Instant::now();
        let a = whole.localize_scan(&e);
        eprintln!(
            "whole {:.2}s raw {}",
            t.elapsed().as_secs_f64(),
            a.raw_poses
        );
        let t = Instant::now();
        let b = localize_tiled(&manifest_path, &e, &options, None).unwrap();
        eprintln!(
            "tiled {:.2}s raw {} same {} exact {}",
            t.elapsed().as_secs_f64(),
            b.result.raw_poses,
            a.candidates == b.result.candidates,
            b.exact
        );
        if std::env::args().nth(2).is_none() {
            continue;
        }
        for k in 0..manifest.tiles.len() {
            let tile = LoadedTile::read(&manifest_path, &manifest, k).unwrap();
            let ts = search_tile(
                &tile,
                k,
                &e.segments,
                options.vehicle.along_streets(e.sensor.as_ref()),
                &options,
                localize::candidates::Cap::NONE,
            )
            .unwrap();
            eprintln!(
                "tile {k} {:?} raw {} min {:?} {:.2}s",
                manifest.tiles[k].key,
                ts.raw.len(),
                ts.raw.first().map(|r| r[0]),
                ts.seconds
            );
        }
    }
}
