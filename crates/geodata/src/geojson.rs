//! GeoJSON (RFC 7946) output shared by every capability: WGS84 `[lon, lat]` positions, the
//! OpenStreetMap attribution as a foreign member, a validator of the RFC's rules, and the
//! map itself (building outlines and highway centre lines).

use crate::osm::OsmMap;
use crate::projection::LocalFrame;
use serde_json::{json, Map, Value};

/// The attribution every output derived from OSM data carries (ODbL 1.0 requires it).
pub const OSM_ATTRIBUTION: &str =
    "© OpenStreetMap contributors, ODbL 1.0 (https://www.openstreetmap.org/copyright)";

/// A FeatureCollection of the features, with the OSM attribution.
pub fn feature_collection(features: Vec<Value>) -> Value {
    json!({"type": "FeatureCollection", "attribution": OSM_ATTRIBUTION, "features": features})
}

/// A Feature with the given geometry and properties.
pub fn feature(geometry: Value, properties: Map<String, Value>) -> Value {
    json!({"type": "Feature", "geometry": geometry, "properties": properties})
}

/// A local-frame point as a GeoJSON position `[lon, lat]`.
pub fn position(frame: &LocalFrame, p: [f64; 2]) -> [f64; 2] {
    let (lat, lon) = frame.to_wgs84(p);
    [lon, lat]
}

/// A closed local-frame ring (last vertex not repeated) as a GeoJSON linear ring, oriented
/// counter-clockwise when `exterior`, clockwise otherwise (RFC 7946 §3.1.6).
pub fn ring(frame: &LocalFrame, points: &[[f64; 2]], exterior: bool) -> Vec<[f64; 2]> {
    let mut r: Vec<[f64; 2]> = points.iter().map(|&p| position(frame, p)).collect();
    if r.first() == r.last() {
        r.pop();
    }
    if (signed_area(&r) > 0.0) != exterior {
        r.reverse();
    }
    if let Some(&first) = r.first() {
        r.push(first);
    }
    r
}

/// Twice the signed area of a ring (positive: counter-clockwise), closed or not.
fn signed_area(r: &[[f64; 2]]) -> f64 {
    let n = r.len();
    (0..n)
        .map(|i| {
            let (a, b) = (r[i], r[(i + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum()
}

/// The map's buildings (Polygons with their holes; properties `osm_id`, `osm_type`,
/// `building`, `height`, `levels`, `name`) and highway ways (LineStrings; `osm_id`,
/// `highway`, `name`, `width`, `lanes`, `oneway`).
pub fn osm_map(map: &OsmMap) -> Value {
    let mut features = Vec::with_capacity(map.buildings.len() + map.highways.len());
    for b in &map.buildings {
        if b.outer.len() < 3 {
            continue;
        }
        let mut rings = vec![ring(&map.frame, &b.outer, true)];
        rings.extend(
            b.inners
                .iter()
                .filter(|h| h.len() >= 3)
                .map(|h| ring(&map.frame, h, false)),
        );
        let mut p = Map::new();
        p.insert("osm_id".into(), json!(b.osm_id));
        p.insert(
            "osm_type".into(),
            json!(match b.kind {
                crate::osm::ElementKind::Way => "way",
                crate::osm::ElementKind::Relation => "relation",
            }),
        );
        p.insert("building".into(), json!(b.building));
        p.insert("height".into(), json!(b.height_m));
        p.insert("levels".into(), json!(b.levels));
        p.insert("name".into(), json!(b.name));
        features.push(feature(json!({"type": "Polygon", "coordinates": rings}), p));
    }
    for w in &map.highways {
        if w.points.len() < 2 {
            continue;
        }
        let line: Vec<[f64; 2]> = w.points.iter().map(|&q| position(&map.frame, q)).collect();
        let mut p = Map::new();
        p.insert("osm_id".into(), json!(w.osm_id));
        p.insert("highway".into(), json!(w.highway));
        p.insert("name".into(), json!(w.name));
        p.insert("width".into(), json!(w.width_m));
        p.insert("lanes".into(), json!(w.lanes));
        p.insert("oneway".into(), json!(w.oneway));
        features.push(feature(
            json!({"type": "LineString", "coordinates": line}),
            p,
        ));
    }
    feature_collection(features)
}

/// Checks a FeatureCollection against RFC 7946's rules: every feature a `Feature` with a
/// properties object (or null); positions of two or three finite numbers with longitude in
/// [−180, 180] and latitude in [−90, 90]; LineStrings of ≥ 2 positions; Polygon rings closed,
/// ≥ 4 positions, exterior counter-clockwise and holes clockwise. Returns the first violation.
pub fn validate(v: &Value) -> Result<(), String> {
    if v["type"] != "FeatureCollection" {
        return Err("type is not FeatureCollection".into());
    }
    let features = v["features"].as_array().ok_or("features is not an array")?;
    for (i, f) in features.iter().enumerate() {
        if f["type"] != "Feature" {
            return Err(format!("feature {i}: type is not Feature"));
        }
        if !(f["properties"].is_object() || f["properties"].is_null()) {
            return Err(format!(
                "feature {i}: properties is neither an object nor null"
            ));
        }
        validate_geometry(&f["geometry"]).map_err(|e| format!("feature {i}: {e}"))?;
    }
    Ok(())
}

fn validate_geometry(g: &Value) -> Result<(), String> {
    let coords = &g["coordinates"];
    match g["type"].as_str() {
        Some("Point") => position_of(coords).map(|_| ()),
        Some("MultiPoint") => positions(coords).map(|_| ()),
        Some("LineString") => line(coords),
        Some("MultiLineString") => array(coords)?.iter().try_for_each(line),
        Some("Polygon") => polygon(coords),
        Some("MultiPolygon") => array(coords)?.iter().try_for_each(polygon),
        Some("GeometryCollection") => array(&g["geometries"])?
            .iter()
            .try_for_each(validate_geometry),
        _ => Err(format!("unknown geometry type {}", g["type"])),
    }
}

fn array(v: &Value) -> Result<&Vec<Value>, String> {
    v.as_array()
        .ok_or_else(|| "coordinates are not an array".to_owned())
}

fn position_of(v: &Value) -> Result<[f64; 2], String> {
    let a = array(v)?;
    if !(2..=3).contains(&a.len()) {
        return Err(format!("position {v} does not have 2 or 3 numbers"));
    }
    let n: Vec<f64> = a.iter().filter_map(Value::as_f64).collect();
    if n.len() != a.len() || n.iter().any(|x| !x.is_finite()) {
        return Err(format!("position {v} holds a non-number"));
    }
    if n[0].abs() > 180.0 || n[1].abs() > 90.0 {
        return Err(format!("position {v} is out of range (lon, lat)"));
    }
    Ok([n[0], n[1]])
}

fn positions(v: &Value) -> Result<Vec<[f64; 2]>, String> {
    array(v)?.iter().map(position_of).collect()
}

fn line(v: &Value) -> Result<(), String> {
    if positions(v)?.len() < 2 {
        return Err("a LineString needs ≥ 2 positions".into());
    }
    Ok(())
}

fn polygon(v: &Value) -> Result<(), String> {
    for (r, ring) in array(v)?.iter().enumerate() {
        let pts = positions(ring)?;
        if pts.len() < 4 || pts.first() != pts.last() {
            return Err(format!("ring {r}: not a closed ring of ≥ 4 positions"));
        }
        let area = signed_area(&pts[..pts.len() - 1]);
        if r == 0 && area <= 0.0 {
            return Err("exterior ring is not counter-clockwise".into());
        }
        if r > 0 && area >= 0.0 {
            return Err(format!("hole {r} is not clockwise"));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    fn frame() -> LocalFrame {
        LocalFrame::new(48.0, 11.0).unwrap()
    }

    #[test]
    fn rings_are_closed_and_oriented_by_role() {
        let square = [[0.0, 0.0], [0.0, 10.0], [10.0, 10.0], [10.0, 0.0]]; // clockwise
        let outer = ring(&frame(), &square, true);
        let hole = ring(&frame(), &square, false);
        assert_eq!(outer.len(), 5);
        assert_eq!(outer.first(), outer.last());
        assert!(signed_area(&outer[..4]) > 0.0);
        assert!(signed_area(&hole[..4]) < 0.0);
        let fc = feature_collection(vec![feature(
            json!({"type": "Polygon", "coordinates": [outer, hole]}),
            Map::new(),
        )]);
        validate(&fc).unwrap();
        assert_eq!(fc["attribution"], OSM_ATTRIBUTION);
    }

    #[test]
    fn validator_rejects_what_the_rfc_forbids() {
        let bad = [
            json!({"type": "Feature", "geometry": {"type": "Point", "coordinates": [200.0, 0.0]}, "properties": {}}),
            json!({"type": "Feature", "geometry": {"type": "LineString", "coordinates": [[0.0, 0.0]]}, "properties": {}}),
            json!({"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [[[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [0.0, 0.0]]]}, "properties": {}}),
            json!({"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]]}, "properties": {}}),
            json!({"type": "Feature", "geometry": {"type": "Circle", "coordinates": [0.0, 0.0]}, "properties": {}}),
            json!({"type": "Feature", "geometry": {"type": "Point", "coordinates": [0.0, 0.0]}, "properties": 3}),
        ];
        for f in bad {
            assert!(
                validate(&feature_collection(vec![f.clone()])).is_err(),
                "{f}"
            );
        }
        let good = json!({"type": "Feature", "geometry": {"type": "Point", "coordinates": [11.5, 48.1]}, "properties": null});
        validate(&feature_collection(vec![good])).unwrap();
    }
}
