//! Issue 19: the map-building job split into tiles, run in any order, gives the whole map's
//! cells (every core cell equal to the whole map's cell at its key, the cores partitioning
//! the map) and the whole map's objects, including objects that cross tile borders and one
//! seen by two clouds; a re-run is a no-op.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use fleet::map::{plan_map, tile_map_path, MapTileResult};
use fleet::merge::{merge_job, Merged};
use fleet::plan::{Job, Plan};
use fleet::run::run_shard;
use geodata::classes::Class;
use geodata::cloud::{write_cloud, PointCloud};
use srtree::map::{MapOptions, SrMap};
use srtree::objects::{extract_objects, ObjectOptions};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

const RESOLUTION: f64 = 0.2;
const TILE_M: f64 = 20.0;

fn osm() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/osm/kth_campus_stockholm.osm")
}

/// A deterministic jitter in [-0.5, 0.5).
fn jitter(i: usize) -> f64 {
    ((i.wrapping_mul(2_654_435_761) % 1000) as f64) / 1000.0 - 0.5
}

struct Builder {
    cloud: PointCloud,
}

impl Builder {
    fn new() -> Builder {
        Builder {
            cloud: PointCloud {
                label: Some(Vec::new()),
                object: Some(Vec::new()),
                ..Default::default()
            },
        }
    }

    fn push(&mut self, p: [f64; 3], class: Class, object: u32) {
        self.cloud.positions.push(p);
        self.cloud.label.as_mut().unwrap().push(class as u8);
        self.cloud.object.as_mut().unwrap().push(object);
    }

    /// Points on the faces of a box `[lo, hi]`, every `step` metres, jittered.
    fn solid(&mut self, lo: [f64; 3], hi: [f64; 3], step: f64, class: Class, object: u32) {
        let n = |a: f64, b: f64| ((b - a) / step).ceil() as usize + 1;
        let (nx, ny, nz) = (n(lo[0], hi[0]), n(lo[1], hi[1]), n(lo[2], hi[2]));
        let mut k = self.cloud.positions.len();
        for i in 0..nx {
            for j in 0..ny {
                for l in 0..nz {
                    let on_face =
                        i == 0 || j == 0 || l == 0 || i + 1 == nx || j + 1 == ny || l + 1 == nz;
                    if !on_face {
                        continue;
                    }
                    k += 1;
                    let p = [
                        (lo[0] + i as f64 * step + 0.01 * jitter(k)).min(hi[0]),
                        (lo[1] + j as f64 * step + 0.01 * jitter(k + 7)).min(hi[1]),
                        (lo[2] + l as f64 * step).min(hi[2]),
                    ];
                    self.push(p, class, object);
                }
            }
        }
    }
}

fn write(dir: &Path, name: &str, b: Builder) {
    write_cloud(dir.join(name), &b.cloud).unwrap();
}

/// Three labelled clouds over 60 × 40 m: ground, cars across tile borders (one car seen by
/// two clouds), a long building wall across three tiles, a tree in a tile's corner.
fn dataset(dir: &Path) {
    let mut a = Builder::new();
    // Ground: street, no object.
    let mut k = 0usize;
    for i in 0..240 {
        for j in 0..160 {
            k += 1;
            let (x, y) = (
                -10.0 + i as f64 * 0.25 + 0.05 * jitter(k),
                -10.0 + j as f64 * 0.25,
            );
            a.push([x, y, 0.02 * jitter(k + 3)], Class::Street, 0);
        }
    }
    // Cars, some across the tile borders at x = 0, 20 and y = 0, 20.
    let cars = [
        (1, [-2.0, 3.0]),
        (2, [18.5, 7.0]),
        (3, [8.0, -1.0]),
        (4, [19.0, 19.0]),
        (5, [30.0, 12.0]),
        (6, [39.0, 24.0]),
    ];
    for (id, [x, y]) in cars {
        a.solid([x, y, 0.2], [x + 4.2, y + 1.8, 1.6], 0.1, Class::Car, id);
    }
    write(dir, "a.ply", a);
    let mut b = Builder::new();
    // The building's wall: 45 m long, 0.4 m thick, 6 m high, across three tiles.
    b.solid(
        [-5.0, 26.0, 0.0],
        [40.0, 26.4, 6.0],
        0.15,
        Class::Building,
        100,
    );
    // Car 3 again from another scan (its far side).
    b.solid([8.05, -0.95, 0.25], [12.1, 0.75, 1.55], 0.12, Class::Car, 3);
    write(dir, "b.ply", b);
    let mut c = Builder::new();
    c.solid([38.5, 28.5, 0.0], [39.3, 29.3, 5.0], 0.1, Class::Tree, 200);
    c.solid([45.0, -8.0, 0.0], [46.0, -7.0, 2.0], 0.1, Class::Other, 300);
    write(dir, "c.ply", c);
}

fn whole_map(dir: &Path) -> SrMap {
    let clouds: Vec<PointCloud> = ["a.ply", "b.ply", "c.ply"]
        .iter()
        .map(|n| geodata::cloud::read_cloud(dir.join(n)).unwrap())
        .collect();
    let mut map = SrMap::new(MapOptions {
        resolution_m: RESOLUTION,
        ..MapOptions::default()
    })
    .unwrap();
    let scans: Vec<(&PointCloud, Option<[f64; 3]>)> = clouds.iter().map(|c| (c, None)).collect();
    map.insert_scans(&scans).unwrap();
    map
}

#[test]
fn tiled_map_equals_the_whole_map() {
    let dir = tempfile::tempdir().unwrap();
    let inputs = dir.path().join("clouds");
    std::fs::create_dir_all(&inputs).unwrap();
    dataset(&inputs);
    let whole = whole_map(&inputs);
    let objects = extract_objects(&whole, &ObjectOptions::default());
    assert!(objects.len() >= 8, "{} objects", objects.len());

    let out = dir.path().join("results");
    let plan = plan_map(&osm(), &inputs, &out, TILE_M, RESOLUTION).unwrap();
    let plan_path = dir.path().join("plan.json");
    plan.write(&plan_path).unwrap();
    let (plan, _) = Plan::read(&plan_path).unwrap();
    assert_eq!(plan.job, Job::Map);
    // 60 × 40 m of points from (-10, -10): tiles -1..=2 × -1..=1.
    assert_eq!(plan.map_tiles.len(), 12);
    // Every object has exactly one owner.
    let mut owners: BTreeMap<u32, usize> = BTreeMap::new();
    for t in &plan.map_tiles {
        for &id in &t.objects {
            assert!(owners.insert(id, 0).is_none(), "object {id} owned twice");
        }
    }
    assert_eq!(owners.len(), objects.len());

    for id in (0..plan.shards.len()).rev() {
        assert!(!run_shard(&plan_path, id, None).unwrap().skipped);
    }
    let Merged::Map(merged) = merge_job(&plan_path).unwrap() else {
        panic!("not a map merge")
    };

    // Cells: the cores partition the whole map, each core cell equal to the whole map's.
    let occupied = whole.cells().iter().filter(|c| c.occupied()).count();
    assert_eq!(
        merged.tiles.iter().map(|t| t.core_cells).sum::<usize>(),
        occupied
    );
    let mut seen = 0usize;
    for (k, t) in plan.map_tiles.iter().enumerate() {
        let tile = srtree::io::read_map(tile_map_path(&plan, k)).unwrap().cells;
        for c in tile.cells() {
            let inside = c.key[0] >= t.core[0]
                && c.key[0] < t.core[2]
                && c.key[1] >= t.core[1]
                && c.key[1] < t.core[3];
            if !inside || !c.occupied() {
                continue;
            }
            let w = whole
                .cell_at_key(c.key)
                .expect("a core cell the whole map has");
            assert_eq!(c.hits, w.hits, "{:?}", c.key);
            assert_eq!(c.object, w.object, "{:?}", c.key);
            assert_eq!(c.label, w.label, "{:?}", c.key);
            assert_eq!(c.log_odds.to_bits(), w.log_odds.to_bits(), "{:?}", c.key);
            assert_eq!(tile.histogram(c), whole.histogram(w), "{:?}", c.key);
            seen += 1;
        }
    }
    assert_eq!(seen, occupied);

    // Objects: the owned objects are the whole map's.
    let tiled: BTreeMap<u32, (usize, &MapTileResult)> = merged
        .tiles
        .iter()
        .flat_map(|t| {
            t.objects
                .iter()
                .enumerate()
                .map(move |(i, o)| (o.id, (i, t)))
        })
        .collect();
    assert_eq!(tiled.len(), objects.len());
    let close = |a: [f64; 3], b: [f64; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9);
    for o in &objects {
        let (i, t) = tiled[&o.id];
        let r = &t.objects[i];
        assert_eq!(r.class, o.class.name(), "object {}", o.id);
        assert_eq!(r.cells, o.cells.len(), "object {}", o.id);
        assert!(close(r.centroid, o.centroid), "object {}", o.id);
        assert!(
            close(r.centre, o.bbox.centre),
            "object {}: {:?} vs {:?}",
            o.id,
            r.centre,
            o.bbox.centre
        );
        assert!(
            close(r.half_extents, o.bbox.half_extents),
            "object {}",
            o.id
        );
        assert!((r.yaw_rad - o.bbox.yaw_rad).abs() < 1e-9, "object {}", o.id);
    }
    // The wall crosses three tiles and car 3 two clouds; both are whole.
    assert!(objects
        .iter()
        .any(|o| o.id == 100 && o.bbox.half_extents[0].max(o.bbox.half_extents[1]) > 20.0));

    // GeoJSON: a feature per tile and per object; a re-run is a no-op.
    let features = merged.geojson["features"].as_array().unwrap();
    assert_eq!(features.len(), plan.map_tiles.len() + objects.len());
    assert!(run_shard(&plan_path, 0, None).unwrap().skipped);
}

#[test]
fn a_tile_side_that_is_not_a_whole_number_of_cells_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let inputs = dir.path().join("clouds");
    std::fs::create_dir_all(&inputs).unwrap();
    dataset(&inputs);
    let e = plan_map(&osm(), &inputs, &dir.path().join("r"), 20.05, 0.1).unwrap_err();
    assert!(e.to_string().contains("whole number of cells"), "{e}");
    let empty = dir.path().join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let e = plan_map(&osm(), &empty, &dir.path().join("r"), 20.0, 0.1).unwrap_err();
    assert!(e.to_string().contains("no labelled cloud files"), "{e}");
}
