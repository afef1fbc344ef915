//! OSM ingestion on the real extracts in `../shared/data/osm`: counts against an independent
//! reader (pyosmium, see `scripts/bench_osm_peers.py`), map invariants, spatial index
//! against brute force, and errors on truncated and garbled copies.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use geodata::osm::geometry::{
    point_in_polygon, point_segment_distance, polygon_intersects_box, segment_intersects_box,
    signed_area,
};
use geodata::osm::{MapIndex, OsmError, OsmMap};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::PathBuf;

fn data_path(name: &str) -> PathBuf {
    let path = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/osm"
    ))
    .join(name);
    assert!(path.exists(), "missing data file {}", path.display());
    path
}

fn load(name: &str) -> OsmMap {
    let path = data_path(name);
    OsmMap::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn kth() -> OsmMap {
    load("kth_campus_stockholm.osm")
}

fn monaco() -> OsmMap {
    load("monaco.osm.pbf")
}

fn helsinki() -> OsmMap {
    load("helsinki_centre.osm.pbf")
}

fn temp_file(name: &str, bytes: &[u8]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("urbansem-osm-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

/// Building and highway-way counts as pyosmium reports them (test vectors).
#[test]
fn counts_match_pyosmium() {
    for (map, buildings, highways) in [
        (kth(), 72, 323),
        (monaco(), 23_329, 2_927),
        (helsinki(), 500, 2_650),
    ] {
        assert_eq!(map.building_count(), buildings);
        assert_eq!(map.stats.highway_ways, highways);
    }
    let m = monaco();
    assert_eq!(
        (m.stats.nodes, m.stats.ways, m.stats.relations),
        (180_118, 27_377, 212)
    );
    assert_eq!(m.stats.building_ways, 23_326);
    assert_eq!(m.stats.open_building_ways, 44);
}

/// Building outlines and holes as libosmium's area assembler builds them (pyosmium 4.3,
/// `area` callback on areas with `building=*` other than `no`: outer and inner rings; see
/// `osmium_read` in `scripts/osm_roundtrip.py`). Before the osmium-style assembly Monaco
/// had two more outlines: two self-crossing building ways osmium (and now urbansem) skips.
#[test]
fn outlines_and_holes_match_pyosmium_areas() {
    for (map, outlines, holes) in [(kth(), 72, 1), (monaco(), 23_327, 2), (helsinki(), 446, 72)] {
        let map_holes: usize = map.buildings.iter().map(|b| b.inners.len()).sum();
        assert_eq!((map.buildings.len(), map_holes), (outlines, holes));
    }
    assert_eq!(monaco().stats.skipped_building_ways_crossing, 2);
}

#[test]
fn bounds_define_the_frame() {
    let m = kth();
    assert_eq!(m.bbox_lonlat, [18.06856, 59.34516, 18.07684, 59.35]);
    let (lat, lon) = m.frame.origin();
    assert!((lat - 59.34758).abs() < 1e-9 && (lon - 18.0727).abs() < 1e-9);
}

#[test]
fn skipped_elements_are_counted() {
    let h = helsinki();
    let s = &h.stats;
    // A way touching itself gives several outlines: count the ways.
    let ways_with_outlines = h
        .buildings
        .iter()
        .filter(|b| b.kind == geodata::osm::ElementKind::Way)
        .map(|b| b.osm_id)
        .collect::<std::collections::BTreeSet<_>>()
        .len();
    assert_eq!(
        ways_with_outlines
            + s.skipped_building_ways_missing_nodes
            + s.skipped_building_ways_degenerate
            + s.skipped_building_ways_crossing,
        s.building_ways
    );
    let relations_with_outlines = h
        .buildings
        .iter()
        .filter(|b| b.kind == geodata::osm::ElementKind::Relation)
        .map(|b| b.osm_id)
        .collect::<std::collections::BTreeSet<_>>()
        .len();
    assert_eq!(
        relations_with_outlines
            + s.skipped_building_relations_missing_members
            + s.skipped_building_relations_unclosed
            + s.skipped_building_relations_crossing
            + s.skipped_building_relations_degenerate,
        s.building_relations
    );
    assert!(
        s.skipped_building_ways_missing_nodes > 0,
        "the Helsinki extract is cut at its border"
    );
    assert_eq!(
        h.highways.len() + s.skipped_highway_ways_missing_nodes + s.skipped_highway_ways_too_short,
        s.highway_ways
    );
}

#[test]
fn rings_follow_the_convention() {
    for map in [kth(), monaco(), helsinki()] {
        for b in &map.buildings {
            assert!(b.outer.len() >= 3);
            assert!(
                signed_area(&b.outer) > 0.0,
                "outer ring of {} is not counter-clockwise",
                b.osm_id
            );
            assert_ne!(b.outer.first(), b.outer.last());
            for inner in &b.inners {
                assert!(
                    signed_area(inner) < 0.0,
                    "inner ring of {} is not clockwise",
                    b.osm_id
                );
            }
        }
    }
    let h = helsinki();
    assert!(
        h.buildings.iter().any(|b| !b.inners.is_empty()),
        "Helsinki has courtyard multipolygons"
    );
}

#[test]
fn network_matches_its_definition() {
    for map in [kth(), helsinki()] {
        let net = &map.streets;
        let expected: usize = map
            .highways
            .iter()
            .filter(|h| !h.area)
            .map(|h| h.node_ids.windows(2).filter(|w| w[0] != w[1]).count())
            .sum();
        assert_eq!(net.segments.len(), expected);
        for s in &net.segments {
            assert!((s.length_m - ((s.b[0] - s.a[0]).hypot(s.b[1] - s.a[1]))).abs() < 1e-9);
        }
        // Brute-force intersections: ≥ 3 segment ends or two different ways at one node.
        let mut ends: std::collections::BTreeMap<i64, (usize, std::collections::BTreeSet<usize>)> =
            Default::default();
        for s in &net.segments {
            for node in [s.from_node, s.to_node] {
                let e = ends.entry(node).or_default();
                e.0 += 1;
                e.1.insert(s.way_index);
            }
        }
        let brute: Vec<i64> = ends
            .iter()
            .filter(|(_, (k, ways))| *k >= 3 || ways.len() >= 2)
            .map(|(n, _)| *n)
            .collect();
        let ours: Vec<i64> = net.intersections.iter().map(|i| i.node_id).collect();
        assert_eq!(ours, brute);
        for &[s1, s2] in &net.neighbour_pairs {
            let (a, b) = (&net.segments[s1], &net.segments[s2]);
            assert!(s1 < s2);
            assert!([a.from_node, a.to_node]
                .iter()
                .any(|n| *n == b.from_node || *n == b.to_node));
        }
    }
}

#[test]
fn index_agrees_with_brute_force() {
    for (map, queries) in [(kth(), 400), (helsinki(), 400), (monaco(), 150)] {
        let index = MapIndex::new(&map);
        let (lo, hi) = map.buildings.iter().flat_map(|b| b.outer.iter()).fold(
            ([f64::MAX; 2], [f64::MIN; 2]),
            |(lo, hi), p| {
                (
                    [lo[0].min(p[0]), lo[1].min(p[1])],
                    [hi[0].max(p[0]), hi[1].max(p[1])],
                )
            },
        );
        let mut rng = ChaCha8Rng::seed_from_u64(42);
        let mut inside_hits = 0;
        for _ in 0..queries {
            let p = [rng.gen_range(lo[0]..hi[0]), rng.gen_range(lo[1]..hi[1])];
            let brute: Vec<usize> = (0..map.buildings.len())
                .filter(|&i| point_in_polygon(p, &map.buildings[i].outer, &map.buildings[i].inners))
                .collect();
            inside_hits += usize::from(!brute.is_empty());
            assert_eq!(index.buildings_containing(p), brute);
            let (seg, dist) = index.nearest_segment(p).unwrap();
            let brute_min = map
                .streets
                .segments
                .iter()
                .map(|s| point_segment_distance(p, s.a, s.b))
                .fold(f64::INFINITY, f64::min);
            assert!((dist - brute_min).abs() < 1e-6, "{dist} vs {brute_min}");
            let s = &map.streets.segments[seg];
            assert!((point_segment_distance(p, s.a, s.b) - brute_min).abs() < 1e-6);
            let half = rng.gen_range(1.0..80.0);
            let (bmin, bmax) = ([p[0] - half, p[1] - half], [p[0] + half, p[1] + half]);
            let brute_segments: Vec<usize> = (0..map.streets.segments.len())
                .filter(|&i| {
                    segment_intersects_box(
                        map.streets.segments[i].a,
                        map.streets.segments[i].b,
                        bmin,
                        bmax,
                    )
                })
                .collect();
            assert_eq!(index.segments_in_box(bmin, bmax), brute_segments);
            let brute_buildings: Vec<usize> = (0..map.buildings.len())
                .filter(|&i| {
                    polygon_intersects_box(
                        &map.buildings[i].outer,
                        &map.buildings[i].inners,
                        bmin,
                        bmax,
                    )
                })
                .collect();
            assert_eq!(index.buildings_in_box(bmin, bmax), brute_buildings);
        }
        assert!(inside_hits > 0, "no random point fell into a building");
    }
}

#[test]
fn shared_frame_places_two_files_consistently() {
    let own = kth();
    let shared_frame = geodata::projection::LocalFrame::new(59.3, 18.0).unwrap();
    let moved =
        OsmMap::load_in_frame(data_path("kth_campus_stockholm.osm"), Some(shared_frame)).unwrap();
    let (b0, b1) = (&own.buildings[0], &moved.buildings[0]);
    let (lat, lon) = own.frame.to_wgs84(b0.outer[0]);
    let expected = shared_frame.to_local(lat, lon);
    assert!(
        (expected[0] - b1.outer[0][0]).abs() < 1e-6 && (expected[1] - b1.outer[0][1]).abs() < 1e-6
    );
}

#[test]
fn truncated_pbf_names_file_and_blob() {
    let bytes = std::fs::read(data_path("monaco.osm.pbf")).unwrap();
    let path = temp_file("monaco_truncated.osm.pbf", &bytes[..bytes.len() / 2]);
    match OsmMap::load(&path) {
        Err(OsmError::Pbf {
            path: p,
            blob_index,
            byte_offset,
            ..
        }) => {
            assert_eq!(p, path);
            assert!(
                blob_index > 0 && byte_offset > 0,
                "blob {blob_index} at {byte_offset}"
            );
        }
        other => panic!("expected a PBF error, got {other:?}"),
    }
}

#[test]
fn garbled_pbf_is_an_error() {
    let mut bytes = std::fs::read(data_path("helsinki_centre.osm.pbf")).unwrap();
    let mid = bytes.len() / 2;
    for b in &mut bytes[mid..mid + 64] {
        *b ^= 0x5a;
    }
    let path = temp_file("helsinki_garbled.osm.pbf", &bytes);
    assert!(matches!(OsmMap::load(&path), Err(OsmError::Pbf { .. })));
}

#[test]
fn truncated_xml_names_file_and_offset() {
    let bytes = std::fs::read(data_path("kth_campus_stockholm.osm")).unwrap();
    let cut = bytes.len() * 3 / 5;
    let path = temp_file("kth_truncated.osm", &bytes[..cut]);
    match OsmMap::load(&path) {
        Err(e @ (OsmError::XmlTruncated { .. } | OsmError::Xml { .. })) => {
            let msg = e.to_string();
            assert!(msg.contains("kth_truncated.osm"), "{msg}");
        }
        other => panic!("expected an XML error, got {other:?}"),
    }
}

#[test]
fn garbled_xml_reports_the_byte_offset() {
    let mut bytes = std::fs::read(data_path("kth_campus_stockholm.osm")).unwrap();
    let text = String::from_utf8_lossy(&bytes).into_owned();
    let at = text.find("<way ").unwrap();
    bytes.splice(at..at, b"</bogus>".iter().copied());
    let path = temp_file("kth_garbled.osm", &bytes);
    match OsmMap::load(&path) {
        Err(OsmError::Xml {
            byte_offset,
            source_name,
            ..
        }) => {
            assert!(source_name.ends_with("kth_garbled.osm"));
            assert!(
                (byte_offset as usize).abs_diff(at) < 16,
                "offset {byte_offset} vs inserted at {at}"
            );
        }
        other => panic!("expected an XML error, got {other:?}"),
    }
}

#[test]
fn unknown_extension_and_missing_file() {
    assert!(matches!(
        OsmMap::load("/nonexistent/map.geojson"),
        Err(OsmError::UnknownExtension { .. })
    ));
    assert!(matches!(
        OsmMap::load("/nonexistent/map.osm"),
        Err(OsmError::Io { .. })
    ));
}
