//! GeoJSON (RFC 7946) output: one WGS84 polygon per estimated segment with its width and
//! offset, the driving area, the driving area with sidewalk and the sidewalks between them,
//! with the OpenStreetMap attribution (built on [`geodata::geojson`]).

use crate::corridor::SegmentFrame;
use crate::model::{SegmentEstimate, Target};
use geodata::osm::OsmMap;
use serde_json::{json, Map, Value};

/// Narrowest sidewalk strip written by [`areas_collection`], metres.
pub const MIN_SIDEWALK_M: f64 = 0.05;

/// The street strip of a segment as a closed counter-clockwise ring in the local frame.
pub fn strip_ring(frame: &SegmentFrame, offset_m: f64, width_m: f64) -> [[f64; 2]; 5] {
    let (lo, hi) = (offset_m - 0.5 * width_m, offset_m + 0.5 * width_m);
    let l = frame.length_m;
    // Right edge forward, left edge back: counter-clockwise (left is +u).
    let p = [
        frame.world(0.0, lo),
        frame.world(l, lo),
        frame.world(l, hi),
        frame.world(0.0, hi),
    ];
    [p[0], p[1], p[2], p[3], p[0]]
}

/// What a polygon of the output covers (`area` property).
fn area_name(target: Target) -> &'static str {
    match target {
        Target::DrivingArea => "driving area",
        Target::WithSidewalk => "driving area and sidewalk",
    }
}

/// One strip polygon of segment `segment` with the segment's OSM properties plus `extra`.
fn strip_feature(
    map: &OsmMap,
    segment: usize,
    offset_m: f64,
    width_m: f64,
    extra: Map<String, Value>,
) -> Option<Value> {
    let seg = map.streets.segments.get(segment)?;
    let frame = SegmentFrame::of(seg)?;
    let ring = strip_ring(&frame, offset_m, width_m);
    let ring = geodata::geojson::ring(&map.frame, &ring[..4], true);
    let way = map.highways.get(seg.way_index);
    let mut p = Map::new();
    p.insert("segment".into(), json!(segment));
    p.insert("osm_way".into(), json!(way.map(|w| w.osm_id)));
    p.insert("highway".into(), json!(seg.highway));
    p.insert("width".into(), json!(width_m));
    p.insert("offset".into(), json!(offset_m));
    p.extend(extra);
    Some(geodata::geojson::feature(
        json!({"type": "Polygon", "coordinates": [ring]}),
        p,
    ))
}

/// The properties that say what an estimate's polygon is.
fn estimate_properties(e: &SegmentEstimate, target: Target) -> Map<String, Value> {
    let mut p = Map::new();
    p.insert("bins".into(), json!(e.bins));
    if let Some(sd) = e.width_sd_m {
        p.insert("width_sd".into(), json!(sd));
    }
    p.insert("target".into(), json!(target.key()));
    p.insert("area".into(), json!(area_name(target)));
    p
}

/// A FeatureCollection of the estimates of one target (coordinates `[lon, lat]`, properties
/// `segment`, `osm_way`, `highway`, `width`, `offset`, `bins`, `width_sd` (the width's
/// posterior spread, metres, when known), `target` (`driving_area` or `with_sidewalk`) and
/// `area` (in words)), with the OSM attribution.
pub fn feature_collection(map: &OsmMap, estimates: &[SegmentEstimate], target: Target) -> Value {
    let features = estimates
        .iter()
        .filter_map(|e| {
            strip_feature(
                map,
                e.segment,
                e.offset_m,
                e.width_m,
                estimate_properties(e, target),
            )
        })
        .collect();
    geodata::geojson::feature_collection(features)
}

/// A FeatureCollection of both targets' estimates: the driving-area polygons, the
/// driving-area-and-sidewalk polygons and, per segment estimated for both, the sidewalk
/// strips between them (`area` = `sidewalk`, `side` = `left` or `right` of the segment's
/// direction; strips narrower than [`MIN_SIDEWALK_M`] omitted), with the OSM attribution.
pub fn areas_collection(
    map: &OsmMap,
    driving: &[SegmentEstimate],
    with_sidewalk: &[SegmentEstimate],
) -> Value {
    let mut features = Vec::new();
    for (estimates, target) in [
        (driving, Target::DrivingArea),
        (with_sidewalk, Target::WithSidewalk),
    ] {
        features.extend(estimates.iter().filter_map(|e| {
            strip_feature(
                map,
                e.segment,
                e.offset_m,
                e.width_m,
                estimate_properties(e, target),
            )
        }));
    }
    for d in driving {
        let Some(w) = with_sidewalk.iter().find(|w| w.segment == d.segment) else {
            continue;
        };
        let (d_lo, d_hi) = (d.offset_m - 0.5 * d.width_m, d.offset_m + 0.5 * d.width_m);
        let (w_lo, w_hi) = (w.offset_m - 0.5 * w.width_m, w.offset_m + 0.5 * w.width_m);
        for (side, lo, hi) in [("right", w_lo, d_lo), ("left", d_hi, w_hi)] {
            if hi - lo < MIN_SIDEWALK_M {
                continue;
            }
            let mut p = Map::new();
            p.insert("area".into(), json!("sidewalk"));
            p.insert("side".into(), json!(side));
            features.extend(strip_feature(map, d.segment, 0.5 * (lo + hi), hi - lo, p));
        }
    }
    geodata::geojson::feature_collection(features)
}

/// Checks a FeatureCollection against RFC 7946's rules ([`geodata::geojson::validate`]).
/// Returns the first violation.
pub fn validate(v: &Value) -> Result<(), String> {
    geodata::geojson::validate(v)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    fn map() -> OsmMap {
        let xml = r#"<?xml version="1.0"?><osm version="0.6">
<node id="1" lat="48.0000" lon="11.0000"/><node id="2" lat="48.0010" lon="11.0000"/>
<way id="10"><nd ref="1"/><nd ref="2"/><tag k="highway" v="residential"/></way></osm>"#;
        OsmMap::from_xml_str(xml).unwrap()
    }

    #[test]
    fn areas_are_valid_polygons_with_sidewalks_and_attribution() {
        let map = map();
        assert!(!map.streets.segments.is_empty());
        let e = |offset_m, width_m| SegmentEstimate {
            segment: 0,
            offset_m,
            width_m,
            bins: 7,
            width_sd_m: Some(0.4),
        };
        let fc = areas_collection(&map, &[e(0.5, 6.0)], &[e(0.0, 10.0)]);
        validate(&fc).unwrap();
        assert_eq!(fc["attribution"], geodata::geojson::OSM_ATTRIBUTION);
        let f = fc["features"].as_array().unwrap();
        let areas: Vec<&str> = f
            .iter()
            .map(|f| f["properties"]["area"].as_str().unwrap())
            .collect();
        assert_eq!(
            areas,
            [
                "driving area",
                "driving area and sidewalk",
                "sidewalk",
                "sidewalk"
            ]
        );
        // Right: [−5, −2.5], left: [3.5, 5].
        assert!((f[2]["properties"]["width"].as_f64().unwrap() - 2.5).abs() < 1e-9);
        assert_eq!(f[2]["properties"]["side"], "right");
        assert!((f[3]["properties"]["width"].as_f64().unwrap() - 1.5).abs() < 1e-9);
        let one = feature_collection(&map, &[e(0.0, 10.0)], Target::WithSidewalk);
        validate(&one).unwrap();
        assert_eq!(one["features"][0]["properties"]["target"], "with_sidewalk");
        assert_eq!(one["features"][0]["properties"]["width_sd"], 0.4);
        assert_eq!(one["attribution"], geodata::geojson::OSM_ATTRIBUTION);
    }
}
