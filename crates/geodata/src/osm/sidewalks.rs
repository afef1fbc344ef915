//! Sidewalks mapped as ways of their own, found beside the roads they belong to.
//!
//! Many cities draw a street's sidewalks as separate footways (`footway=sidewalk`, with the
//! road tagged `sidewalk=separate`) rather than as a tag of the road. Such a footway tells
//! where the street's sidewalk is: [`mapped_sidewalk_distances`] gives every drivable way
//! the distance of its mapped sidewalks from its centre line.
//!
//! A footway segment belongs to a road segment when it runs parallel to it (within
//! [`MAX_ANGLE_DEG`]), overlaps it along its length, and its centre line lies
//! [`DISTANCE_RANGE_M`] from the road's centre line. The footways considered are those
//! tagged `footway=sidewalk`, and for a road tagged `sidewalk=separate` also its plain
//! `footway` and `path` ways. A way has a mapped sidewalk when such footways run along at
//! least [`MIN_SHARE`] of its length (both sides counted); its distance is the
//! overlap-weighted mean over both sides. Roads tagged `sidewalk=no|none` have none. The
//! thresholds were set once from the OSM sidewalk schema (a sidewalk lies just beyond the
//! kerb), before any evaluation, and not tuned.

use super::model::{HighwayWay, StreetSegment};
use super::tags::is_drivable;
use rstar::primitives::{GeomWithData, Rectangle};
use rstar::{RTree, AABB};

/// Largest angle between a road segment and a footway beside it.
pub const MAX_ANGLE_DEG: f64 = 20.0;
/// Range of the footway centre line's distance from the road's centre line, metres.
pub const DISTANCE_RANGE_M: [f64; 2] = [1.5, 9.0];
/// Share of a way's length along which footways must run beside it.
pub const MIN_SHARE: f64 = 0.25;

/// Per way of `highways` (in order), the overlap-weighted mean distance of its mapped
/// sidewalks from its centre line, metres; `None` for ways without (module docs).
pub fn mapped_sidewalk_distances(
    highways: &[HighwayWay],
    segments: &[StreetSegment],
) -> Vec<Option<f64>> {
    let mut out = vec![None; highways.len()];
    let way = |k: usize| highways.get(segments[k].way_index);
    let tagged = |k: usize| way(k).is_some_and(|w| w.is_sidewalk && !w.tunnel);
    let plain = |k: usize| {
        way(k).is_some_and(|w| matches!(w.highway.as_str(), "footway" | "path") && !w.tunnel)
    };
    let footways: Vec<GeomWithData<Rectangle<[f64; 2]>, usize>> = (0..segments.len())
        .filter(|&k| segments[k].length_m > 0.0 && (tagged(k) || plain(k)))
        .map(|k| {
            let (a, b) = (segments[k].a, segments[k].b);
            let lo = [a[0].min(b[0]), a[1].min(b[1])];
            let hi = [a[0].max(b[0]), a[1].max(b[1])];
            GeomWithData::new(Rectangle::from_corners(lo, hi), k)
        })
        .collect();
    if footways.is_empty() {
        return out;
    }
    let tree = RTree::bulk_load(footways);
    let cos_max = MAX_ANGLE_DEG.to_radians().cos();
    let r = DISTANCE_RANGE_M[1];
    for run in segments.chunk_by(|x, y| x.way_index == y.way_index) {
        let Some(w) = highways.get(run[0].way_index) else {
            continue;
        };
        if !is_drivable(&w.highway) || matches!(w.sidewalk.as_deref(), Some("no" | "none")) {
            continue;
        }
        let plain_too = w.sidewalk.as_deref() == Some("separate");
        let (mut length, mut covered, mut sum) = (0.0, 0.0, 0.0);
        for seg in run {
            length += seg.length_m;
            if seg.length_m <= 0.0 {
                continue;
            }
            let e = [
                (seg.b[0] - seg.a[0]) / seg.length_m,
                (seg.b[1] - seg.a[1]) / seg.length_m,
            ];
            let query = AABB::from_corners(
                [seg.a[0].min(seg.b[0]) - r, seg.a[1].min(seg.b[1]) - r],
                [seg.a[0].max(seg.b[0]) + r, seg.a[1].max(seg.b[1]) + r],
            );
            for f in tree.locate_in_envelope_intersecting(&query) {
                let k = f.data;
                if !(tagged(k) || plain_too) {
                    continue;
                }
                let fs = &segments[k];
                let fe = [
                    (fs.b[0] - fs.a[0]) / fs.length_m,
                    (fs.b[1] - fs.a[1]) / fs.length_m,
                ];
                if (e[0] * fe[0] + e[1] * fe[1]).abs() < cos_max {
                    continue;
                }
                let ((t0, u0), (t1, u1)) = (seg.coordinates(fs.a), seg.coordinates(fs.b));
                let (lo, hi) = (t0.min(t1).max(0.0), t0.max(t1).min(seg.length_m));
                if hi <= lo || (t1 - t0).abs() < 1e-9 {
                    continue;
                }
                // The footway's distance at the middle of the overlap.
                let tm = 0.5 * (lo + hi);
                let u = (u0 + (u1 - u0) * (tm - t0) / (t1 - t0)).abs();
                if !(DISTANCE_RANGE_M[0]..=DISTANCE_RANGE_M[1]).contains(&u) {
                    continue;
                }
                covered += hi - lo;
                sum += (hi - lo) * u;
            }
        }
        if covered > 0.0 && covered >= MIN_SHARE * length {
            out[run[0].way_index] = Some(sum / covered);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use crate::osm::OsmMap;

    /// A 111 m residential road along x (`road` tags) and footways given as
    /// (metres north, start lon, end lon, tags).
    fn map(road: &str, footways: &[(f64, f64, f64, &str)]) -> OsmMap {
        let mut xml = String::from(
            r#"<osm><node id="1" lat="60.0" lon="24.0"/><node id="2" lat="60.0" lon="24.002"/>"#,
        );
        xml += &format!(
            r#"<way id="1"><nd ref="1"/><nd ref="2"/><tag k="highway" v="residential"/>{road}</way>"#
        );
        for (i, (north, lon0, lon1, tags)) in footways.iter().enumerate() {
            let lat = 60.0 + north / 111_320.0;
            let (a, b) = (10 + 2 * i, 11 + 2 * i);
            xml += &format!(
                r#"<node id="{a}" lat="{lat}" lon="{lon0}"/><node id="{b}" lat="{lat}" lon="{lon1}"/>
                <way id="{}"><nd ref="{a}"/><nd ref="{b}"/><tag k="highway" v="footway"/>{tags}</way>"#,
                100 + i
            );
        }
        OsmMap::from_xml_str(&(xml + "</osm>")).unwrap()
    }

    #[test]
    fn mapped_sidewalks_are_found_beside_their_road() {
        let sw = r#"<tag k="footway" v="sidewalk"/>"#;
        let separate = r#"<tag k="sidewalk" v="separate"/>"#;
        let distance = |m: &OsmMap| m.highways[0].mapped_sidewalk_m;
        // Both sides, full length: the mean of the two distances.
        let both = map("", &[(6.0, 24.0, 24.002, sw), (-5.0, 24.0, 24.002, sw)]);
        assert!((distance(&both).unwrap() - 5.5).abs() < 0.05, "{both:?}");
        // Weighted by overlap: 6 m along the whole road, 3 m along its second half.
        let weighted = map("", &[(6.0, 24.0, 24.002, sw), (-3.0, 24.001, 24.003, sw)]);
        assert!((distance(&weighted).unwrap() - 5.0).abs() < 0.05);
        // A plain footway is a sidewalk only of a road tagged `separate`.
        assert_eq!(distance(&map("", &[(6.0, 24.0, 24.002, "")])), None);
        let plain = map(separate, &[(6.0, 24.0, 24.002, "")]);
        assert!((distance(&plain).unwrap() - 6.0).abs() < 0.05);
        // Too far, too short an overlap, `sidewalk=no`: none.
        assert_eq!(distance(&map("", &[(12.0, 24.0, 24.002, sw)])), None);
        assert_eq!(distance(&map("", &[(6.0, 24.0018, 24.003, sw)])), None);
        let no = r#"<tag k="sidewalk" v="no"/>"#;
        assert_eq!(distance(&map(no, &[(6.0, 24.0, 24.002, sw)])), None);
        // The footway itself has none.
        assert_eq!(both.highways[1].mapped_sidewalk_m, None);
    }
}
