//! MCD `kth_day_06` building points, registered with their poses and georeferenced through
//! the MCD scaled-Mercator origin into the OSM map's local frame, fall on the KTH campus
//! building outlines of `osm/kth_campus_stockholm.osm` (median horizontal distance < 1 m).
//!
//! This checks the whole chain at once: KITTI-style scan reading, MCD labels and class
//! mapping, `pose_inW.csv` quaternions, the `hhs_calib.yaml` lidar extrinsic, the scaled
//! Mercator world frame, the transverse-Mercator local frame and the OSM reader.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use geodata::classes::Class;
use geodata::datasets::mcd::McdSequence;
use geodata::osm::OsmMap;
use std::path::PathBuf;

fn data_file(rel: &str) -> PathBuf {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data")).join(rel);
    assert!(p.exists(), "missing shared data: {}", p.display());
    p
}

/// Every `stride`-th building point of every MCD scan, in the map's frame (x, y).
fn mcd_building_points(map: &OsmMap, stride: usize) -> Vec<[f64; 2]> {
    let seq = McdSequence::open(data_file("lidar/mcd_kth_day_06")).unwrap();
    let frames = seq.frames().unwrap();
    assert_eq!(frames.len(), 30);
    let mut out = Vec::new();
    for f in frames {
        let scan = seq.load_scan(f).unwrap();
        let local = scan.cloud_in_local(&map.frame);
        let mut k = 0usize;
        for (i, p) in local.positions.iter().enumerate() {
            if local.class(i) == Class::Building {
                if k % stride == 0 {
                    out.push([p[0], p[1]]);
                }
                k += 1;
            }
        }
    }
    out
}

/// Every outline edge (outer and inner rings) of the map's buildings.
fn outline_edges(map: &OsmMap) -> Vec<([f64; 2], [f64; 2])> {
    let mut edges = Vec::new();
    for b in &map.buildings {
        for ring in std::iter::once(&b.outer).chain(b.inners.iter()) {
            for (i, &a) in ring.iter().enumerate() {
                edges.push((a, ring[(i + 1) % ring.len()]));
            }
        }
    }
    edges
}

fn point_segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    ((p[0] - a[0] - t * dx).powi(2) + (p[1] - a[1] - t * dy).powi(2)).sqrt()
}

/// Median distance from the points, shifted by `offset`, to the nearest outline edge.
fn median_distance(points: &[[f64; 2]], edges: &[([f64; 2], [f64; 2])], offset: [f64; 2]) -> f64 {
    let mut d: Vec<f64> = points
        .iter()
        .map(|p| {
            let q = [p[0] + offset[0], p[1] + offset[1]];
            edges
                .iter()
                .map(|&(a, b)| point_segment_distance(q, a, b))
                .fold(f64::INFINITY, f64::min)
        })
        .collect();
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

#[test]
fn mcd_building_points_fall_on_kth_osm_outlines() {
    let map = OsmMap::load(data_file("osm/kth_campus_stockholm.osm")).unwrap();
    let edges = outline_edges(&map);
    assert!(edges.len() > 100, "{} outline edges", edges.len());
    let points = mcd_building_points(&map, 8);
    assert!(points.len() > 50_000, "{} building points", points.len());
    let median = median_distance(&points, &edges, [0.0, 0.0]);
    println!("MCD/KTH: {} building points, median distance to the nearest OSM outline edge {median:.3} m", points.len());
    assert!(median < 1.0, "median distance {median:.3} m");
    // The test can fail: the same points moved 4 m in any direction are clearly off
    // (facades parallel to a shift stay close, so each direction only has to be worse).
    let mut worst = 0.0f64;
    for offset in [
        [4.0, 0.0],
        [0.0, 4.0],
        [-4.0, 0.0],
        [0.0, -4.0],
        [2.8, 2.8],
        [-2.8, -2.8],
    ] {
        let shifted = median_distance(&points, &edges, offset);
        println!("  shifted by {offset:?} m: median {shifted:.3} m");
        assert!(
            shifted > median + 0.3,
            "shift {offset:?}: median {shifted:.3} m vs {median:.3} m"
        );
        worst = worst.max(shifted);
    }
    assert!(worst > 2.0, "the worst 4 m shift gives only {worst:.3} m");
}
