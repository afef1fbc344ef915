//! The true street geometry of the simulated world, per OSM street segment.
//!
//! Convention (shared with `streets` and the `streets` dataset's `segments.json`): for a
//! segment from `a` to `b` with unit direction e and left normal n = (−e_y, e_x), a point p
//! has along-coordinate t = (p − a)·e and lateral coordinate u = (p − a)·n (left positive).
//! The **driving area** of the segment is the strip 0 ≤ t ≤ L, |u − dₛ| ≤ wₛ/2, where dₛ
//! is the *offset* of the true street centre from the OSM centre line and wₛ the *width*.
//! The world's paved driving area is the union over segments of the capsules of radius
//! wₛ/2 about the offset centre lines (the strips plus round caps that close the joints),
//! and the sidewalk the capsules of radius wₛ/2 + sidewalk width outside it.
//!
//! Widths come from the `width` tag when present (then constant along the way), else from
//! `lanes`, else from the highway type, seeded per way; both width and offset follow a
//! seeded AR(1) walk along the way, so neighbouring segments of one way vary smoothly.
//! Drivable ways have a seeded sidewalk width by type unless tagged `sidewalk=no|none`.
//!
//! **Sidewalks mapped as ways of their own.** Many cities draw a street's sidewalks as
//! separate footways (`footway=sidewalk`, and the road tagged `sidewalk=separate`) rather than
//! as a tag of the road. Such a footway *is* the street's sidewalk: for a drivable way with
//! mapped sidewalks ([`geodata::osm::sidewalks`]: their distance d from the centre line), the
//! sidewalk reaches from the kerb to the footways' mean outer edge, d − wₛ/2 + 1.125 m (half
//! a simulated footway's mean width; clamped to 1–7 m), so the world has one sidewalk there,
//! labelled sidewalk, not a sidewalk and a second paved strip beside it. A road tagged
//! `sidewalk=separate` without mapped sidewalks has none of its own (its footway, where the
//! map draws it, is paved as other ground; see [`super::scene`]).

use super::{normal, purpose, stream_rng, SimError};
use geodata::osm::model::StreetSegment;
use geodata::osm::tags::is_drivable;
use geodata::osm::OsmMap;
use rand::Rng;
use serde::Serialize;

/// The true geometry of one street segment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StreetTruth {
    /// Offset dₛ of the street centre from the OSM centre line, metres, left of a→b positive.
    pub offset_m: f64,
    /// Width wₛ of the driving area (or of the path, for footways), metres.
    pub width_m: f64,
    /// Width of the sidewalk on each side beyond the driving area, metres (0: none).
    pub sidewalk_m: f64,
    /// Cars drive here (`false` for footways, paths, cycleways, steps, pedestrian streets).
    pub drivable: bool,
    /// The segment is on the ground (`false` for tunnels and layers below 0).
    pub on_ground: bool,
    /// The width came from the way's `width` tag.
    pub width_tagged: bool,
}

/// Options of the street truth model.
#[derive(Debug, Clone, PartialEq)]
pub struct TruthOptions {
    /// Standard deviation of the first segment's offset of a way, metres.
    pub offset_sigma_m: f64,
    /// Step standard deviation of the offset walk along a way, metres.
    pub offset_step_m: f64,
    /// Step standard deviation of the log-width walk along a way.
    pub log_width_step: f64,
    /// AR(1) coefficient pulling the walks back to the way's base values.
    pub ar_coefficient: f64,
}

impl Default for TruthOptions {
    fn default() -> Self {
        TruthOptions {
            offset_sigma_m: 0.6,
            offset_step_m: 0.2,
            log_width_step: 0.04,
            ar_coefficient: 0.85,
        }
    }
}

/// (min, max) width in metres of an untagged way of this type, and its sidewalk range.
fn type_ranges(highway: &str) -> ([f64; 2], [f64; 2]) {
    match highway.trim_end_matches("_link") {
        "motorway" | "trunk" => ([14.0, 20.0], [0.0, 0.0]),
        "primary" => ([11.0, 16.0], [2.5, 4.5]),
        "secondary" => ([9.0, 13.0], [2.0, 4.0]),
        "tertiary" => ([7.5, 10.5], [2.0, 3.5]),
        "residential" | "unclassified" | "road" | "busway" => ([5.5, 8.5], [1.5, 3.0]),
        "living_street" => ([4.0, 6.0], [0.0, 1.5]),
        "service" => ([3.0, 4.5], [0.0, 1.0]),
        "pedestrian" => ([5.0, 10.0], [0.0, 0.0]),
        "steps" => ([1.5, 3.0], [0.0, 0.0]),
        _ => ([1.5, 3.0], [0.0, 0.0]),
    }
}

/// The true geometry of every segment of `map.streets.segments`, in order.
pub fn street_truth(
    map: &OsmMap,
    options: &TruthOptions,
    seed: u64,
) -> Result<Vec<StreetTruth>, SimError> {
    for (name, value) in [
        ("offset_sigma_m", options.offset_sigma_m),
        ("offset_step_m", options.offset_step_m),
        ("log_width_step", options.log_width_step),
    ] {
        if !(value.is_finite() && value >= 0.0) {
            return Err(SimError::InvalidOption {
                name,
                value,
                expected: "a finite value ≥ 0",
            });
        }
    }
    if !(0.0..1.0).contains(&options.ar_coefficient) {
        return Err(SimError::InvalidOption {
            name: "ar_coefficient",
            value: options.ar_coefficient,
            expected: "a value in [0, 1)",
        });
    }
    let segments = &map.streets.segments;
    let mut truth = Vec::with_capacity(segments.len());
    let mut i = 0;
    while i < segments.len() {
        // One way's segments are contiguous and in way order.
        let way_index = segments[i].way_index;
        let mut j = i;
        while j < segments.len() && segments[j].way_index == way_index {
            j += 1;
        }
        let Some(way) = map.highways.get(way_index) else {
            i = j;
            continue;
        };
        let mut way_rng = stream_rng(seed, purpose::STREET_WAY, way.osm_id as u64);
        let drivable = is_drivable(&way.highway);
        let (width_range, sidewalk_range) = type_ranges(&way.highway);
        let tagged = way.width_m.filter(|w| w.is_finite() && *w > 0.5);
        let base_width = match (tagged, way.lanes) {
            (Some(w), _) => w.clamp(1.0, 40.0),
            (None, Some(lanes)) if drivable && lanes > 0 => {
                f64::from(lanes.min(8)) * way_rng.gen_range(3.0..3.4)
            }
            _ => way_rng.gen_range(width_range[0]..=width_range[1]),
        };
        // `separate`: the sidewalk is mapped as its own footway; [`mapped_sidewalks`] finds
        // it, and without one the road has no sidewalk beside it.
        let sidewalk_tag_none = matches!(way.sidewalk.as_deref(), Some("no" | "none" | "separate"));
        let sidewalk_m = if sidewalk_tag_none || sidewalk_range[1] <= 0.0 {
            0.0
        } else {
            way_rng.gen_range(sidewalk_range[0]..=sidewalk_range[1])
        };
        let on_ground = !way.tunnel && way.layer >= 0;
        let mut seg_rng = stream_rng(seed, purpose::STREET_SEGMENT, way.osm_id as u64);
        let mut log_w = 0.0_f64;
        let mut offset = if drivable {
            options.offset_sigma_m * normal(&mut seg_rng)
        } else {
            0.0
        };
        for k in i..j {
            if k > i && drivable {
                offset =
                    options.ar_coefficient * offset + options.offset_step_m * normal(&mut seg_rng);
                if tagged.is_none() {
                    log_w = options.ar_coefficient * log_w
                        + options.log_width_step * normal(&mut seg_rng);
                }
            }
            let width_m = base_width * log_w.exp();
            let offset_m = offset.clamp(-0.25 * width_m, 0.25 * width_m);
            truth.push(StreetTruth {
                offset_m,
                width_m,
                sidewalk_m,
                drivable,
                on_ground,
                width_tagged: tagged.is_some(),
            });
        }
        i = j;
    }
    mapped_sidewalks(map, &mut truth);
    Ok(truth)
}

/// Range of a sidewalk that reaches to mapped footways, metres.
const MAPPED_SIDEWALK_RANGE_M: [f64; 2] = [1.0, 7.0];

/// Widens every drivable way's sidewalk to the footways mapped beside it (module docs).
fn mapped_sidewalks(map: &OsmMap, truth: &mut [StreetTruth]) {
    // Half the mean width of a simulated footway.
    let [lo, hi] = type_ranges("footway").0;
    let footway_half_m = 0.25 * (lo + hi);
    for (seg, t) in map.streets.segments.iter().zip(truth.iter_mut()) {
        let mapped = map
            .highways
            .get(seg.way_index)
            .and_then(|w| w.mapped_sidewalk_m);
        if let (true, Some(d)) = (t.drivable, mapped) {
            t.sidewalk_m = (d - 0.5 * t.width_m + footway_half_m)
                .clamp(MAPPED_SIDEWALK_RANGE_M[0], MAPPED_SIDEWALK_RANGE_M[1]);
        }
    }
}

/// The segment's true centre line: its end points moved by the offset along the left normal.
pub fn offset_centre_line(segment: &StreetSegment, truth: &StreetTruth) -> [[f64; 2]; 2] {
    let d = [segment.b[0] - segment.a[0], segment.b[1] - segment.a[1]];
    let len = (d[0] * d[0] + d[1] * d[1]).sqrt().max(1e-12);
    let n = [-d[1] / len, d[0] / len];
    let o = truth.offset_m;
    [
        [segment.a[0] + o * n[0], segment.a[1] + o * n[1]],
        [segment.b[0] + o * n[0], segment.b[1] + o * n[1]],
    ]
}

/// Whether a point lies in the segment's driving-area strip (0 ≤ t ≤ L, |u − d| ≤ w/2).
pub fn in_strip(segment: &StreetSegment, truth: &StreetTruth, p: [f64; 2]) -> bool {
    let (t, u) = segment.coordinates(p);
    (0.0..=segment.length_m).contains(&t) && (u - truth.offset_m).abs() <= 0.5 * truth.width_m
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small_map() -> OsmMap {
        crate::scene::tests::small_map(3)
    }

    #[test]
    fn one_truth_per_segment_deterministic_and_plausible() {
        let map = small_map();
        let a = street_truth(&map, &TruthOptions::default(), 9).unwrap();
        let b = street_truth(&map, &TruthOptions::default(), 9).unwrap();
        let c = street_truth(&map, &TruthOptions::default(), 10).unwrap();
        assert_eq!(a.len(), map.streets.segments.len());
        assert_eq!(a, b);
        assert_ne!(a, c);
        for t in &a {
            assert!(t.width_m > 1.0 && t.width_m < 41.0, "{t:?}");
            assert!(t.offset_m.abs() <= 0.25 * t.width_m + 1e-12);
        }
        assert!(a.iter().any(|t| t.drivable));
    }

    #[test]
    fn neighbouring_segments_of_a_way_vary_smoothly() {
        let map = small_map();
        let truth = street_truth(&map, &TruthOptions::default(), 4).unwrap();
        let segs = &map.streets.segments;
        let mut pairs = 0;
        for k in 1..segs.len() {
            if segs[k].way_index == segs[k - 1].way_index && truth[k].drivable {
                pairs += 1;
                let dw = (truth[k].width_m / truth[k - 1].width_m).ln().abs();
                assert!(dw < 0.25, "width jump {dw}");
                assert!((truth[k].offset_m - truth[k - 1].offset_m).abs() < 1.5);
            }
        }
        assert!(pairs > 0);
    }

    #[test]
    fn strip_membership_matches_coordinates() {
        let map = small_map();
        let truth = street_truth(&map, &TruthOptions::default(), 4).unwrap();
        let (s, t) = map
            .streets
            .segments
            .iter()
            .zip(&truth)
            .find(|(_, t)| t.drivable)
            .unwrap();
        let [c0, c1] = offset_centre_line(s, t);
        let mid = [(c0[0] + c1[0]) / 2.0, (c0[1] + c1[1]) / 2.0];
        assert!(in_strip(s, t, mid));
        let (tt, u) = s.coordinates(mid);
        assert!((tt - s.length_m / 2.0).abs() < 1e-9);
        assert!((u - t.offset_m).abs() < 1e-9);
        // Just outside the left edge.
        let e = [
            (s.b[0] - s.a[0]) / s.length_m,
            (s.b[1] - s.a[1]) / s.length_m,
        ];
        let out = [
            mid[0] - e[1] * (t.width_m / 2.0 + 0.01),
            mid[1] + e[0] * (t.width_m / 2.0 + 0.01),
        ];
        assert!(!in_strip(s, t, out));
    }

    /// A 111 m residential street along x and, `north_m` north of it, a parallel footway
    /// with `footway` tags; the street has `street` tags.
    fn street_and_footway(street: &str, footway: &str, north_m: f64) -> OsmMap {
        let lat = 60.0 + north_m / 111_320.0;
        OsmMap::from_xml_str(&format!(
            r#"<osm><node id="1" lat="60.0" lon="24.0"/><node id="2" lat="60.0" lon="24.002"/>
            <node id="3" lat="{lat}" lon="23.9995"/><node id="4" lat="{lat}" lon="24.0025"/>
            <way id="10"><nd ref="1"/><nd ref="2"/><tag k="highway" v="residential"/>{street}</way>
            <way id="11"><nd ref="3"/><nd ref="4"/><tag k="highway" v="footway"/>{footway}</way>
            </osm>"#
        ))
        .unwrap()
    }

    #[test]
    fn sidewalks_mapped_as_footways_are_the_streets_sidewalk() {
        let sidewalk_tag = r#"<tag k="footway" v="sidewalk"/>"#;
        let separate = r#"<tag k="sidewalk" v="separate"/>"#;
        let sidewalk_of = |street: &str, footway: &str, north_m: f64| {
            let map = street_and_footway(street, footway, north_m);
            let truth = street_truth(&map, &TruthOptions::default(), 3).unwrap();
            let road = map.streets.segments.iter().position(|s| s.way_index == 0);
            let path = map.streets.segments.iter().position(|s| s.way_index == 1);
            (truth[road.unwrap()], truth[path.unwrap()])
        };
        // A tagged sidewalk north of the road: the sidewalk reaches from the kerb to its outer
        // edge (as mapped, with a footway's mean width).
        for north_m in [4.5, 6.0, 8.0] {
            for street in ["", separate] {
                let (road, path) = sidewalk_of(street, sidewalk_tag, north_m);
                let expected = north_m - 0.5 * road.width_m + 1.125;
                assert!(
                    (road.sidewalk_m - expected).abs() < 0.05,
                    "{north_m} {street}: {road:?} {path:?}"
                );
            }
        }
        // A plain footway is the sidewalk only of a road tagged `separate`.
        let (road, _) = sidewalk_of(separate, "", 6.0);
        let expected = 6.0 - 0.5 * road.width_m + 1.125;
        assert!((road.sidewalk_m - expected).abs() < 0.05, "{road:?}");
        let (road, _) = sidewalk_of("", "", 6.0);
        assert!((1.5..=3.0).contains(&road.sidewalk_m), "{road:?}");
        // Too far from the kerb, it is a path of its own: the default, or none for `separate`.
        let (road, _) = sidewalk_of("", sidewalk_tag, 20.0);
        assert!((1.5..=3.0).contains(&road.sidewalk_m), "{road:?}");
        let (road, _) = sidewalk_of(separate, sidewalk_tag, 20.0);
        assert_eq!(road.sidewalk_m, 0.0);
        // `sidewalk=no` stays without one.
        let (road, _) = sidewalk_of(r#"<tag k="sidewalk" v="no"/>"#, sidewalk_tag, 6.0);
        assert_eq!(road.sidewalk_m, 0.0);
    }

    #[test]
    fn rejects_bad_options() {
        let map = small_map();
        let bad = TruthOptions {
            ar_coefficient: 1.0,
            ..TruthOptions::default()
        };
        assert!(street_truth(&map, &bad, 1).is_err());
    }
}
