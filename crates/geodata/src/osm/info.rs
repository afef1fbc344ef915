//! What a map file holds (`urbansem osm info`): element counts, buildings, street network.

use super::model::{OsmMap, OsmStats};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::Path;

/// The statistics of one parsed map file (`osm info --json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OsmInfo {
    /// The map file.
    pub file: String,
    /// Building elements: closed ways plus multipolygons.
    pub buildings: usize,
    /// Ways with a `highway=*` tag.
    pub highway_ways: usize,
    /// Street segments.
    pub segments: usize,
    /// Street intersections.
    pub intersections: usize,
    /// `[min_lon, min_lat, max_lon, max_lat]`.
    pub bbox: [f64; 4],
    /// Closed building ways.
    pub building_ways: usize,
    /// Building multipolygons.
    pub building_relations: usize,
    /// Building outlines built from them.
    pub building_outlines: usize,
    /// Pairs of neighbouring street segments.
    pub neighbour_pairs: usize,
    /// Total length of the street segments, metres.
    pub street_length_m: f64,
    /// Nodes in the file.
    pub nodes: usize,
    /// Ways in the file.
    pub ways: usize,
    /// Relations in the file.
    pub relations: usize,
    /// WGS84 origin of the local frame, degrees.
    pub frame_origin_lat_lon: [f64; 2],
    /// Every count, skipped elements included.
    pub stats: OsmStats,
    /// Seconds spent parsing.
    pub parse_seconds: f64,
}

impl OsmInfo {
    /// The statistics of `map`, read from `file` in `parse_seconds`.
    pub fn new(file: &Path, map: &OsmMap, parse_seconds: f64) -> Self {
        let s = &map.stats;
        let (origin_lat, origin_lon) = map.frame.origin();
        Self {
            file: file.display().to_string(),
            buildings: map.building_count(),
            highway_ways: s.highway_ways,
            segments: map.streets.segments.len(),
            intersections: map.streets.intersections.len(),
            bbox: map.bbox_lonlat,
            building_ways: s.building_ways,
            building_relations: s.building_relations,
            building_outlines: map.buildings.len(),
            neighbour_pairs: map.streets.neighbour_pairs.len(),
            street_length_m: map.streets.segments.iter().map(|x| x.length_m).sum::<f64>(),
            nodes: s.nodes,
            ways: s.ways,
            relations: s.relations,
            frame_origin_lat_lon: [origin_lat, origin_lon],
            stats: s.clone(),
            parse_seconds,
        }
    }

    /// A readable summary, one line per topic.
    pub fn text(&self) -> String {
        let s = &self.stats;
        let [origin_lat, origin_lon] = self.frame_origin_lat_lon;
        let mut out = String::new();
        let _ = writeln!(out, "{}", self.file);
        let _ = writeln!(
            out,
            "  elements        {} nodes, {} ways, {} relations",
            s.nodes, s.ways, s.relations
        );
        let _ = writeln!(
            out,
            "  bbox            lon {:.5}..{:.5}, lat {:.5}..{:.5}",
            self.bbox[0], self.bbox[2], self.bbox[1], self.bbox[3]
        );
        let _ = writeln!(
            out,
            "  frame origin    lat {origin_lat:.6}, lon {origin_lon:.6}"
        );
        let _ = writeln!(
            out,
            "  buildings       {} ({} closed ways + {} multipolygons) → {} outlines",
            self.buildings, s.building_ways, s.building_relations, self.building_outlines
        );
        let _ = writeln!(out, "  highway ways    {}", s.highway_ways);
        let _ = writeln!(
            out,
            "  street network  {} segments ({:.1} km), {} intersections, {} neighbour pairs",
            self.segments,
            self.street_length_m / 1000.0,
            self.intersections,
            self.neighbour_pairs
        );
        let _ = writeln!(
            out,
            "  skipped         buildings: {} missing nodes, {} degenerate, {} relations missing members, {} unclosed; highways: {} missing nodes, {} too short; {} open building ways",
            s.skipped_building_ways_missing_nodes,
            s.skipped_building_ways_degenerate,
            s.skipped_building_relations_missing_members,
            s.skipped_building_relations_unclosed,
            s.skipped_highway_ways_missing_nodes,
            s.skipped_highway_ways_too_short,
            s.open_building_ways
        );
        let _ = writeln!(out, "  parse time      {:.3} s", self.parse_seconds);
        out
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn counts_a_building_and_a_street_and_prints_them() {
        let xml = r#"<osm version="0.6">
          <node id="1" lat="48.0" lon="11.0"/><node id="2" lat="48.0" lon="11.001"/>
          <node id="3" lat="48.001" lon="11.001"/>
          <way id="10"><nd ref="1"/><nd ref="2"/><nd ref="3"/><nd ref="1"/><tag k="building" v="yes"/></way>
          <way id="11"><nd ref="1"/><nd ref="3"/><tag k="highway" v="service"/></way>
        </osm>"#;
        let map = OsmMap::from_xml_str(xml).unwrap();
        let info = OsmInfo::new(Path::new("t.osm"), &map, 0.5);
        assert_eq!((info.buildings, info.building_outlines), (1, 1));
        assert_eq!((info.highway_ways, info.segments), (1, 1));
        assert_eq!((info.nodes, info.ways, info.relations), (3, 2, 0));
        let text = info.text();
        assert!(text.starts_with("t.osm\n  elements        3 nodes, 2 ways, 0 relations\n"));
        assert!(
            text.contains("  buildings       1 (1 closed ways + 0 multipolygons) → 1 outlines\n")
        );
        assert!(text.ends_with("  parse time      0.500 s\n"));
    }
}
