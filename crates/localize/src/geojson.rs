//! Localization results as GeoJSON (RFC 7946, built on [`geodata::geojson`]): one scan's
//! candidates as Points, a track as a LineString of its best poses plus one Point per scan,
//! with the OpenStreetMap attribution.
//!
//! Headings are written in three conventions, all in degrees: `yaw_deg` counter-clockwise
//! from true east (the report's `yaw`), `heading_deg` clockwise from true north (a compass
//! bearing, what map viewers call rotation) and `yaw_grid_deg` counter-clockwise from the
//! map's local x axis (grid east). The collection's `yaw_convention` member says so.

use crate::report::{GeoCandidate, LocalizeReport, TrackReport};
use geodata::geojson::{feature, feature_collection};
use serde_json::{json, Map, Value};

/// The collection member that states the heading conventions.
pub const YAW_CONVENTION: &str = "yaw_deg: counter-clockwise from true east; heading_deg: clockwise from true north (compass bearing); yaw_grid_deg: counter-clockwise from the local frame's x axis (grid east); positions [lon, lat] WGS84; x, y: metres east, north in the map's local frame";

/// A heading counter-clockwise from true east (radians) as a compass bearing in [0, 360)
/// degrees (clockwise from true north).
pub fn compass_deg(yaw_east_ccw_rad: f64) -> f64 {
    let b = (90.0 - yaw_east_ccw_rad.to_degrees()).rem_euclid(360.0);
    if b >= 360.0 {
        0.0
    } else {
        b
    }
}

/// The value of the cost named `cost` (`dcm`, `forward`, `reverse`, `symmetric`).
fn cost_of(c: &GeoCandidate, cost: &str) -> f64 {
    match cost {
        "dcm" => c.dcm,
        "forward" => c.forward,
        "symmetric" => c.symmetric,
        _ => c.reverse,
    }
}

/// The properties of one candidate: `rank`, `x`, `y`, the three headings, `cost` (the
/// ranking cost's value) and `cost_kind` (its name), `dcm`, `forward`, `reverse`,
/// `symmetric`, `refined`, `confidence`.
fn candidate_properties(c: &GeoCandidate, cost: &str) -> Map<String, Value> {
    let mut p = Map::new();
    p.insert("rank".into(), json!(c.rank));
    p.insert("x".into(), json!(c.x));
    p.insert("y".into(), json!(c.y));
    p.insert("yaw_deg".into(), json!(c.yaw.to_degrees()));
    p.insert("heading_deg".into(), json!(compass_deg(c.yaw)));
    p.insert("yaw_grid_deg".into(), json!(c.yaw_grid.to_degrees()));
    p.insert("cost".into(), json!(cost_of(c, cost)));
    p.insert("cost_kind".into(), json!(cost));
    p.insert("dcm".into(), json!(c.dcm));
    p.insert("forward".into(), json!(c.forward));
    p.insert("reverse".into(), json!(c.reverse));
    p.insert("symmetric".into(), json!(c.symmetric));
    p.insert("refined".into(), json!(c.refined));
    p.insert("confidence".into(), json!(c.confidence));
    p
}

/// A Point Feature of a candidate at `[lon, lat]`.
fn candidate_point(c: &GeoCandidate, cost: &str, extra: Map<String, Value>) -> Value {
    let mut p = candidate_properties(c, cost);
    p.extend(extra);
    feature(json!({"type": "Point", "coordinates": [c.lon, c.lat]}), p)
}

/// Adds the collection-level members (heading conventions and sources).
fn with_members(mut fc: Value, members: &[(&str, Value)]) -> Value {
    if let Some(o) = fc.as_object_mut() {
        o.insert("yaw_convention".into(), json!(YAW_CONVENTION));
        for (k, v) in members {
            o.insert((*k).into(), v.clone());
        }
    }
    fc
}

/// Candidates as Point Features in their order, ranked by the cost named `cost` (`dcm`,
/// `forward`, `reverse`, `symmetric`), with the OSM attribution and the member `cost`.
pub fn candidates_features(candidates: &[GeoCandidate], cost: &str) -> Value {
    let features = candidates
        .iter()
        .map(|c| candidate_point(c, cost, Map::new()))
        .collect();
    with_members(feature_collection(features), &[("cost", json!(cost))])
}

/// One scan's listed candidates as Point Features (best first), with the OSM attribution
/// and the members `map`, `scan`, `cost`.
pub fn candidates_collection(report: &LocalizeReport) -> Value {
    with_members(
        candidates_features(&report.candidates, report.cost),
        &[("map", json!(report.map)), ("scan", json!(report.scan))],
    )
}

/// A track: a LineString through the best poses of the localized scans in order (when at
/// least two are), then one Point per localized scan (its best listed candidate; properties
/// of the candidate plus `index` (0-based scan index) and `scan` (file name)), with the OSM
/// attribution and the members `map`, `scans_dir`, `cost`.
pub fn track_collection(report: &TrackReport) -> Value {
    let mut features = Vec::new();
    let best: Vec<(usize, &str, &GeoCandidate)> = report
        .scans
        .iter()
        .enumerate()
        .filter_map(|(i, r)| r.candidates.first().map(|c| (i, r.scan.as_str(), c)))
        .collect();
    if best.len() >= 2 {
        let line: Vec<[f64; 2]> = best.iter().map(|(_, _, c)| [c.lon, c.lat]).collect();
        let mut p = Map::new();
        p.insert("kind".into(), json!("track"));
        p.insert("scans".into(), json!(best.len()));
        features.push(feature(
            json!({"type": "LineString", "coordinates": line}),
            p,
        ));
    }
    for (i, scan, c) in &best {
        let mut p = Map::new();
        p.insert("kind".into(), json!("scan"));
        p.insert("index".into(), json!(i));
        p.insert("scan".into(), json!(scan));
        features.push(candidate_point(c, report.cost, p));
    }
    with_members(
        feature_collection(features),
        &[
            ("map", json!(report.map)),
            ("scans_dir", json!(report.scans_dir)),
            ("cost", json!(report.cost)),
        ],
    )
}

#[cfg(test)]
pub(crate) mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;
    use crate::pipeline::Candidate;
    use crate::rank::Costs;
    use crate::report::{TrackRow, TrackSeconds};
    use crate::Pose2;
    use geodata::osm::OsmMap;

    pub(crate) fn map() -> OsmMap {
        OsmMap::from_xml_str(
            r#"<?xml version="1.0"?><osm version="0.6">
<node id="1" lat="59.3500" lon="18.0700"/><node id="2" lat="59.3510" lon="18.0700"/>
<node id="3" lat="59.3510" lon="18.0720"/>
<way id="10"><nd ref="1"/><nd ref="2"/><nd ref="3"/><nd ref="1"/><tag k="building" v="yes"/></way></osm>"#,
        )
        .unwrap()
    }

    fn candidate(map: &OsmMap, rank: usize, x: f64, y: f64, yaw_rad: f64) -> GeoCandidate {
        let c = Candidate {
            pose: Pose2 { x, y, yaw_rad },
            costs: Costs {
                dcm: 1.0 + rank as f64,
                forward: 2.0,
                reverse: 0.5 + rank as f64,
                symmetric: 3.0,
            },
            refined: true,
            confidence: 0.25,
        };
        GeoCandidate::new(map, rank, &c)
    }

    #[test]
    fn candidates_are_valid_points_that_convert_back() {
        let map = map();
        let cands = [
            candidate(&map, 0, 120.0, -35.5, 0.3),
            candidate(&map, 1, -800.0, 1500.0, 4.0),
        ];
        let fc = candidates_features(&cands, "reverse");
        geodata::geojson::validate(&fc).unwrap();
        assert_eq!(fc["attribution"], geodata::geojson::OSM_ATTRIBUTION);
        assert_eq!(fc["yaw_convention"], YAW_CONVENTION);
        let text = serde_json::to_string(&fc).unwrap();
        let back: Value = serde_json::from_str(&text).unwrap();
        for (f, c) in back["features"].as_array().unwrap().iter().zip(&cands) {
            let pos = &f["geometry"]["coordinates"];
            let xy = map
                .frame
                .to_local(pos[1].as_f64().unwrap(), pos[0].as_f64().unwrap());
            assert!(
                (xy[0] - c.x).abs() < 0.01 && (xy[1] - c.y).abs() < 0.01,
                "{xy:?}"
            );
            let p = &f["properties"];
            assert_eq!(p["rank"], c.rank);
            assert_eq!(p["cost"].as_f64().unwrap(), c.reverse);
            assert_eq!(p["cost_kind"], "reverse");
            let yaw = p["yaw_deg"].as_f64().unwrap();
            let heading = p["heading_deg"].as_f64().unwrap();
            let sum = (yaw + heading - 90.0).rem_euclid(360.0);
            assert!(!(1e-9..=360.0 - 1e-9).contains(&sum), "{yaw} + {heading}");
            assert!((p["yaw_grid_deg"].as_f64().unwrap().to_radians() - c.yaw_grid).abs() < 1e-12);
        }
    }

    #[test]
    fn compass_bearings() {
        assert!((compass_deg(0.0) - 90.0).abs() < 1e-12); // east
        assert!(compass_deg(std::f64::consts::FRAC_PI_2).abs() < 1e-12); // north
        assert!((compass_deg(std::f64::consts::PI) - 270.0).abs() < 1e-12); // west
        assert!((compass_deg(-std::f64::consts::FRAC_PI_2) - 180.0).abs() < 1e-12);
        // south
    }

    pub(crate) fn track_report(map: &OsmMap) -> TrackReport {
        let row = |i: usize, c: Option<GeoCandidate>| TrackRow {
            scan: format!("{i:03}.ply"),
            lat: c.map(|c| c.lat),
            lon: c.map(|c| c.lon),
            yaw: c.map(|c| c.yaw),
            x: c.map(|c| c.x),
            y: c.map(|c| c.y),
            confidence: 0.5,
            candidates: c.into_iter().collect(),
            segments: 10,
            sensor: None,
            message: None,
            odometry_run: None,
        };
        TrackReport {
            map: "m.osm".into(),
            scans_dir: "scans".into(),
            odometry: "odo.txt".into(),
            window: 3,
            history_m: crate::track::TRACK_HISTORY_M,
            smoothed: true,
            pose_graph: true,
            cost: "reverse",
            scans: vec![
                row(0, Some(candidate(map, 0, 0.0, 0.0, 0.1))),
                row(1, None),
                row(2, Some(candidate(map, 0, 10.0, 2.0, 0.2))),
                row(3, Some(candidate(map, 0, 20.0, 5.0, -0.3))),
            ],
            seconds: TrackSeconds {
                total: 1.0,
                per_scan: 0.25,
            },
        }
    }

    #[test]
    fn track_is_a_line_and_points() {
        let map = map();
        let report = track_report(&map);
        let fc = track_collection(&report);
        geodata::geojson::validate(&fc).unwrap();
        assert_eq!(fc["attribution"], geodata::geojson::OSM_ATTRIBUTION);
        let f = fc["features"].as_array().unwrap();
        assert_eq!(f.len(), 4);
        assert_eq!(f[0]["geometry"]["type"], "LineString");
        assert_eq!(f[0]["geometry"]["coordinates"].as_array().unwrap().len(), 3);
        let indices: Vec<u64> = f[1..]
            .iter()
            .map(|f| f["properties"]["index"].as_u64().unwrap())
            .collect();
        assert_eq!(indices, [0, 2, 3]);
        let pos = &f[3]["geometry"]["coordinates"];
        let xy = map
            .frame
            .to_local(pos[1].as_f64().unwrap(), pos[0].as_f64().unwrap());
        assert!((xy[0] - 20.0).abs() < 0.01 && (xy[1] - 5.0).abs() < 0.01);
    }
}
