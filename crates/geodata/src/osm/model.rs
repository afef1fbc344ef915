//! The map types: buildings, highway ways, street segments, intersections, statistics.
//!
//! Conventions: every coordinate is in the map's local frame ([`crate::projection::LocalFrame`]),
//! `[east, north]` in metres. Rings are closed implicitly: the last vertex is *not* a repeat
//! of the first. Outer rings are counter-clockwise (positive signed area), inner rings
//! (courtyards) clockwise.

use crate::projection::LocalFrame;
use serde::Serialize;

/// Which OSM element a building came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum ElementKind {
    /// A closed way tagged `building=*`.
    Way,
    /// A `type=multipolygon` relation tagged `building=*`.
    Relation,
}

/// One building outline (one outer ring with its holes).
///
/// An element whose area has several outer rings (a multipolygon relation with several
/// outer rings, or a way that touches itself, as in a figure eight) yields several
/// `Building`s with the same `osm_id`; see [`super`] for how rings are assembled.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Building {
    /// Id of the OSM way or relation.
    pub osm_id: i64,
    /// Way or relation.
    pub kind: ElementKind,
    /// Value of the `building` tag (`yes`, `house`, …).
    pub building: String,
    /// Outer ring, counter-clockwise, last vertex not repeated, metres in the local frame.
    pub outer: Vec<[f64; 2]>,
    /// Inner rings (holes), clockwise, last vertex not repeated.
    pub inners: Vec<Vec<[f64; 2]>>,
    /// `height` in metres, when tagged and numeric.
    pub height_m: Option<f64>,
    /// `building:levels`, when tagged and numeric.
    pub levels: Option<f64>,
    /// `name`, when tagged.
    pub name: Option<String>,
}

/// One OSM way tagged `highway=*`, with its geometry in the local frame.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HighwayWay {
    /// Id of the OSM way.
    pub osm_id: i64,
    /// Value of the `highway` tag (`primary`, `residential`, `footway`, …).
    pub highway: String,
    /// `name`, when tagged.
    pub name: Option<String>,
    /// `width` in metres, when tagged and numeric.
    pub width_m: Option<f64>,
    /// `lanes`, when tagged and numeric.
    pub lanes: Option<u32>,
    /// `tunnel` is tagged and not `no`.
    pub tunnel: bool,
    /// `layer` (0 when untagged or not an integer).
    pub layer: i32,
    /// `sidewalk` value (`both`, `left`, `no`, `separate`, …), when tagged, by the `sidewalk`
    /// key or by `sidewalk:both` / `sidewalk:left` / `sidewalk:right`.
    pub sidewalk: Option<String>,
    /// `footway=sidewalk`: this way is a street's sidewalk, mapped as a way of its own.
    pub is_sidewalk: bool,
    /// Distance of the footways mapped as this road's sidewalks from its centre line, metres,
    /// derived while reading the map ([`super::sidewalks`]); `None` without.
    pub mapped_sidewalk_m: Option<f64>,
    /// `oneway=yes|true|1|-1`.
    pub oneway: bool,
    /// `area=yes`: a pedestrian square or similar, not a centre line (kept out of the network).
    pub area: bool,
    /// OSM node ids in way order.
    pub node_ids: Vec<i64>,
    /// Node positions in way order, metres in the local frame.
    pub points: Vec<[f64; 2]>,
}

impl Building {
    /// A way tagged `building=yes` and nothing else, with this outline and these holes (maps
    /// drawn by code: façade maps, test cities).
    pub fn outline(osm_id: i64, outer: Vec<[f64; 2]>, inners: Vec<Vec<[f64; 2]>>) -> Building {
        Building {
            osm_id,
            kind: ElementKind::Way,
            building: "yes".into(),
            outer,
            inners,
            height_m: None,
            levels: None,
            name: None,
        }
    }
}

impl HighwayWay {
    /// A way tagged `highway=<highway>` and nothing else, through these nodes.
    pub fn plain(
        osm_id: i64,
        highway: &str,
        node_ids: Vec<i64>,
        points: Vec<[f64; 2]>,
    ) -> HighwayWay {
        HighwayWay {
            osm_id,
            highway: highway.into(),
            name: None,
            width_m: None,
            lanes: None,
            tunnel: false,
            layer: 0,
            sidewalk: None,
            is_sidewalk: false,
            mapped_sidewalk_m: None,
            oneway: false,
            area: false,
            node_ids,
            points,
        }
    }
}

/// A street segment: the straight piece between two consecutive nodes of a highway way.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StreetSegment {
    /// Index of the way in [`super::OsmMap::highways`].
    pub way_index: usize,
    /// Position of the segment in its way (0 = first).
    pub index_in_way: usize,
    /// OSM node id of the start point `p_{s,b}`.
    pub from_node: i64,
    /// OSM node id of the end point `p_{s,e}`.
    pub to_node: i64,
    /// Start point, metres in the local frame.
    pub a: [f64; 2],
    /// End point, metres in the local frame.
    pub b: [f64; 2],
    /// Euclidean length in metres.
    pub length_m: f64,
    /// The way's `highway` value.
    pub highway: String,
}

impl StreetSegment {
    /// The along and lateral coordinates (t, u) of a point in the segment's frame: t from `a`
    /// towards `b`, u to the left of that direction, metres ((0, 0) for a zero-length segment).
    pub fn coordinates(&self, p: [f64; 2]) -> (f64, f64) {
        let d = [self.b[0] - self.a[0], self.b[1] - self.a[1]];
        let len = (d[0] * d[0] + d[1] * d[1]).sqrt();
        if len <= 0.0 {
            return (0.0, 0.0);
        }
        let e = [d[0] / len, d[1] / len];
        let q = [p[0] - self.a[0], p[1] - self.a[1]];
        (q[0] * e[0] + q[1] * e[1], -q[0] * e[1] + q[1] * e[0])
    }
}

/// A street intersection: a node shared by ≥ 3 segment ends or by two different ways.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Intersection {
    /// OSM node id.
    pub node_id: i64,
    /// Position, metres in the local frame.
    pub position: [f64; 2],
    /// Indices into [`StreetNetwork::segments`] of the segments ending here, ascending.
    pub segment_ids: Vec<usize>,
}

/// The street graph G = (P, S) of thesis §4.4.2 with its neighbour pairs N.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct StreetNetwork {
    /// All segments S, way by way in way order.
    pub segments: Vec<StreetSegment>,
    /// Intersections, sorted by node id.
    pub intersections: Vec<Intersection>,
    /// Neighbour pairs N as `[s1, s2]` with `s1 < s2`, sorted: segments sharing a waypoint.
    pub neighbour_pairs: Vec<[usize; 2]>,
}

/// Element counts and everything that was skipped while building the map.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct OsmStats {
    /// Nodes in the file.
    pub nodes: usize,
    /// Ways in the file.
    pub ways: usize,
    /// Relations in the file.
    pub relations: usize,
    /// Closed ways with `building=*` other than `no` (counted whether or not their nodes
    /// resolve): first and last node the same, or at the same location.
    pub building_ways: usize,
    /// `type=multipolygon` relations with `building=*` other than `no`.
    pub building_relations: usize,
    /// Ways with a `highway=*` tag.
    pub highway_ways: usize,
    /// Ways with `building=*` (not `no`) that are not closed; not buildings.
    pub open_building_ways: usize,
    /// Building ways skipped because a node reference was missing from the file.
    pub skipped_building_ways_missing_nodes: usize,
    /// Building ways skipped because no area is left: fewer than 3 distinct locations, or
    /// every segment cancels against its way back.
    pub skipped_building_ways_degenerate: usize,
    /// Building ways skipped because two of their segments cross, overlap, or touch away
    /// from a shared node (osmium declares these invalid too).
    pub skipped_building_ways_crossing: usize,
    /// Building relations skipped because a member way or node was missing from the file.
    pub skipped_building_relations_missing_members: usize,
    /// Building relations skipped because their member ways do not join into closed rings.
    pub skipped_building_relations_unclosed: usize,
    /// Building relations skipped because segments of their member ways cross, overlap, or
    /// touch away from a shared node.
    pub skipped_building_relations_crossing: usize,
    /// Building relations skipped because no area is left: all segments cancel in pairs,
    /// or a member way cancels out entirely (a way listed twice, a duplicated ring).
    pub skipped_building_relations_degenerate: usize,
    /// Highway ways skipped because a node reference was missing from the file.
    pub skipped_highway_ways_missing_nodes: usize,
    /// Highway ways with fewer than two nodes.
    pub skipped_highway_ways_too_short: usize,
}

/// A parsed OSM map in one local metric frame.
#[derive(Debug, Clone)]
pub struct OsmMap {
    /// The local frame all coordinates are in.
    pub frame: LocalFrame,
    /// `[min_lon, min_lat, max_lon, max_lat]`: the file's bounds, or the nodes' extent without bounds.
    pub bbox_lonlat: [f64; 4],
    /// Building outlines (ways first in file order, then relations).
    pub buildings: Vec<Building>,
    /// All highway ways whose nodes resolved, in file order.
    pub highways: Vec<HighwayWay>,
    /// Street segments, intersections and neighbour pairs built from the non-area highways.
    pub streets: StreetNetwork,
    /// Counts and skipped elements.
    pub stats: OsmStats,
}

impl OsmMap {
    /// Number of building elements in the file: closed `building=*` ways plus building multipolygons.
    pub fn building_count(&self) -> usize {
        self.stats.building_ways + self.stats.building_relations
    }
}

#[cfg(test)]
mod tests {
    use super::StreetSegment;

    #[test]
    fn segment_coordinates_run_along_and_left() {
        let seg = StreetSegment {
            way_index: 0,
            index_in_way: 0,
            from_node: 1,
            to_node: 2,
            a: [1.0, 1.0],
            b: [4.0, 5.0],
            length_m: 5.0,
            highway: "residential".into(),
        };
        let close = |(t, u): (f64, f64), want: (f64, f64)| {
            assert!(
                (t - want.0).abs() < 1e-12 && (u - want.1).abs() < 1e-12,
                "{t} {u}"
            );
        };
        close(seg.coordinates(seg.a), (0.0, 0.0));
        close(seg.coordinates(seg.b), (5.0, 0.0));
        // 2 m to the left of the middle: along (0.6, 0.8), left normal (-0.8, 0.6).
        close(seg.coordinates([2.5 - 1.6, 3.0 + 1.2]), (2.5, 2.0));
        close(seg.coordinates([2.5 + 1.6, 3.0 - 1.2]), (2.5, -2.0));
        let point = StreetSegment { b: seg.a, ..seg };
        close(point.coordinates([9.0, 9.0]), (0.0, 0.0));
    }
}
