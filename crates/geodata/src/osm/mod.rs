//! OpenStreetMap ingestion: `.osm` XML and `.osm.pbf` → buildings, highway ways, street network.
//!
//! Both readers stream the file into the same raw element tables (nodes, ways, relations with
//! only the tags urbansem uses), then [`OsmMap`] is assembled from them in a local metric
//! frame ([`crate::projection::LocalFrame`]) whose origin is the centre of the file's
//! `<bounds>` (or of the nodes' extent when the file has none).
//!
//! - Buildings: closed ways with `building=*` other than `no`, and `type=multipolygon`
//!   relations with `building=*`, assembled into polygons with holes as libosmium's area
//!   assembler does (module `rings`): from the segments between nodes, duplicates cancelled in
//!   pairs, rings split where they touch themselves, inner/outer decided by nesting rather
//!   than member roles. Checked on libosmium's multipolygon test suite
//!   (`tests/osm_testdata.rs`): osmium's polygons, holes and areas on all 50 valid cases.
//! - Where osmium declares an area invalid, urbansem repairs what has one reading (a node
//!   repeated at one location, ring ends that are different nodes at one location, a spike
//!   traced out and back) and skips the rest, counting each reason in [`OsmStats`]: open
//!   rings, crossing or overlapping segments, members that duplicate each other (7 repaired and
//!   23 skipped of osmium's 30 invalid cases).
//! - Highways: every way with `highway=*`; all but `area=yes` ones form the street network
//!   ([`network`]): segments between consecutive nodes, intersections, neighbour pairs N
//!   (thesis §4.4.2).
//! - Elements that reference nodes or ways missing from the file (extracts cut at the border)
//!   are skipped and counted in [`OsmStats`], never silently.
//!
//! Cost: reading is linear in the file (streaming XML; PBF blobs bounded by the format's
//! limits and by the file's size before anything is allocated), node lookups are hashed,
//! and assembling an area of n segments is O(n log n), so loading a map is O(N log N) in
//! its size N.
//!
//! ```
//! let xml = r#"<osm version="0.6">
//!   <node id="1" lat="48.0" lon="11.0"/><node id="2" lat="48.0" lon="11.001"/>
//!   <node id="3" lat="48.001" lon="11.001"/>
//!   <way id="10"><nd ref="1"/><nd ref="2"/><nd ref="3"/><nd ref="1"/><tag k="building" v="yes"/></way>
//!   <way id="11"><nd ref="1"/><nd ref="3"/><tag k="highway" v="service"/></way>
//! </osm>"#;
//! let map = geodata::osm::OsmMap::from_xml_str(xml).unwrap();
//! assert_eq!(map.buildings.len(), 1);
//! assert_eq!(map.streets.segments.len(), 1);
//! ```

pub mod error;
pub mod geometry;
pub mod index;
pub mod info;
pub mod model;
pub mod network;
mod pbf;
mod rings;
pub mod sidewalks;
pub mod tags;
pub mod write;
mod xml;

pub use error::OsmError;
pub use index::MapIndex;
pub use model::{
    Building, ElementKind, HighwayWay, Intersection, OsmMap, OsmStats, StreetNetwork, StreetSegment,
};

use crate::projection::LocalFrame;
use rayon::prelude::*;
use std::path::Path;

/// Tag keys kept from ways and relations; everything else is dropped while reading.
pub(crate) const KEPT_KEYS: [&str; 17] = [
    "building",
    "highway",
    "footway",
    "name",
    "width",
    "lanes",
    "tunnel",
    "layer",
    "sidewalk",
    "sidewalk:both",
    "sidewalk:left",
    "sidewalk:right",
    "oneway",
    "height",
    "building:levels",
    "area",
    "type",
];

/// Whether a tag key is one [`KEPT_KEYS`] holds.
pub(crate) fn is_kept_key(key: &[u8]) -> bool {
    KEPT_KEYS.iter().any(|k| k.as_bytes() == key)
}

/// A node as read: id and WGS84 position in degrees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct RawNode {
    pub id: i64,
    pub lat: f64,
    pub lon: f64,
}

/// A way as read: id, node references and kept tags.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct RawWay {
    pub id: i64,
    pub refs: Vec<i64>,
    pub tags: Vec<(String, String)>,
}

/// A relation as read: id, way members with their role, kept tags, count of non-way members.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct RawRelation {
    pub id: i64,
    pub way_members: Vec<(i64, String)>,
    pub tags: Vec<(String, String)>,
}

/// Everything a reader produces.
#[derive(Debug, Default)]
pub(crate) struct RawData {
    /// `[min_lon, min_lat, max_lon, max_lat]` from the file header, if any.
    pub bounds: Option<[f64; 4]>,
    pub nodes: Vec<RawNode>,
    pub ways: Vec<RawWay>,
    pub relations: Vec<RawRelation>,
}

/// A way's sidewalks as one `sidewalk` value (`both`, `left`, `right`, `no`, `separate`, …):
/// the `sidewalk` tag when present, else from `sidewalk:both` or `sidewalk:left` /
/// `sidewalk:right` (the per-side scheme many cities map with): the sides with a sidewalk
/// (`yes`) give `both`, `left` or `right`; with none, `separate` when a side is mapped as its
/// own way, else `no`.
fn sidewalk_value(tags: &[(String, String)]) -> Option<String> {
    if let Some(v) = tag(tags, "sidewalk").or_else(|| tag(tags, "sidewalk:both")) {
        return Some(v.to_string());
    }
    let (left, right) = (tag(tags, "sidewalk:left"), tag(tags, "sidewalk:right"));
    if left.is_none() && right.is_none() {
        return None;
    }
    let yes = |v: Option<&str>| v == Some("yes");
    Some(
        match (yes(left), yes(right)) {
            (true, true) => "both",
            (true, false) => "left",
            (false, true) => "right",
            _ if left == Some("separate") || right == Some("separate") => "separate",
            _ => "no",
        }
        .to_string(),
    )
}

fn tag<'a>(tags: &'a [(String, String)], key: &str) -> Option<&'a str> {
    tags.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
}

/// Leading decimal number of a tag value (`"12"`, `"12.5 m"`, `"3;4"` → 3); `None` if there is none.
fn leading_number(value: &str) -> Option<f64> {
    let trimmed = value.trim();
    let end = trimmed
        .char_indices()
        .find(|(_, c)| !(c.is_ascii_digit() || *c == '.' || *c == '-'))
        .map_or(trimmed.len(), |(i, _)| i);
    trimmed
        .get(..end)?
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
}

fn is_building(tags: &[(String, String)]) -> Option<&str> {
    tag(tags, "building").filter(|v| *v != "no")
}

/// Node table: the nodes as read, found by id through a hash index. Positions are projected
/// when a kept way asks for them (in the parallel way pass), so nodes that no building or
/// street uses (points of interest, landuse, water) are never projected.
pub(crate) struct NodeTable<'a> {
    /// The nodes as read, in file order.
    nodes: &'a [RawNode],
    /// Index into `nodes` per node id; of equal ids the last in the file wins.
    index_by_id: rustc_hash::FxHashMap<i64, u32>,
    projector: crate::projection::BoxProjector,
}

impl<'a> NodeTable<'a> {
    /// Indexes the nodes by id (node ids in references are rarely consecutive, so a hash
    /// lookup beats a search of the sorted ids).
    fn new(nodes: &'a [RawNode], frame: &LocalFrame, bbox_lonlat: [f64; 4]) -> Self {
        let mut index_by_id = rustc_hash::FxHashMap::default();
        index_by_id.reserve(nodes.len());
        for (k, node) in nodes.iter().enumerate() {
            // More than 2^32 nodes cannot be held in memory as RawNodes anyway.
            index_by_id.insert(node.id, k as u32);
        }
        NodeTable {
            nodes,
            index_by_id,
            projector: crate::projection::BoxProjector::new(*frame, bbox_lonlat),
        }
    }

    /// The node of an id, if the file has it.
    fn node(&self, id: i64) -> Option<&RawNode> {
        self.nodes.get(*self.index_by_id.get(&id)? as usize)
    }

    /// Local position of a node id, if the file has it.
    fn local(&self, id: i64) -> Option<[f64; 2]> {
        let node = self.node(id)?;
        Some(self.projector.to_local(node.lat, node.lon))
    }

    /// Fixed-point location (osmium's 1e-7 degree grid) and local position of a node id, if
    /// the file has it with a valid WGS84 position.
    fn location(&self, id: i64) -> Option<rings::PieceNode> {
        let node = self.node(id)?;
        let fixed = rings::fixed_location(node.lat, node.lon)?;
        Some((fixed, self.projector.to_local(node.lat, node.lon)))
    }

    /// Whether two node ids are at one location (the same id, or the same fixed point).
    fn same_location(&self, a: i64, b: i64) -> bool {
        a == b
            || matches!(
                (self.location(a), self.location(b)),
                (Some((p, _)), Some((q, _))) if p == q
            )
    }

    /// Local positions of all `refs`, or `None` if any is missing.
    fn project(&self, refs: &[i64]) -> Option<Vec<[f64; 2]>> {
        refs.iter().map(|&id| self.local(id)).collect()
    }
}

/// What one way contributes: its building outlines (several for a way that touches itself)
/// and its highway, if any.
struct WayOutcome {
    buildings: Vec<Building>,
    highway: Option<HighwayWay>,
}

/// Ways per parallel task when building outlines and highways.
const WAY_CHUNK: usize = 2048;

#[derive(Default)]
struct WayCounts {
    building_ways: usize,
    open_building_ways: usize,
    highway_ways: usize,
    building_missing: usize,
    building_degenerate: usize,
    building_crossing: usize,
    highway_missing: usize,
    highway_short: usize,
}

impl WayCounts {
    fn add(&mut self, o: &WayCounts) {
        self.building_ways += o.building_ways;
        self.open_building_ways += o.open_building_ways;
        self.highway_ways += o.highway_ways;
        self.building_missing += o.building_missing;
        self.building_degenerate += o.building_degenerate;
        self.building_crossing += o.building_crossing;
        self.highway_missing += o.highway_missing;
        self.highway_short += o.highway_short;
    }
}

/// The building outlines of one element, one per assembled polygon.
fn outlines(
    polygons: Vec<rings::Polygon>,
    osm_id: i64,
    kind: ElementKind,
    value: &str,
    tags: &[(String, String)],
) -> impl Iterator<Item = Building> {
    let height_m = tag(tags, "height").and_then(leading_number);
    let levels = tag(tags, "building:levels").and_then(leading_number);
    let name = tag(tags, "name").map(str::to_string);
    let value = value.to_string();
    polygons.into_iter().map(move |(outer, inners)| Building {
        osm_id,
        kind,
        building: value.clone(),
        outer,
        inners,
        height_m,
        levels,
        name: name.clone(),
    })
}

fn build_way(way: &RawWay, nodes: &NodeTable, counts: &mut WayCounts) -> WayOutcome {
    let mut buildings = Vec::new();
    if let Some(value) = is_building(&way.tags) {
        // Closed: first and last node the same, or two nodes at one location (repaired).
        let closed = way.refs.len() >= 4
            && matches!((way.refs.first(), way.refs.last()),
                (Some(&f), Some(&l)) if nodes.same_location(f, l));
        if closed {
            counts.building_ways += 1;
            match rings::assemble(&[&way.refs], nodes) {
                Err(rings::RingError::Missing) => counts.building_missing += 1,
                Err(rings::RingError::Crossing) => counts.building_crossing += 1,
                Err(
                    rings::RingError::Cancelled
                    | rings::RingError::Degenerate
                    | rings::RingError::Unclosed,
                ) => counts.building_degenerate += 1,
                Ok(polygons) => {
                    buildings.extend(outlines(
                        polygons,
                        way.id,
                        ElementKind::Way,
                        value,
                        &way.tags,
                    ));
                }
            }
        } else {
            counts.open_building_ways += 1;
        }
    }
    let mut highway = None;
    if let Some(kind) = tag(&way.tags, "highway") {
        counts.highway_ways += 1;
        if way.refs.len() < 2 {
            counts.highway_short += 1;
        } else {
            match nodes.project(&way.refs) {
                None => counts.highway_missing += 1,
                Some(points) => {
                    highway = Some(HighwayWay {
                        osm_id: way.id,
                        highway: kind.to_string(),
                        name: tag(&way.tags, "name").map(str::to_string),
                        width_m: tag(&way.tags, "width").and_then(leading_number),
                        lanes: tag(&way.tags, "lanes").and_then(|v| v.trim().parse::<u32>().ok()),
                        tunnel: tag(&way.tags, "tunnel").is_some_and(|v| v != "no"),
                        layer: tag(&way.tags, "layer")
                            .and_then(|v| v.trim().parse().ok())
                            .unwrap_or(0),
                        sidewalk: sidewalk_value(&way.tags),
                        is_sidewalk: tag(&way.tags, "footway") == Some("sidewalk"),
                        mapped_sidewalk_m: None,
                        oneway: tag(&way.tags, "oneway")
                            .is_some_and(|v| matches!(v, "yes" | "true" | "1" | "-1")),
                        area: tag(&way.tags, "area") == Some("yes"),
                        node_ids: way.refs.clone(),
                        points,
                    })
                }
            }
        }
    }
    WayOutcome { buildings, highway }
}

/// The frame origin for raw data: centre of the bounds, else of the nodes' extent.
fn extent_of(raw: &RawData, source_name: &str) -> Result<[f64; 4], OsmError> {
    if let Some(b) = raw.bounds {
        return Ok(b);
    }
    let mut bbox = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for n in &raw.nodes {
        bbox = [
            bbox[0].min(n.lon),
            bbox[1].min(n.lat),
            bbox[2].max(n.lon),
            bbox[3].max(n.lat),
        ];
    }
    if raw.nodes.is_empty() {
        return Err(OsmError::EmptyMap {
            source_name: source_name.to_string(),
        });
    }
    Ok(bbox)
}

impl OsmMap {
    /// Reads an `.osm` (XML) or `.osm.pbf` file; the frame is centred on the file's bounds.
    pub fn load(path: impl AsRef<Path>) -> Result<OsmMap, OsmError> {
        Self::load_in_frame(path, None)
    }

    /// Reads a file like [`OsmMap::load`], into `frame` when one is given (to share a frame).
    pub fn load_in_frame(
        path: impl AsRef<Path>,
        frame: Option<LocalFrame>,
    ) -> Result<OsmMap, OsmError> {
        let path = path.as_ref();
        let name = path.to_string_lossy().to_lowercase();
        let raw = if name.ends_with(".pbf") {
            pbf::read_pbf(path)?
        } else if name.ends_with(".osm") || name.ends_with(".xml") {
            let file = std::fs::File::open(path).map_err(|source| OsmError::Io {
                path: path.to_path_buf(),
                source,
            })?;
            xml::read_xml(
                std::io::BufReader::with_capacity(1 << 16, file),
                &path.display().to_string(),
            )?
        } else {
            return Err(OsmError::UnknownExtension {
                path: path.to_path_buf(),
            });
        };
        Self::from_raw(raw, frame, &path.display().to_string())
    }

    /// Parses OSM XML held in a string (frame centred on its bounds).
    pub fn from_xml_str(xml: &str) -> Result<OsmMap, OsmError> {
        Self::from_xml_reader(xml.as_bytes(), "<string>", None)
    }

    /// Parses OSM XML from any buffered reader; `source_name` appears in errors.
    pub fn from_xml_reader<R: std::io::BufRead>(
        reader: R,
        source_name: &str,
        frame: Option<LocalFrame>,
    ) -> Result<OsmMap, OsmError> {
        let raw = xml::read_xml(reader, source_name)?;
        Self::from_raw(raw, frame, source_name)
    }

    pub(crate) fn from_raw(
        raw: RawData,
        frame: Option<LocalFrame>,
        source_name: &str,
    ) -> Result<OsmMap, OsmError> {
        let bbox_lonlat = extent_of(&raw, source_name)?;
        let frame = match frame {
            Some(f) => f,
            None => LocalFrame::new(
                0.5 * (bbox_lonlat[1] + bbox_lonlat[3]),
                0.5 * (bbox_lonlat[0] + bbox_lonlat[2]),
            )
            .map_err(|source| OsmError::Frame {
                source_name: source_name.to_string(),
                source,
            })?,
        };
        let mut stats = OsmStats {
            nodes: raw.nodes.len(),
            ways: raw.ways.len(),
            relations: raw.relations.len(),
            ..OsmStats::default()
        };
        let nodes = NodeTable::new(&raw.nodes, &frame, bbox_lonlat);

        // Chunks of ways in parallel, each into its own buildings, highways and counts; the
        // chunks are joined in order, so the output keeps the file's way order.
        type Chunk = (Vec<Building>, Vec<HighwayWay>, WayCounts);
        let chunks: Vec<Chunk> = raw
            .ways
            .par_chunks(WAY_CHUNK)
            .map(|ways| {
                let mut chunk: Chunk = (Vec::new(), Vec::new(), WayCounts::default());
                for w in ways {
                    let outcome = build_way(w, &nodes, &mut chunk.2);
                    chunk.0.extend(outcome.buildings);
                    chunk.1.extend(outcome.highway);
                }
                chunk
            })
            .collect();
        let mut buildings = Vec::with_capacity(chunks.iter().map(|c| c.0.len()).sum());
        let mut highways = Vec::with_capacity(chunks.iter().map(|c| c.1.len()).sum());
        let mut counts = WayCounts::default();
        for (bs, hs, c) in chunks {
            buildings.extend(bs);
            highways.extend(hs);
            counts.add(&c);
        }
        stats.building_ways += counts.building_ways;
        stats.open_building_ways += counts.open_building_ways;
        stats.highway_ways += counts.highway_ways;
        stats.skipped_building_ways_missing_nodes += counts.building_missing;
        stats.skipped_building_ways_degenerate += counts.building_degenerate;
        stats.skipped_building_ways_crossing += counts.building_crossing;
        stats.skipped_highway_ways_missing_nodes += counts.highway_missing;
        stats.skipped_highway_ways_too_short += counts.highway_short;

        let mut way_refs: rustc_hash::FxHashMap<i64, &[i64]> = rustc_hash::FxHashMap::default();
        let wanted: rustc_hash::FxHashSet<i64> = raw
            .relations
            .iter()
            .filter(|r| {
                tag(&r.tags, "type") == Some("multipolygon") && is_building(&r.tags).is_some()
            })
            .flat_map(|r| r.way_members.iter().map(|(id, _)| *id))
            .collect();
        for w in &raw.ways {
            if wanted.contains(&w.id) {
                way_refs.insert(w.id, &w.refs);
            }
        }
        for rel in &raw.relations {
            if tag(&rel.tags, "type") != Some("multipolygon") {
                continue;
            }
            let Some(value) = is_building(&rel.tags) else {
                continue;
            };
            stats.building_relations += 1;
            let pieces: Option<Vec<&[i64]>> = rel
                .way_members
                .iter()
                .map(|(way_id, _role)| way_refs.get(way_id).copied())
                .collect();
            let assembled = pieces.map_or(Err(rings::RingError::Missing), |pieces| {
                rings::assemble(&pieces, &nodes)
            });
            match assembled {
                Err(rings::RingError::Missing) => {
                    stats.skipped_building_relations_missing_members += 1
                }
                Err(rings::RingError::Unclosed) => stats.skipped_building_relations_unclosed += 1,
                Err(rings::RingError::Crossing) => stats.skipped_building_relations_crossing += 1,
                Err(rings::RingError::Cancelled | rings::RingError::Degenerate) => {
                    stats.skipped_building_relations_degenerate += 1
                }
                Ok(polygons) => buildings.extend(outlines(
                    polygons,
                    rel.id,
                    ElementKind::Relation,
                    value,
                    &rel.tags,
                )),
            }
        }
        let streets = network::build_network(&highways);
        let distances = sidewalks::mapped_sidewalk_distances(&highways, &streets.segments);
        for (way, d) in highways.iter_mut().zip(distances) {
            way.mapped_sidewalk_m = d;
        }
        Ok(OsmMap {
            frame,
            bbox_lonlat,
            buildings,
            highways,
            streets,
            stats,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn leading_numbers() {
        assert_eq!(leading_number("12"), Some(12.0));
        assert_eq!(leading_number(" 12.5 m"), Some(12.5));
        assert_eq!(leading_number("3;4"), Some(3.0));
        assert_eq!(leading_number("tall"), None);
    }

    #[test]
    fn missing_nodes_are_counted_not_silent() {
        let xml = r#"<osm><node id="1" lat="48.0" lon="11.0"/><node id="2" lat="48.0" lon="11.001"/>
            <way id="5"><nd ref="1"/><nd ref="2"/><nd ref="99"/><nd ref="1"/><tag k="building" v="yes"/></way>
            <way id="6"><nd ref="1"/><nd ref="98"/><tag k="highway" v="footway"/></way>
            <way id="7"><nd ref="1"/><nd ref="2"/><tag k="building" v="no"/></way></osm>"#;
        let map = OsmMap::from_xml_str(xml).unwrap();
        assert_eq!(map.building_count(), 1);
        assert_eq!(map.buildings.len(), 0);
        assert_eq!(map.stats.skipped_building_ways_missing_nodes, 1);
        assert_eq!(map.stats.highway_ways, 1);
        assert_eq!(map.stats.skipped_highway_ways_missing_nodes, 1);
    }

    #[test]
    fn sidewalks_are_read_from_every_tagging_scheme() {
        let way = |id: usize, tags: &str| {
            format!(
                r#"<way id="{id}"><nd ref="1"/><nd ref="2"/><tag k="highway" v="residential"/>{tags}</way>"#
            )
        };
        let t = |k: &str, v: &str| format!(r#"<tag k="{k}" v="{v}"/>"#);
        let cases: [(String, Option<&str>); 9] = [
            (String::new(), None),
            (t("sidewalk", "both"), Some("both")),
            // The plain key wins over the per-side scheme.
            (t("sidewalk", "no") + &t("sidewalk:left", "yes"), Some("no")),
            (t("sidewalk:both", "separate"), Some("separate")),
            (
                t("sidewalk:left", "yes") + &t("sidewalk:right", "yes"),
                Some("both"),
            ),
            (
                t("sidewalk:left", "yes") + &t("sidewalk:right", "no"),
                Some("left"),
            ),
            (t("sidewalk:right", "yes"), Some("right")),
            (
                t("sidewalk:left", "no") + &t("sidewalk:right", "separate"),
                Some("separate"),
            ),
            (
                t("sidewalk:left", "no") + &t("sidewalk:right", "no"),
                Some("no"),
            ),
        ];
        let ways: String = cases
            .iter()
            .enumerate()
            .map(|(i, (tags, _))| way(10 + i, tags))
            .collect();
        let xml = format!(
            r#"<osm><node id="1" lat="48.0" lon="11.0"/><node id="2" lat="48.0" lon="11.001"/>{ways}</osm>"#
        );
        let map = OsmMap::from_xml_str(&xml).unwrap();
        assert_eq!(map.highways.len(), cases.len());
        for (h, (tags, expected)) in map.highways.iter().zip(&cases) {
            assert_eq!(h.sidewalk.as_deref(), *expected, "{tags}");
            assert!(!h.is_sidewalk);
        }
        let footway = r#"<way id="9"><nd ref="1"/><nd ref="2"/><tag k="highway" v="footway"/><tag k="footway" v="sidewalk"/></way>"#;
        let map =
            OsmMap::from_xml_str(&xml.replace("</osm>", &format!("{footway}</osm>"))).unwrap();
        assert!(map.highways.iter().any(|h| h.is_sidewalk && h.osm_id == 9));
    }

    #[test]
    fn empty_map_is_an_error() {
        assert!(matches!(
            OsmMap::from_xml_str("<osm></osm>"),
            Err(OsmError::EmptyMap { .. })
        ));
    }
}
