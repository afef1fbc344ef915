//! GeoJSON (RFC 7946) output: one WGS84 polygon per estimated segment with its width and offset.

use crate::corridor::SegmentFrame;
use crate::model::SegmentEstimate;
use geodata::osm::OsmMap;
use serde_json::{json, Value};

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

/// A FeatureCollection of the estimates (coordinates `[lon, lat]`, properties `segment`,
/// `osm_way`, `highway`, `width`, `offset`, `bins`).
pub fn feature_collection(map: &OsmMap, estimates: &[SegmentEstimate]) -> Value {
    let features: Vec<Value> = estimates
        .iter()
        .filter_map(|e| {
            let seg = map.streets.segments.get(e.segment)?;
            let frame = SegmentFrame::of(seg)?;
            let ring: Vec<[f64; 2]> = strip_ring(&frame, e.offset_m, e.width_m)
                .iter()
                .map(|&p| {
                    let (lat, lon) = map.frame.to_wgs84(p);
                    [lon, lat]
                })
                .collect();
            let way = map.highways.get(seg.way_index);
            Some(json!({
                "type": "Feature",
                "geometry": {"type": "Polygon", "coordinates": [ring]},
                "properties": {
                    "segment": e.segment,
                    "osm_way": way.map(|w| w.osm_id),
                    "highway": seg.highway,
                    "width": e.width_m,
                    "offset": e.offset_m,
                    "bins": e.bins,
                },
            }))
        })
        .collect();
    json!({"type": "FeatureCollection", "features": features})
}

/// Checks a FeatureCollection against RFC 7946's rules for polygons: closed rings of ≥ 4
/// positions, longitudes in [−180, 180], latitudes in [−90, 90], exterior rings
/// counter-clockwise. Returns the first violation.
pub fn validate(v: &Value) -> Result<(), String> {
    if v["type"] != "FeatureCollection" {
        return Err("type is not FeatureCollection".into());
    }
    let features = v["features"].as_array().ok_or("features is not an array")?;
    for (i, f) in features.iter().enumerate() {
        if f["type"] != "Feature" || f["geometry"]["type"] != "Polygon" {
            return Err(format!("feature {i} is not a Polygon Feature"));
        }
        if !f["properties"].is_object() {
            return Err(format!("feature {i} has no properties object"));
        }
        let rings = f["geometry"]["coordinates"]
            .as_array()
            .ok_or(format!("feature {i}: coordinates not an array"))?;
        for (r, ring) in rings.iter().enumerate() {
            let pts: Vec<[f64; 2]> = ring
                .as_array()
                .ok_or(format!("feature {i} ring {r} not an array"))?
                .iter()
                .map(|p| {
                    [
                        p[0].as_f64().unwrap_or(f64::NAN),
                        p[1].as_f64().unwrap_or(f64::NAN),
                    ]
                })
                .collect();
            if pts.len() < 4 || pts.first() != pts.last() {
                return Err(format!(
                    "feature {i} ring {r}: not a closed ring of ≥ 4 positions"
                ));
            }
            if pts
                .iter()
                .any(|p| !(p[0].abs() <= 180.0 && p[1].abs() <= 90.0))
            {
                return Err(format!("feature {i} ring {r}: position out of range"));
            }
            let area: f64 = pts
                .windows(2)
                .map(|w| w[0][0] * w[1][1] - w[1][0] * w[0][1])
                .sum();
            if r == 0 && area <= 0.0 {
                return Err(format!(
                    "feature {i}: exterior ring is not counter-clockwise"
                ));
            }
        }
    }
    Ok(())
}
