//! Issue 19: streets over map tiles equal streets over the whole map — bit for bit, on a
//! synthetic lattice and on the real KITTI-360 drive 0009 with its OSM roads, with tree and
//! with loopy coupling, tile sides from 40 m to one tile for everything; each tile's halo
//! equals the coupling components computed by brute force from the whole map's network.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use geodata::cloud::PointCloud;
use geodata::osm::OsmMap;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use streets::corridor::CorridorOptions;
use streets::dataset::SegmentTruth;
use streets::inference::{Edge, Network};
use streets::model::{
    network_edges, ClassifierOptions, Estimates, GeometryOptions, StreetModel, Target,
};
use streets::potentials::SegmentPotential;
use streets::tiles::{merge_tiles, plan_tiles, TileGrid};
use streets::StreetsError;

/// The lattice fixture: map, cloud, truth.
fn lattice() -> (OsmMap, PointCloud, Vec<SegmentTruth>) {
    let l = streets::synthetic::lattice().unwrap();
    (l.map, l.cloud, l.truth)
}

/// The lattice fixture's model.
fn lattice_model(map: &OsmMap, cloud: &PointCloud, truth: &[SegmentTruth]) -> StreetModel {
    streets::synthetic::lattice_model(&streets::synthetic::Lattice {
        map: map.clone(),
        cloud: cloud.clone(),
        truth: truth.to_vec(),
    })
    .unwrap()
}

/// KITTI-360 drive 0009 (real scans, registered) on its OSM roads.
fn kitti360_drive_0009_on_its_roads() -> streets::real::RealDataset {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    let dir: PathBuf = data.join("lidar/kitti360_2013_05_28_drive_0009");
    let map = data.join("osm/karlsruhe_west_kitti360_0009_roads.osm");
    for p in [&dir, &map] {
        assert!(p.exists(), "missing shared data: {}", p.display());
    }
    streets::real::load_sequence(
        &dir,
        &map,
        &CorridorOptions::default(),
        &streets::real::TruthOptions::default(),
        &|_, _| {},
    )
    .unwrap()
}

/// The coupling components of the whole map's network by union-find (the oracle of the
/// halos): component id per observed segment.
fn components_by_union_find(
    map: &OsmMap,
    observed: &[usize],
    geometry: &GeometryOptions,
) -> Vec<(usize, usize)> {
    let mut parent: Vec<usize> = (0..observed.len()).collect();
    fn find(p: &mut [usize], mut x: usize) -> usize {
        while p[x] != x {
            x = p[x];
        }
        x
    }
    for e in network_edges(map, observed, geometry) {
        let (a, b) = (find(&mut parent, e.s1), find(&mut parent, e.s2));
        parent[a] = b;
    }
    (0..observed.len())
        .map(|k| (observed[k], find(&mut parent, k)))
        .collect()
}

/// Tiles of `grid` merged equal the whole map's estimate; every drivable segment is owned
/// once, by the tile holding its midpoint; each tile's halo is the rest of its owned
/// segments' components. Returns (tiles, components crossing a tile border).
fn check_tiles(
    model: &StreetModel,
    map: &OsmMap,
    cloud: &PointCloud,
    whole: &Estimates,
    grid: TileGrid,
) -> (usize, usize) {
    let plan = grid.plan(map);
    let segs = &map.streets.segments;
    let mut owned: Vec<usize> = plan.iter().flat_map(|t| t.owned.clone()).collect();
    owned.sort_unstable();
    let drivable: Vec<usize> = (0..segs.len())
        .filter(|&s| geodata::osm::tags::is_drivable(&segs[s].highway))
        .collect();
    assert_eq!(owned, drivable, "each drivable segment owned once");
    for t in &plan {
        let (lo, hi) = grid.core(t.key);
        for &s in &t.owned {
            let m = [
                0.5 * (segs[s].a[0] + segs[s].b[0]),
                0.5 * (segs[s].a[1] + segs[s].b[1]),
            ];
            assert!((lo[0]..hi[0]).contains(&m[0]) && (lo[1]..hi[1]).contains(&m[1]));
        }
    }
    let observed: Vec<usize> = whole.segments.iter().map(|e| e.segment).collect();
    let component = components_by_union_find(map, &observed, &model.geometry);
    let tile_of_segment = |s: usize| plan.iter().position(|t| t.owned.contains(&s)).unwrap();
    let mut crossing = BTreeSet::new();
    for &(s, c) in &component {
        for &(t, d) in &component {
            if c == d && tile_of_segment(s) != tile_of_segment(t) {
                crossing.insert(c);
            }
        }
    }
    let mut parts = Vec::new();
    for t in &plan {
        let part = model.estimate_tile(map, cloud, t, "map", "cloud").unwrap();
        let mine: BTreeSet<usize> = component
            .iter()
            .filter(|(s, _)| t.owned.contains(s))
            .map(|&(_, c)| c)
            .collect();
        let halo: Vec<usize> = component
            .iter()
            .filter(|(s, c)| mine.contains(c) && !t.owned.contains(s))
            .map(|&(s, _)| s)
            .collect();
        assert_eq!(part.halo, halo, "tile {:?}", t.key);
        parts.push(part);
    }
    let merged = merge_tiles(parts).unwrap();
    assert_eq!(&merged, whole, "{grid:?}");
    (plan.len(), crossing.len())
}

/// Tiles of the lattice equal the whole map at `max_turn_deg` for each `(tile_m, origin)`.
fn lattice_tiles_equal_the_whole_map(max_turn_deg: f64, grids: &[(f64, [f64; 2])]) {
    let (map, cloud, truth) = lattice();
    let mut model = lattice_model(&map, &cloud, &truth);
    model.geometry.max_turn_deg = max_turn_deg;
    let exact = max_turn_deg < 90.0;
    let whole = model.estimate(&map, &cloud, "map", "cloud").unwrap();
    assert_eq!(whole.exact, exact, "{max_turn_deg}°");
    assert!(
        whole.segments.len() >= 24 && whole.unobserved >= 1,
        "{whole:?}"
    );
    for &(tile_m, origin) in grids {
        let grid = TileGrid::new(tile_m, origin).unwrap();
        let (tiles, crossing) = check_tiles(&model, &map, &cloud, &whole, grid);
        eprintln!("{max_turn_deg}°, {tile_m} m tiles: {tiles} tiles, {crossing} components crossing borders");
        if tile_m < 500.0 {
            // 45°: each straight street is a chain across tiles; 180°: one component.
            assert!(tiles >= 4 && crossing >= if exact { 4 } else { 1 });
        } else {
            assert_eq!(tiles, 1);
        }
    }
}

/// 45°: straight streets couple through the crossings (chains, a forest). Tile borders on
/// the lattice lines (40 m from the origin), off them, and one tile for everything.
#[test]
fn lattice_tiles_equal_the_whole_map_with_tree_coupling() {
    lattice_tiles_equal_the_whole_map(
        45.0,
        &[
            (40.0, [0.0, 0.0]),
            (70.0, [-13.0, 7.0]),
            (1000.0, [-500.0, -500.0]),
        ],
    );
}

/// 180°: every pair of neighbours couples (triangles at each crossing, loopy max-product).
#[test]
fn lattice_tiles_equal_the_whole_map_with_loopy_coupling() {
    lattice_tiles_equal_the_whole_map(180.0, &[(90.0, [-20.0, -20.0])]);
}

/// Tiles on KITTI-360 drive 0009 equal the whole map at `max_turn_deg` (45°: a forest;
/// 180°: every pair of neighbours coupled, loops).
fn kitti360_tiles_equal_the_whole_map(max_turn_deg: f64, tile_m: f64, origin: [f64; 2]) {
    let real = kitti360_drive_0009_on_its_roads();
    let ds = &real.dataset;
    let options = ClassifierOptions {
        max_train_bins: 150,
        calibration_bins: 150,
        ..ClassifierOptions::default()
    };
    let mut model = StreetModel::train(ds, Target::DrivingArea, &options).unwrap();
    model.geometry.max_turn_deg = max_turn_deg;
    // A 24 m corridor (120 columns) keeps loopy max-product quick; the bins keep their features.
    model.geometry.corridor.width_m = 24.0;
    model.geometry.max_width_m = 12.0;
    let whole = model.estimate(&ds.map, &ds.cloud, "map", "cloud").unwrap();
    assert!(whole.segments.len() >= 20, "{}", whole.segments.len());
    assert_eq!(whole.exact, max_turn_deg < 90.0, "loops only at 180°");
    let grid = TileGrid::new(tile_m, origin).unwrap();
    let (tiles, crossing) = check_tiles(&model, &ds.map, &ds.cloud, &whole, grid);
    eprintln!(
        "{max_turn_deg}°, {tile_m} m tiles: {tiles} tiles, {crossing} components crossing borders"
    );
    assert!(
        tiles >= 10 && crossing >= 1,
        "{tiles} tiles, {crossing} crossing"
    );
}

#[test]
fn kitti360_tiles_equal_the_whole_map_with_tree_coupling() {
    kitti360_tiles_equal_the_whole_map(45.0, 150.0, [31.0, -57.0]);
}

#[test]
fn kitti360_tiles_equal_the_whole_map_with_loopy_coupling() {
    kitti360_tiles_equal_the_whole_map(180.0, 300.0, [0.0, 0.0]);
}

#[test]
fn plans_round_trip_and_bad_plans_are_errors() {
    let map = OsmMap::from_xml_str(&streets::synthetic::lattice_osm_xml()).unwrap();
    let plan = plan_tiles(&map, 60.0).unwrap();
    let text = serde_json::to_string(&plan).unwrap();
    assert_eq!(
        serde_json::from_str::<Vec<streets::tiles::StreetTile>>(&text).unwrap(),
        plan
    );
    for bad in [0.0, -5.0, f64::NAN, f64::INFINITY] {
        let err = plan_tiles(&map, bad).unwrap_err();
        assert!(
            matches!(err, StreetsError::InvalidOption { name: "tile_m", .. }),
            "{err}"
        );
    }
    let grid = TileGrid::new(60.0, [10.0, -20.0]).unwrap();
    assert_eq!(grid.tile_of([10.0, -20.0]), (0, 0));
    assert_eq!(grid.tile_of([9.999, 40.0]), (-1, 1));
    assert_eq!(grid.core((1, -1)), ([70.0, -80.0], [130.0, -20.0]));

    let (map, cloud, truth) = lattice();
    let model = lattice_model(&map, &cloud, &truth);
    let mut tile = plan[0].clone();
    tile.owned.push(map.streets.segments.len() + 3);
    let err = model
        .estimate_tile(&map, &cloud, &tile, "map", "cloud")
        .unwrap_err();
    assert!(matches!(err, StreetsError::TilePlan { .. }), "{err}");
    assert!(err.to_string().contains("made from this map"), "{err}");
    let footways = OsmMap::from_xml_str(
        &streets::synthetic::lattice_osm_xml()
            .replace("residential", "footway")
            .replace("tertiary", "footway"),
    )
    .unwrap();
    let err = model
        .estimate_tile(&footways, &cloud, &plan[0], "footways.osm", "cloud")
        .unwrap_err();
    assert!(matches!(err, StreetsError::NoStreets { .. }), "{err}");
    assert!(err.to_string().contains("footways.osm"), "{err}");
    let part = model
        .estimate_tile(&map, &cloud, &plan[0], "map", "cloud")
        .unwrap();
    let err = merge_tiles(vec![part.clone(), part]).unwrap_err();
    assert!(matches!(err, StreetsError::TileOverlap { .. }), "{err}");
}

/// Brute force: on random networks of trees and loops, max-product over the whole network
/// gives each component exactly (bit for bit) what the component alone gives, and on a
/// tree component the exact optimum found by enumeration.
#[test]
fn max_product_solves_each_component_as_if_alone() {
    use rand::{Rng, SeedableRng};
    let n = 4;
    let states: Vec<(usize, usize)> = (0..n).flat_map(|a| (a..n).map(move |b| (a, b))).collect();
    for seed in 0..30u64 {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let k = rng.gen_range(3..9);
        let potentials: Vec<SegmentPotential> = (0..k)
            .map(|_| {
                let mut log = vec![f64::NEG_INFINITY; n * n];
                for &(a, b) in &states {
                    log[a * n + b] = rng.gen_range(-4.0..0.0);
                }
                SegmentPotential { cols: n, log }
            })
            .collect();
        let mut edges = Vec::new();
        for s2 in 1..k {
            for s1 in 0..s2 {
                if rng.gen_range(0..k) == 0 {
                    edges.push(Edge {
                        s1,
                        s2,
                        flipped: rng.gen(),
                    });
                }
            }
        }
        let net = Network {
            potentials,
            edges,
            lambda: rng.gen_range(0.05..1.0),
            truncation: if rng.gen() { 2.0 } else { f64::INFINITY },
        };
        let whole = net.max_product(20);
        let mut all_exact = true;
        for nodes in net.components() {
            let sub = net.subnetwork(&nodes);
            let alone = sub.max_product(20);
            let mine: Vec<(usize, usize)> = nodes.iter().map(|&s| whole.states[s]).collect();
            assert_eq!(mine, alone.states, "seed {seed}, component {nodes:?}");
            all_exact &= alone.exact;
            if alone.exact && nodes.len() <= 4 {
                let mut best = f64::NEG_INFINITY;
                let mut idx = vec![0usize; nodes.len()];
                'all: loop {
                    let lab: Vec<(usize, usize)> = idx.iter().map(|&i| states[i]).collect();
                    best = best.max(sub.log_probability(&lab));
                    for p in 0..=idx.len() {
                        if p == idx.len() {
                            break 'all;
                        }
                        idx[p] += 1;
                        if idx[p] < states.len() {
                            break;
                        }
                        idx[p] = 0;
                    }
                }
                assert!((alone.log_probability - best).abs() < 1e-9, "seed {seed}");
            }
        }
        assert_eq!(whole.exact, all_exact);
        assert_eq!(whole.exact, net.is_forest());
    }
}
