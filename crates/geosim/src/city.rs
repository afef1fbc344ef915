//! A seeded procedural city written as OSM XML: the embedded default map of urbansem.
//!
//! The street network is a jittered grid (irregular quadrilateral blocks) with one primary
//! avenue, one secondary street, a secondary diagonal through grid corners, residential
//! streets with a few removed pieces (larger blocks, T-junctions), service dead ends and
//! footways across blocks. Buildings fill each block behind a setback from every street
//! centre line: rectangles and L-shapes along the block edges, and in some blocks a
//! courtyard building mapped as a `type=multipolygon` relation with an inner ring. Every
//! candidate building is rejected if it comes closer than the setback to any street centre
//! line, leaves its block or overlaps a building already placed.
//!
//! The output is deterministic for a seed (byte-identical), O(B·S) for B building candidates
//! and S street segments.
//!
//! ```
//! use geosim::city::{generate_city, CityOptions};
//! let xml = generate_city(&CityOptions { size_m: 400.0, ..CityOptions::default() }, 7).unwrap();
//! let map = geodata::osm::OsmMap::from_xml_str(&xml).unwrap();
//! assert!(map.buildings.len() > 10);
//! ```

use geodata::osm::geometry::{
    point_in_ring, point_segment_distance, rings_overlap, segments_intersect, signed_area,
};
use geodata::osm::write::xml_tag;
use geodata::osm::{OsmError, OsmMap};
use geodata::projection::{LocalFrame, ProjectionError};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::fmt::Write as _;
use thiserror::Error;

/// Options of the procedural city.
#[derive(Debug, Clone, PartialEq)]
pub struct CityOptions {
    /// Side length of the (square) city in metres.
    pub size_m: f64,
    /// Nominal block pitch (street spacing) in metres.
    pub block_m: f64,
    /// Maximum random displacement of each street corner in metres.
    pub jitter_m: f64,
    /// Fraction of residential street pieces removed (kept connected).
    pub removed_fraction: f64,
    /// Probability that a block gets a service dead end.
    pub dead_end_probability: f64,
    /// Probability that a block gets a footway across it.
    pub footway_probability: f64,
    /// Probability that a block gets a courtyard building (multipolygon).
    pub courtyard_probability: f64,
    /// Latitude of the city centre in degrees.
    pub origin_lat_deg: f64,
    /// Longitude of the city centre in degrees.
    pub origin_lon_deg: f64,
}

impl Default for CityOptions {
    fn default() -> Self {
        CityOptions {
            size_m: 1000.0,
            block_m: 125.0,
            jitter_m: 14.0,
            removed_fraction: 0.08,
            dead_end_probability: 0.2,
            footway_probability: 0.15,
            courtyard_probability: 0.15,
            origin_lat_deg: 48.1372,
            origin_lon_deg: 11.5756,
        }
    }
}

/// Why a city could not be generated or parsed.
#[derive(Debug, Error)]
pub enum CityError {
    /// An option is out of range.
    #[error("invalid city option {name} = {value}: {expected}")]
    InvalidOption {
        /// Option name.
        name: &'static str,
        /// Value given.
        value: f64,
        /// What is allowed.
        expected: &'static str,
    },
    /// The origin is not a valid frame origin.
    #[error(transparent)]
    Frame(#[from] ProjectionError),
    /// The generated XML did not parse (a bug in the generator).
    #[error("generated city does not parse: {0}")]
    Parse(#[from] OsmError),
}

/// What the generator wrote, to check a parse against.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CityStats {
    /// Nodes written.
    pub nodes: usize,
    /// Ways tagged `highway=*`.
    pub highway_ways: usize,
    /// Street segments (consecutive node pairs of highway ways).
    pub segments: usize,
    /// Closed building ways.
    pub building_ways: usize,
    /// Building multipolygon relations (courtyards).
    pub building_relations: usize,
}

const STREET_NAMES: [&str; 12] = [
    "Linden",
    "Ahorn",
    "Birken",
    "Eichen",
    "Kastanien",
    "Ulmen",
    "Erlen",
    "Buchen",
    "Tannen",
    "Eschen",
    "Pappel",
    "Weiden",
];

type Tags = Vec<(&'static str, String)>;

struct Way {
    nodes: Vec<usize>,
    tags: Tags,
}

struct Builder {
    points: Vec<[f64; 2]>,
    ways: Vec<Way>,
    /// Courtyard relations: outer way index, inner way index, tags.
    relations: Vec<(usize, usize, Tags)>,
    street_segments: Vec<([f64; 2], [f64; 2], f64)>,
}

impl Builder {
    fn node(&mut self, p: [f64; 2]) -> usize {
        self.points.push(p);
        self.points.len() - 1
    }
}

fn check_options(o: &CityOptions) -> Result<(), CityError> {
    let positive = [("size_m", o.size_m), ("block_m", o.block_m)];
    for (name, value) in positive {
        if !(value.is_finite() && value > 0.0) {
            return Err(CityError::InvalidOption {
                name,
                value,
                expected: "a positive number of metres",
            });
        }
    }
    if o.block_m < 60.0 || o.size_m < o.block_m {
        return Err(CityError::InvalidOption {
            name: "block_m",
            value: o.block_m,
            expected: "≥ 60 m and ≤ size_m",
        });
    }
    if !(o.jitter_m >= 0.0 && o.jitter_m <= 0.15 * o.block_m) {
        return Err(CityError::InvalidOption {
            name: "jitter_m",
            value: o.jitter_m,
            expected: "between 0 and 0.15·block_m",
        });
    }
    let probabilities = [
        ("removed_fraction", o.removed_fraction),
        ("dead_end_probability", o.dead_end_probability),
        ("footway_probability", o.footway_probability),
        ("courtyard_probability", o.courtyard_probability),
    ];
    for (name, value) in probabilities {
        if !(0.0..=1.0).contains(&value) {
            return Err(CityError::InvalidOption {
                name,
                value,
                expected: "a probability in [0, 1]",
            });
        }
    }
    Ok(())
}

fn find(parent: &mut [usize], mut x: usize) -> usize {
    while parent[x] != x {
        parent[x] = parent[parent[x]];
        x = parent[x];
    }
    x
}

fn connected(n: usize, edges: &[(usize, usize)]) -> bool {
    let mut parent: Vec<usize> = (0..n).collect();
    for &(a, b) in edges {
        let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
        parent[ra] = rb;
    }
    let root = find(&mut parent, 0);
    (0..n).all(|v| find(&mut parent, v) == root)
}

fn lerp(a: [f64; 2], b: [f64; 2], t: f64) -> [f64; 2] {
    [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
}

/// Half of the carriageway width assumed for each highway type (setbacks are measured from it).
fn half_width_m(highway: &str) -> f64 {
    match highway {
        "primary" => 9.0,
        "secondary" => 7.0,
        "residential" => 5.0,
        "service" => 3.5,
        _ => 2.0,
    }
}

/// Generates a city and returns its OSM XML.
pub fn generate_city(options: &CityOptions, seed: u64) -> Result<String, CityError> {
    generate_city_with_stats(options, seed).map(|(xml, _)| xml)
}

/// Generates a city and returns its OSM XML with the counts of what was written.
pub fn generate_city_with_stats(
    options: &CityOptions,
    seed: u64,
) -> Result<(String, CityStats), CityError> {
    check_options(options)?;
    let frame = LocalFrame::new(options.origin_lat_deg, options.origin_lon_deg)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let cells = (options.size_m / options.block_m).round().max(1.0) as usize;
    let pitch = options.size_m / cells as f64;
    let n = cells + 1;
    let half = 0.5 * options.size_m;
    let mut b = Builder {
        points: Vec::new(),
        ways: Vec::new(),
        relations: Vec::new(),
        street_segments: Vec::new(),
    };

    // 1. Jittered grid corners; corner (i, j) is node i + j·n.
    for j in 0..n {
        for i in 0..n {
            let mut jitter = |on_border: bool| {
                if on_border {
                    0.0
                } else {
                    rng.gen_range(-options.jitter_m..=options.jitter_m)
                }
            };
            let dx = jitter(i == 0 || i == cells);
            let dy = jitter(j == 0 || j == cells);
            b.node([-half + i as f64 * pitch + dx, -half + j as f64 * pitch + dy]);
        }
    }
    let corner = |i: usize, j: usize| i + j * n;
    let primary_row = n / 2;
    let secondary_col = n / 3;
    // Grid edges: (from, to, highway, is_row, line index, position along line).
    let mut edges: Vec<(usize, usize, &'static str, bool, usize, usize)> = Vec::new();
    for j in 0..n {
        for i in 0..cells {
            let kind = if j == primary_row {
                "primary"
            } else {
                "residential"
            };
            edges.push((corner(i, j), corner(i + 1, j), kind, true, j, i));
        }
    }
    for i in 0..n {
        for j in 0..cells {
            let kind = if i == secondary_col {
                "secondary"
            } else {
                "residential"
            };
            edges.push((corner(i, j), corner(i, j + 1), kind, false, i, j));
        }
    }
    // The diagonal avenue runs through corners (k, k) and shares them with the grid.
    let diagonal: Vec<(usize, usize)> = (0..cells)
        .map(|k| (corner(k, k), corner(k + 1, k + 1)))
        .collect();
    // 2. Remove some residential pieces while the network stays connected.
    let mut present = vec![true; edges.len()];
    for e in 0..edges.len() {
        let (_, _, kind, ..) = edges[e];
        if kind != "residential" || !rng.gen_bool(options.removed_fraction) {
            continue;
        }
        present[e] = false;
        let kept: Vec<(usize, usize)> = edges
            .iter()
            .zip(&present)
            .filter(|(_, &p)| p)
            .map(|(e, _)| (e.0, e.1))
            .chain(diagonal.iter().copied())
            .collect();
        if !connected(n * n, &kept) {
            present[e] = true;
        }
    }
    let edge_index = |is_row: bool, line: usize, pos: usize| -> usize {
        if is_row {
            line * cells + pos
        } else {
            n * cells + line * cells + pos
        }
    };
    // 3. Per-block features: a dead end from the bottom edge, or a footway left to right.
    let mut midpoints: Vec<Option<usize>> = vec![None; edges.len()];
    let mut extra_ways: Vec<(Vec<usize>, &'static str)> = Vec::new();
    let mut courtyard_cells = Vec::new();
    for j in 0..cells {
        for i in 0..cells {
            let on_diagonal = i == j;
            let roll: f64 = rng.gen();
            let bottom = edge_index(true, j, i);
            let (left, right) = (edge_index(false, i, j), edge_index(false, i + 1, j));
            if roll < options.dead_end_probability && present[bottom] {
                let (p, q) = (b.points[edges[bottom].0], b.points[edges[bottom].1]);
                let mid = lerp(p, q, 0.5);
                let m = *midpoints[bottom].get_or_insert_with(|| b.node(mid));
                let top_mid = lerp(
                    b.points[corner(i, j + 1)],
                    b.points[corner(i + 1, j + 1)],
                    0.5,
                );
                let depth = if on_diagonal {
                    0.2
                } else {
                    rng.gen_range(0.3..0.42)
                };
                let end = b.node(lerp(mid, top_mid, depth));
                extra_ways.push((vec![m, end], "service"));
            } else if roll < options.dead_end_probability + options.footway_probability
                && !on_diagonal
                && present[left]
                && present[right]
            {
                let mut ends = [0usize; 2];
                for (slot, e) in ends.iter_mut().zip([left, right]) {
                    let mid = lerp(b.points[edges[e].0], b.points[edges[e].1], 0.5);
                    *slot = *midpoints[e].get_or_insert_with(|| b.node(mid));
                }
                extra_ways.push((ends.to_vec(), "footway"));
            } else if rng.gen_bool(options.courtyard_probability) && !on_diagonal {
                courtyard_cells.push((i, j));
            }
        }
    }
    // 4. Street ways: each grid line becomes one way per run of present pieces.
    let name_of_line = |is_row: bool, line: usize| -> String {
        let base = STREET_NAMES[line % STREET_NAMES.len()];
        if is_row {
            format!("{base}straße")
        } else {
            format!("{base}weg")
        }
    };
    let mut runs: Vec<(Vec<usize>, &'static str, String)> = Vec::new();
    for is_row in [true, false] {
        for line in 0..n {
            let mut current: Vec<usize> = Vec::new();
            let mut kind = "residential";
            for pos in 0..=cells {
                let e = if pos < cells {
                    Some(edge_index(is_row, line, pos))
                } else {
                    None
                };
                match e.filter(|&e| present[e]) {
                    Some(e) => {
                        let (from, to, k, ..) = edges[e];
                        kind = k;
                        if current.is_empty() {
                            current.push(from);
                        }
                        if let Some(m) = midpoints[e] {
                            current.push(m);
                        }
                        current.push(to);
                    }
                    None => {
                        if current.len() >= 2 {
                            runs.push((
                                std::mem::take(&mut current),
                                kind,
                                name_of_line(is_row, line),
                            ));
                        }
                        current.clear();
                    }
                }
            }
        }
    }
    let diagonal_nodes: Vec<usize> = (0..n).map(|k| corner(k, k)).collect();
    runs.push((diagonal_nodes, "secondary", "Diagonale".to_string()));
    for (nodes, kind, name) in runs {
        let mut tags = vec![("highway", kind.to_string()), ("name", name)];
        match kind {
            "primary" => {
                tags.push(("lanes", "4".into()));
                tags.push(("width", "18".into()));
                tags.push(("sidewalk", "both".into()));
            }
            "secondary" => {
                tags.push(("lanes", "2".into()));
                tags.push(("width", "14".into()));
            }
            _ if rng.gen_bool(0.3) => tags.push(("lanes", "2".into())),
            _ => {}
        }
        b.ways.push(Way { nodes, tags });
    }
    for (nodes, kind) in extra_ways {
        b.ways.push(Way {
            nodes,
            tags: vec![("highway", kind.to_string())],
        });
    }
    for w in &b.ways {
        let kind = w.tags.first().map_or("", |t| t.1.as_str());
        for pair in w.nodes.windows(2) {
            if let [p, q] = pair {
                b.street_segments
                    .push((b.points[*p], b.points[*q], half_width_m(kind)));
            }
        }
    }
    let highway_ways = b.ways.len();
    let segments = b.street_segments.len();

    // 5. Buildings, block by block.
    let mut building_ways = 0;
    let mut building_relations = 0;
    for j in 0..cells {
        for i in 0..cells {
            let block = [
                corner(i, j),
                corner(i + 1, j),
                corner(i + 1, j + 1),
                corner(i, j + 1),
            ]
            .map(|c| b.points[c]);
            let mut placed: Vec<Vec<[f64; 2]>> = Vec::new();
            if courtyard_cells.contains(&(i, j)) {
                let c = lerp(
                    lerp(block[0], block[2], 0.5),
                    lerp(block[1], block[3], 0.5),
                    0.5,
                );
                let (hx, hy) = (rng.gen_range(28.0..36.0), rng.gen_range(26.0..34.0));
                let outer = vec![
                    [c[0] - hx, c[1] - hy],
                    [c[0] + hx, c[1] - hy],
                    [c[0] + hx, c[1] + hy],
                    [c[0] - hx, c[1] + hy],
                ];
                let (ix, iy) = (hx - 11.0, hy - 11.0);
                let inner = vec![
                    [c[0] - ix, c[1] - iy],
                    [c[0] - ix, c[1] + iy],
                    [c[0] + ix, c[1] + iy],
                    [c[0] + ix, c[1] - iy],
                ];
                if acceptable(&outer, &block, &b.street_segments, &placed) {
                    let close = |ring: &[[f64; 2]], b: &mut Builder| -> usize {
                        let mut ids: Vec<usize> = ring.iter().map(|&p| b.node(p)).collect();
                        ids.push(ids[0]);
                        b.ways.push(Way {
                            nodes: ids,
                            tags: Vec::new(),
                        });
                        b.ways.len() - 1
                    };
                    let ow = close(&outer, &mut b);
                    let iw = close(&inner, &mut b);
                    let levels = rng.gen_range(4..8u32);
                    b.relations.push((
                        ow,
                        iw,
                        vec![
                            ("type", "multipolygon".into()),
                            ("building", "apartments".into()),
                            ("building:levels", levels.to_string()),
                        ],
                    ));
                    building_relations += 1;
                    placed.push(outer);
                }
            }
            for k in 0..4 {
                let (p, q) = (block[k], block[(k + 1) % 4]);
                let len = ((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2)).sqrt();
                let u = [(q[0] - p[0]) / len, (q[1] - p[1]) / len];
                let v = [-u[1], u[0]];
                let mut t = 12.0 + rng.gen_range(0.0..4.0);
                while t < len - 22.0 {
                    let width = rng.gen_range(10.0..22.0_f64).min(len - 12.0 - t);
                    let depth = rng.gen_range(9.0..16.0);
                    let setback = 12.0 + rng.gen_range(0.0..4.0);
                    let at = |along: f64, inward: f64| {
                        [
                            p[0] + u[0] * along + v[0] * inward,
                            p[1] + u[1] * along + v[1] * inward,
                        ]
                    };
                    let ring = if rng.gen_bool(0.2) && width > 14.0 {
                        let wing = depth + rng.gen_range(6.0..12.0);
                        let wing_w = 0.45 * width;
                        vec![
                            at(t, setback),
                            at(t + width, setback),
                            at(t + width, setback + depth),
                            at(t + wing_w, setback + depth),
                            at(t + wing_w, setback + wing),
                            at(t, setback + wing),
                        ]
                    } else {
                        vec![
                            at(t, setback),
                            at(t + width, setback),
                            at(t + width, setback + depth),
                            at(t, setback + depth),
                        ]
                    };
                    if width >= 8.0 && acceptable(&ring, &block, &b.street_segments, &placed) {
                        let mut ids: Vec<usize> = ring.iter().map(|&p| b.node(p)).collect();
                        ids.push(ids[0]);
                        let kind =
                            ["yes", "residential", "apartments", "commercial"][rng.gen_range(0..4)];
                        let mut tags = vec![("building", kind.to_string())];
                        match rng.gen_range(0..3) {
                            0 => tags.push(("height", format!("{:.1}", rng.gen_range(6.0..24.0)))),
                            1 => tags.push(("building:levels", rng.gen_range(2..7u32).to_string())),
                            _ => {}
                        }
                        b.ways.push(Way { nodes: ids, tags });
                        building_ways += 1;
                        placed.push(ring);
                    }
                    t += width + rng.gen_range(0.0..5.0);
                }
            }
        }
    }
    let stats = CityStats {
        nodes: b.points.len(),
        highway_ways,
        segments,
        building_ways,
        building_relations,
    };
    Ok((write_xml(&b, &frame, half), stats))
}

/// Whether a building ring stays in its block, keeps the setback from every street and overlaps nothing placed.
fn acceptable(
    ring: &[[f64; 2]],
    block: &[[f64; 2]; 4],
    streets: &[([f64; 2], [f64; 2], f64)],
    placed: &[Vec<[f64; 2]>],
) -> bool {
    if signed_area(ring) <= 0.0 || !ring.iter().all(|&p| point_in_ring(p, block)) {
        return false;
    }
    let m = ring.len();
    for &(a, b, half_width) in streets {
        let clearance = half_width + 2.0;
        if ring
            .iter()
            .any(|&p| point_segment_distance(p, a, b) < clearance)
        {
            return false;
        }
        if (0..m).any(|i| segments_intersect(ring[i], ring[(i + 1) % m], a, b)) {
            return false;
        }
        if point_segment_distance(a, ring[0], ring[1 % m]) < clearance && point_in_ring(a, ring) {
            return false;
        }
    }
    !placed.iter().any(|other| rings_overlap(ring, other))
}

fn write_xml(b: &Builder, frame: &LocalFrame, half: f64) -> String {
    let mut xml = String::with_capacity(64 * b.points.len() + 4096);
    let (min_lat, min_lon) = frame.to_wgs84([-half - 20.0, -half - 20.0]);
    let (max_lat, max_lon) = frame.to_wgs84([half + 20.0, half + 20.0]);
    xml.push_str("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<osm version=\"0.6\" generator=\"urbansem sim city\">\n");
    let _ = writeln!(xml, "  <bounds minlat=\"{min_lat:.7}\" minlon=\"{min_lon:.7}\" maxlat=\"{max_lat:.7}\" maxlon=\"{max_lon:.7}\"/>");
    for (k, &p) in b.points.iter().enumerate() {
        let (lat, lon) = frame.to_wgs84(p);
        let _ = writeln!(
            xml,
            "  <node id=\"{}\" lat=\"{lat:.7}\" lon=\"{lon:.7}\" version=\"1\"/>",
            k + 1
        );
    }
    for (k, w) in b.ways.iter().enumerate() {
        let _ = writeln!(xml, "  <way id=\"{}\" version=\"1\">", k + 1);
        for &node in &w.nodes {
            let _ = writeln!(xml, "    <nd ref=\"{}\"/>", node + 1);
        }
        for (key, value) in &w.tags {
            xml_tag(&mut xml, key, value);
        }
        xml.push_str("  </way>\n");
    }
    for (k, (outer, inner, tags)) in b.relations.iter().enumerate() {
        let _ = writeln!(xml, "  <relation id=\"{}\" version=\"1\">", k + 1);
        let _ = writeln!(
            xml,
            "    <member type=\"way\" ref=\"{}\" role=\"outer\"/>",
            outer + 1
        );
        let _ = writeln!(
            xml,
            "    <member type=\"way\" ref=\"{}\" role=\"inner\"/>",
            inner + 1
        );
        for (key, value) in tags {
            xml_tag(&mut xml, key, value);
        }
        xml.push_str("  </relation>\n");
    }
    xml.push_str("</osm>\n");
    xml
}

/// The embedded default map: [`CityOptions::default`] with seed 1, parsed.
pub fn default_city_map() -> Result<OsmMap, CityError> {
    let xml = generate_city(&CityOptions::default(), 1)?;
    Ok(OsmMap::from_xml_str(&xml)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use geodata::osm::geometry::segments_intersect;
    use geodata::osm::write::xml_attribute;

    #[test]
    fn same_seed_same_bytes_other_seed_other_city() {
        let o = CityOptions {
            size_m: 500.0,
            ..CityOptions::default()
        };
        assert_eq!(generate_city(&o, 3).unwrap(), generate_city(&o, 3).unwrap());
        assert_ne!(generate_city(&o, 3).unwrap(), generate_city(&o, 4).unwrap());
    }

    #[test]
    fn default_city_parses_back_with_the_generated_counts() {
        let (xml, stats) = generate_city_with_stats(&CityOptions::default(), 1).unwrap();
        let map = OsmMap::from_xml_str(&xml).unwrap();
        assert_eq!(map.stats.nodes, stats.nodes);
        assert_eq!(map.stats.highway_ways, stats.highway_ways);
        assert_eq!(map.streets.segments.len(), stats.segments);
        assert_eq!(map.stats.building_ways, stats.building_ways);
        assert_eq!(map.stats.building_relations, stats.building_relations);
        assert_eq!(
            map.buildings.len(),
            stats.building_ways + stats.building_relations
        );
        assert!(stats.building_ways > 300, "{stats:?}");
        assert!(stats.building_relations > 0, "{stats:?}");
        assert!(map.buildings.iter().any(|b| !b.inners.is_empty()));
        let kinds: std::collections::BTreeSet<&str> =
            map.highways.iter().map(|h| h.highway.as_str()).collect();
        for k in ["primary", "secondary", "residential", "service", "footway"] {
            assert!(kinds.contains(k), "{k} missing from {kinds:?}");
        }
        let extent = map
            .buildings
            .iter()
            .flat_map(|b| b.outer.iter())
            .fold(0.0_f64, |m, p| m.max(p[0].abs()).max(p[1].abs()));
        assert!(extent < 520.0, "{extent}");
    }

    #[test]
    fn no_building_crosses_a_street_centre_line_and_the_graph_is_connected() {
        for seed in [1, 2, 3] {
            let map = if seed == 1 {
                default_city_map().unwrap()
            } else {
                OsmMap::from_xml_str(&generate_city(&CityOptions::default(), seed).unwrap())
                    .unwrap()
            };
            assert_eq!(map.streets.components().1, 1, "seed {seed}");
            for bld in &map.buildings {
                let m = bld.outer.len();
                for s in &map.streets.segments {
                    for i in 0..m {
                        assert!(
                            !segments_intersect(bld.outer[i], bld.outer[(i + 1) % m], s.a, s.b),
                            "seed {seed} building {}",
                            bld.osm_id
                        );
                    }
                    assert!(
                        !point_in_ring(s.a, &bld.outer),
                        "seed {seed} building {}",
                        bld.osm_id
                    );
                }
            }
        }
    }

    /// Every `<tag>` of an OSM XML text as quick-xml reads it back (unescaped).
    fn tags_read_back(xml: &str) -> Vec<(String, String)> {
        let mut reader = quick_xml::Reader::from_str(xml);
        let mut tags = Vec::new();
        loop {
            match reader.read_event().unwrap() {
                quick_xml::events::Event::Empty(e) if e.name().as_ref() == b"tag" => {
                    let value = |key: &[u8]| {
                        let attr = e.try_get_attribute(key).unwrap().unwrap();
                        attr.unescape_value().unwrap().into_owned()
                    };
                    tags.push((value(b"k"), value(b"v")));
                }
                quick_xml::events::Event::Eof => return tags,
                _ => {}
            }
        }
    }

    /// Issue 16: the writer put tag keys and values into attributes unescaped, so a `"`,
    /// `&` or `<` in a name gave a file no XML reader accepts.
    #[test]
    fn nasty_tag_values_round_trip_through_writer_and_reader() {
        let nasty = [
            "a \"quoted\" & 'single' <tag/> > end",
            "line one\nline two\r\n\ttabbed  &amp; already escaped",
            "unicode: Straße, 東京, Ελλάδα, 🚲",
            "",
        ];
        let frame = LocalFrame::new(48.0, 11.0).unwrap();
        let square = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]];
        let mut ways = Vec::new();
        for (k, value) in nasty.iter().enumerate() {
            let first = 4 * k;
            ways.push(Way {
                nodes: vec![first, first + 1, first + 2, first + 3, first],
                tags: vec![
                    ("building", value.to_string()),
                    ("name", value.to_string()),
                    ("k&<\"'>", value.to_string()),
                ],
            });
        }
        ways.push(Way {
            nodes: vec![0, 2],
            tags: vec![
                ("highway", nasty[0].to_string()),
                ("name", nasty[1].to_string()),
            ],
        });
        let points = (0..nasty.len())
            .flat_map(|k| square.iter().map(move |p| [p[0] + 20.0 * k as f64, p[1]]))
            .collect();
        let b = Builder {
            points,
            ways,
            relations: vec![(
                0,
                1,
                vec![("name", "control \u{1} and \u{FFFF}".to_string())],
            )],
            street_segments: Vec::new(),
        };
        let xml = write_xml(&b, &frame, 100.0);
        // Every key and value, exactly (the characters XML cannot hold become U+FFFD).
        let expected: Vec<(String, String)> = b
            .ways
            .iter()
            .flat_map(|w| w.tags.iter())
            .chain(b.relations.iter().flat_map(|r| r.2.iter()))
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .map(|(k, v)| (k, v.replace(['\u{1}', '\u{FFFF}'], "\u{FFFD}")))
            .collect();
        assert_eq!(tags_read_back(&xml), expected);
        // And through urbansem's own reader.
        let map = OsmMap::from_xml_str(&xml).unwrap();
        let names: Vec<&str> = map
            .buildings
            .iter()
            .filter_map(|b| b.name.as_deref())
            .collect();
        let values: Vec<&str> = map.buildings.iter().map(|b| b.building.as_str()).collect();
        assert_eq!(names, nasty.to_vec());
        assert_eq!(values, nasty.to_vec());
        assert_eq!(map.highways[0].highway, nasty[0]);
        assert_eq!(map.highways[0].name.as_deref(), Some(nasty[1]));
        // Plain text is not touched (the generated city stays byte for byte the same).
        assert!(matches!(
            xml_attribute("Lindenstraße 12"),
            std::borrow::Cow::Borrowed(_)
        ));
    }

    #[test]
    fn bad_options_are_rejected() {
        let bad = CityOptions {
            size_m: -1.0,
            ..CityOptions::default()
        };
        assert!(matches!(
            generate_city(&bad, 1),
            Err(CityError::InvalidOption { name: "size_m", .. })
        ));
        let bad = CityOptions {
            removed_fraction: 2.0,
            ..CityOptions::default()
        };
        assert!(matches!(
            generate_city(&bad, 1),
            Err(CityError::InvalidOption { .. })
        ));
    }
}
