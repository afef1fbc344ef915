//! A building map drawn from the labelled scans of a real sequence: the façades its scans
//! saw, as building outlines, beside the streets of an OSM map.
//!
//! Real car scans need a map of the place to be localized on. Where the OSM buildings of a
//! recorded drive are not at hand (the shared KITTI-360 drive comes with its streets only),
//! the drive's own building-labelled points give one: every scan is registered by its
//! dataset pose into one local frame, its building points within `max_range_m` of the sensor
//! are counted in `cell_m` cells of the ground plane, cells with at least `min_points` are
//! occupied, a closing (dilate, then erode by one cell) joins the gaps between scan lines, and
//! each 4-connected group of at least `min_cells` occupied cells becomes one building: the
//! outer boundary of its cells (holes filled), simplified by Douglas–Peucker within
//! `simplify_m` (halved until the ring stays simple). Scans can be held out
//! (`hold_out`: every n-th from an offset), so the scans that are localized are not those
//! the map was drawn from.
//!
//! What such a map is and is not: its outlines are the walls that other scans of the same
//! drive saw, one to a few cells thick, with the labels' errors; walls no scan saw are
//! missing, as buildings are missing from OSM; it holds no backyards, so the search area is
//! the drive's corridor unless distractors are added. It measures the sensor's side of
//! localization (walls from a roof-mounted scanner against a map of the right walls), not
//! OSM's mapping error.
//!
//! Cost: linear in the points read and in the occupied cells (held in a hash set, not a
//! dense grid over their bounding box, so a drive of any length fits in memory).

use crate::{LocalizeError, Result, WithContext};
use geodata::classes::Class;
use geodata::datasets::LidarSequence;
use geodata::osm::geometry::segments_intersect;
use geodata::osm::model::{Building, OsmMap, OsmStats, StreetNetwork};
use geodata::projection::LocalFrame;
use rustc_hash::{FxHashMap, FxHashSet};
use serde::Serialize;
use std::path::Path;

/// How the façade map is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FacadeMapOptions {
    /// Cell side, metres.
    pub cell_m: f64,
    /// Building points a cell needs to be occupied.
    pub min_points: u32,
    /// Points farther than this from their scan's sensor are not used, metres.
    pub max_range_m: f64,
    /// Occupied cells a building needs.
    pub min_cells: usize,
    /// Douglas–Peucker tolerance of the outlines, metres.
    pub simplify_m: f64,
    /// Depth given to the buildings behind the walls seen, metres: each occupied cell is
    /// extended this far away from the mean position of the sensors that saw it (0: the walls
    /// as seen, one to a few cells thick).
    pub depth_m: f64,
    /// Scans not used: those whose position in the sequence's frame order is `offset`
    /// modulo `every` (`(every, offset)`).
    pub hold_out: Option<(usize, usize)>,
}

impl Default for FacadeMapOptions {
    fn default() -> Self {
        FacadeMapOptions {
            cell_m: 0.5,
            min_points: 2,
            max_range_m: 50.0,
            min_cells: 8,
            simplify_m: 0.25,
            depth_m: 0.0,
            hold_out: None,
        }
    }
}

/// What went into a façade map.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct FacadeMapSummary {
    /// Frame numbers of the scans drawn from.
    pub frames_used: Vec<u64>,
    /// Frame numbers of the scans held out.
    pub frames_held_out: Vec<u64>,
    /// Building-labelled points counted.
    pub building_points: usize,
    /// Occupied cells after the closing.
    pub cells: usize,
    /// Buildings (outlines) written.
    pub buildings: usize,
    /// Outline vertices in total.
    pub vertices: usize,
    /// Groups of occupied cells dropped as smaller than `min_cells`.
    pub dropped_small: usize,
    /// Street segments taken from the roads map.
    pub street_segments: usize,
    /// Buildings the OSM reader finds in the written file (equal to `buildings` unless an
    /// outline was invalid).
    pub buildings_read_back: usize,
}

fn invalid(name: &'static str, value: f64, expected: &'static str) -> LocalizeError {
    LocalizeError::InvalidOption {
        name,
        value,
        expected,
    }
}

fn check(options: &FacadeMapOptions) -> Result<()> {
    if !(options.cell_m.is_finite() && options.cell_m >= 0.05 && options.cell_m <= 10.0) {
        return Err(invalid("cell_m", options.cell_m, "0.05 … 10 m"));
    }
    if !(options.max_range_m.is_finite() && options.max_range_m > 0.0) {
        return Err(invalid(
            "max_range_m",
            options.max_range_m,
            "a positive length",
        ));
    }
    if !(options.depth_m.is_finite() && (0.0..=100.0).contains(&options.depth_m)) {
        return Err(invalid("depth_m", options.depth_m, "0 … 100 m"));
    }
    if !(options.simplify_m.is_finite() && options.simplify_m >= 0.0) {
        return Err(invalid("simplify_m", options.simplify_m, "≥ 0 m"));
    }
    check_every_nth("hold_out", options.hold_out)
}

/// An error unless a selection of every n-th scan (`(every, offset)`, `name` in the error)
/// has every ≥ 1 and an offset below it.
pub fn check_every_nth(name: &'static str, select: Option<(usize, usize)>) -> Result<()> {
    match select {
        Some((every, offset)) if every == 0 || offset >= every => Err(invalid(
            name,
            every as f64,
            "every ≥ 1 and an offset below it",
        )),
        _ => Ok(()),
    }
}

/// Whether scan `i` (position in frame order) is one of every n-th from an offset
/// (`(every, offset)`; none without a selection): held out of a façade map, or evaluated.
pub fn held_out(select: Option<(usize, usize)>, i: usize) -> bool {
    select.is_some_and(|(every, offset)| every > 0 && i % every == offset)
}

/// The façade map of a labelled sequence, beside the streets of `roads` and in its frame
/// (without roads: a frame at the first scan), and what went into it.
pub fn facade_map(
    seq: &dyn LidarSequence,
    roads: Option<&OsmMap>,
    options: &FacadeMapOptions,
) -> Result<(OsmMap, FacadeMapSummary)> {
    check(options)?;
    let dir = seq.dir().to_path_buf();
    if !seq.labelled() {
        return Err(LocalizeError::Dataset {
            path: dir,
            message: "the sequence has no per-point labels (gt_labels/), so no building points to draw a map from".into(),
        });
    }
    let frames = seq.frames()?;
    let mut summary = FacadeMapSummary::default();
    let mut frame: Option<LocalFrame> = roads.map(|r| r.frame);
    let mut counts: FxHashMap<(i64, i64), CellViews> = Default::default();
    let inv = 1.0 / options.cell_m;
    for (i, &f) in frames.iter().enumerate() {
        if held_out(options.hold_out, i) {
            summary.frames_held_out.push(f);
            continue;
        }
        let scan = seq.load_scan(f)?;
        let Some(labels) = scan.cloud.label.as_ref() else {
            return Err(LocalizeError::Dataset {
                path: scan.path.clone(),
                message: "this scan has no label file, and a façade map needs every scan used to be labelled (hold it out)".into(),
            });
        };
        let local = match frame {
            Some(fr) => fr,
            None => {
                let (lat, lon) = scan.sensor_wgs84();
                let fr = LocalFrame::new(lat, lon).map_err(|e| LocalizeError::Dataset {
                    path: scan.path.clone(),
                    message: format!("its pose gives no local frame: {e}"),
                })?;
                frame = Some(fr);
                fr
            }
        };
        let iso = scan.local_from_sensor(&local);
        let sensor = iso.translation.vector;
        let r2 = options.max_range_m * options.max_range_m;
        for (p, &l) in scan.cloud.positions.iter().zip(labels) {
            let within = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]) <= r2;
            if l != Class::Building as u8 || !within {
                continue;
            }
            let q = iso * nalgebra::Point3::new(p[0], p[1], p[2]);
            if !(q.x.is_finite() && q.y.is_finite()) {
                continue;
            }
            let key = ((q.x * inv).floor() as i64, (q.y * inv).floor() as i64);
            let c = counts.entry(key).or_insert((0, 0.0, 0.0));
            *c = (c.0 + 1, c.1 + sensor.x, c.2 + sensor.y);
            summary.building_points += 1;
        }
        summary.frames_used.push(f);
    }
    let Some(frame) = frame else {
        return Err(LocalizeError::Dataset {
            path: dir,
            message: "no scans left to draw the map from (all held out, or none in the folder)"
                .into(),
        });
    };
    let mut seen: Vec<((i64, i64), CellViews)> = counts
        .into_iter()
        .filter(|(_, c)| c.0 >= options.min_points)
        .collect();
    seen.sort_unstable_by_key(|&(k, _)| k);
    let mut occupied: Vec<(i64, i64)> = seen.iter().map(|&(k, _)| k).collect();
    if options.depth_m > 0.0 {
        // Each cell extended away from its mean viewpoint, in half-cell steps.
        let steps = (2.0 * options.depth_m / options.cell_m).ceil() as usize;
        for &((x, y), (n, sx, sy)) in &seen {
            let centre = [
                (x as f64 + 0.5) * options.cell_m,
                (y as f64 + 0.5) * options.cell_m,
            ];
            let (dx, dy) = (centre[0] - sx / n as f64, centre[1] - sy / n as f64);
            let len = dx.hypot(dy);
            if len < 1e-6 {
                continue;
            }
            let (ux, uy) = (dx / len, dy / len);
            for k in 1..=steps {
                let t = k as f64 * 0.5 * options.cell_m;
                occupied.push((
                    ((centre[0] + ux * t) * inv).floor() as i64,
                    ((centre[1] + uy * t) * inv).floor() as i64,
                ));
            }
        }
        occupied.sort_unstable();
        occupied.dedup();
    }
    let mut buildings = Vec::new();
    if !occupied.is_empty() {
        let grid = Grid::closed(&occupied);
        summary.cells = grid.order.len();
        for component in grid.components() {
            if component.len() < options.min_cells {
                summary.dropped_small += 1;
                continue;
            }
            let Some(ring) = grid.outer_ring(&component) else {
                continue;
            };
            let ring: Vec<[f64; 2]> = ring
                .iter()
                .map(|&(x, y)| [x as f64 * options.cell_m, y as f64 * options.cell_m])
                .collect();
            let ring = simplify_ring(&ring, options.simplify_m);
            summary.vertices += ring.len();
            buildings.push(Building::outline(
                buildings.len() as i64 + 1,
                ring,
                Vec::new(),
            ));
        }
    }
    summary.buildings = buildings.len();
    let (highways, streets, stats) = match roads {
        Some(r) => (r.highways.clone(), r.streets.clone(), r.stats.clone()),
        None => (Vec::new(), StreetNetwork::default(), OsmStats::default()),
    };
    summary.street_segments = streets.segments.len();
    let mut map = OsmMap {
        frame,
        bbox_lonlat: [0.0; 4],
        buildings,
        highways,
        streets,
        stats,
    };
    map.bbox_lonlat = lonlat_box(&map).unwrap_or([0.0; 4]);
    Ok((map, summary))
}

/// Per cell: building points, and the sums of the x and y of the sensors that saw them.
type CellViews = (u32, f64, f64);

/// Draws the façade map of the real sequence in `dataset` beside the streets of the OSM map
/// `roads` (in its frame), writes it to `out` as OSM XML, and reads it back to check that
/// every outline survives the reader (`buildings_read_back`).
pub fn write_facade_map(
    dataset: &Path,
    roads: Option<&Path>,
    out: &Path,
    options: &FacadeMapOptions,
) -> Result<FacadeMapSummary> {
    let seq = geodata::datasets::open_sequence(dataset)?;
    let roads_map = match roads {
        Some(p) => Some(
            OsmMap::load(p).context_with(|| format!("loading the roads map {}", p.display()))?,
        ),
        None => None,
    };
    let (map, mut summary) = facade_map(seq.as_ref(), roads_map.as_ref(), options)?;
    let xml = geodata::osm::write::to_xml(&map, "urbansem localize facade-map");
    geodata::fsio::write_atomic(out, xml.as_bytes()).map_err(|source| LocalizeError::Io {
        action: "writing",
        path: out.to_path_buf(),
        source,
    })?;
    let back = OsmMap::load(out).context_with(|| format!("reading back {}", out.display()))?;
    summary.buildings_read_back = back.buildings.len();
    Ok(summary)
}

/// `[min_lon, min_lat, max_lon, max_lat]` of a map's building and street vertices.
fn lonlat_box(map: &OsmMap) -> Option<[f64; 4]> {
    let mut out: Option<[f64; 4]> = None;
    let points = map
        .buildings
        .iter()
        .flat_map(|b| b.outer.iter().copied())
        .chain(map.highways.iter().flat_map(|h| h.points.iter().copied()));
    for p in points {
        let (lat, lon) = map.frame.to_wgs84(p);
        let b = out.get_or_insert([lon, lat, lon, lat]);
        *b = [b[0].min(lon), b[1].min(lat), b[2].max(lon), b[3].max(lat)];
    }
    out
}

/// Occupied cells, held sparsely: memory and time grow with the occupied cells, not with
/// their bounding box (a long drive's box would not fit in memory).
struct Grid {
    cells: FxHashSet<(i64, i64)>,
    /// The occupied cells in scan order (row by row, then by column).
    order: Vec<(i64, i64)>,
}

impl Grid {
    /// The cells, closed (dilated, then eroded, by one cell in the 8-neighbourhood).
    fn closed(occupied: &[(i64, i64)]) -> Grid {
        const AROUND: [(i64, i64); 9] = [
            (-1, -1),
            (0, -1),
            (1, -1),
            (-1, 0),
            (0, 0),
            (1, 0),
            (-1, 1),
            (0, 1),
            (1, 1),
        ];
        let mut dilated: FxHashSet<(i64, i64)> = FxHashSet::default();
        dilated.reserve(occupied.len() * 3);
        for &(x, y) in occupied {
            for (dx, dy) in AROUND {
                dilated.insert((x + dx, y + dy));
            }
        }
        let mut order: Vec<(i64, i64)> = dilated
            .iter()
            .copied()
            .filter(|&(x, y)| {
                AROUND
                    .iter()
                    .all(|&(dx, dy)| dilated.contains(&(x + dx, y + dy)))
            })
            .collect();
        order.sort_unstable_by_key(|&(x, y)| (y, x));
        Grid {
            cells: order.iter().copied().collect(),
            order,
        }
    }

    fn at(&self, x: i64, y: i64) -> bool {
        self.cells.contains(&(x, y))
    }

    /// 4-connected groups of occupied cells, in scan order of their first cell.
    fn components(&self) -> Vec<Vec<(i64, i64)>> {
        let mut seen: FxHashSet<(i64, i64)> = FxHashSet::default();
        let mut out = Vec::new();
        for &start in &self.order {
            if !seen.insert(start) {
                continue;
            }
            let mut stack = vec![start];
            let mut comp = Vec::new();
            while let Some((x, y)) = stack.pop() {
                comp.push((x, y));
                for (dx, dy) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
                    let n = (x + dx, y + dy);
                    if self.at(n.0, n.1) && seen.insert(n) {
                        stack.push(n);
                    }
                }
            }
            out.push(comp);
        }
        out
    }

    /// The outer boundary of a 4-connected group as a counter-clockwise ring of cell corners
    /// (grid coordinates), collinear corners dropped.
    fn outer_ring(&self, comp: &[(i64, i64)]) -> Option<Vec<(i64, i64)>> {
        // An occupied 4-neighbour of a group's cell is in the group.
        let inside = |x: i64, y: i64| self.at(x, y);
        // Directed boundary edges with the group on the left, keyed by their start corner.
        let mut out: FxHashMap<(i64, i64), Vec<(i64, i64)>> = Default::default();
        for &(x, y) in comp {
            if !inside(x, y - 1) {
                out.entry((x, y)).or_default().push((x + 1, y));
            }
            if !inside(x + 1, y) {
                out.entry((x + 1, y)).or_default().push((x + 1, y + 1));
            }
            if !inside(x, y + 1) {
                out.entry((x + 1, y + 1)).or_default().push((x, y + 1));
            }
            if !inside(x - 1, y) {
                out.entry((x, y + 1)).or_default().push((x, y));
            }
        }
        let mut best: Option<(i64, Vec<(i64, i64)>)> = None;
        let mut starts: Vec<(i64, i64)> = out.keys().copied().collect();
        starts.sort_unstable();
        for s in starts {
            while out.get(&s).is_some_and(|v| !v.is_empty()) {
                let mut ring = vec![s];
                let mut prev = s;
                let mut cur = take(&mut out, s, None)?;
                while cur != s {
                    ring.push(cur);
                    let dir = (cur.0 - prev.0, cur.1 - prev.1);
                    let next = take(&mut out, cur, Some(dir))?;
                    prev = cur;
                    cur = next;
                }
                let area2: i64 = (0..ring.len())
                    .map(|i| {
                        let (a, b) = (ring[i], ring[(i + 1) % ring.len()]);
                        a.0 * b.1 - b.0 * a.1
                    })
                    .sum();
                if best.as_ref().is_none_or(|(a, _)| area2 > *a) {
                    best = Some((area2, ring));
                }
            }
        }
        let (area2, ring) = best?;
        if area2 <= 0 {
            return None;
        }
        // Drop corners where the boundary runs straight on.
        let n = ring.len();
        let kept: Vec<(i64, i64)> = (0..n)
            .filter(|&i| {
                let (a, b, c) = (ring[(i + n - 1) % n], ring[i], ring[(i + 1) % n]);
                (b.0 - a.0) * (c.1 - b.1) - (b.1 - a.1) * (c.0 - b.0) != 0
            })
            .map(|i| ring[i])
            .collect();
        Some(kept)
    }
}

/// Takes the boundary edge leaving `at`; where two leave (cells touching at a corner only),
/// the one turning right of the incoming direction `dir`, which keeps the touching cells'
/// boundaries apart (4-connectivity).
fn take(
    out: &mut FxHashMap<(i64, i64), Vec<(i64, i64)>>,
    at: (i64, i64),
    dir: Option<(i64, i64)>,
) -> Option<(i64, i64)> {
    let v = out.get_mut(&at)?;
    let i = match (dir, v.len()) {
        (_, 0) => return None,
        (Some(d), n) if n > 1 => {
            // Right of d = (d.1, -d.0).
            let right = (at.0 + d.1, at.1 - d.0);
            v.iter().position(|&e| e == right).unwrap_or(0)
        }
        _ => 0,
    };
    Some(v.swap_remove(i))
}

/// A closed ring simplified by Douglas–Peucker within `tol` metres; the tolerance is halved
/// until no two edges of the result cross (0: the ring as given).
pub fn simplify_ring(ring: &[[f64; 2]], tol: f64) -> Vec<[f64; 2]> {
    let mut tol = tol;
    while tol > 0.01 {
        let s = douglas_peucker_closed(ring, tol);
        if s.len() >= 3 && is_simple(&s) {
            return s;
        }
        tol *= 0.5;
    }
    ring.to_vec()
}

fn douglas_peucker_closed(ring: &[[f64; 2]], tol: f64) -> Vec<[f64; 2]> {
    let n = ring.len();
    if n < 4 {
        return ring.to_vec();
    }
    // Split at vertex 0 and the vertex farthest from it.
    let far = (1..n)
        .max_by(|&i, &j| {
            let d = |k: usize| (ring[k][0] - ring[0][0]).hypot(ring[k][1] - ring[0][1]);
            d(i).total_cmp(&d(j))
        })
        .unwrap_or(n / 2);
    let mut keep = vec![false; n];
    keep[0] = true;
    keep[far] = true;
    let chain_a: Vec<usize> = (0..=far).collect();
    let chain_b: Vec<usize> = (far..n).chain([0]).collect();
    for chain in [chain_a, chain_b] {
        dp(ring, &chain, tol, &mut keep);
    }
    (0..n).filter(|&i| keep[i]).map(|i| ring[i]).collect()
}

fn dp(ring: &[[f64; 2]], chain: &[usize], tol: f64, keep: &mut [bool]) {
    if chain.len() < 3 {
        return;
    }
    let (a, b) = (ring[chain[0]], ring[chain[chain.len() - 1]]);
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len = dx.hypot(dy);
    let dist = |p: [f64; 2]| {
        if len < 1e-12 {
            (p[0] - a[0]).hypot(p[1] - a[1])
        } else {
            ((p[0] - a[0]) * dy - (p[1] - a[1]) * dx).abs() / len
        }
    };
    let (mut worst, mut at) = (0.0, 0);
    for (k, &i) in chain.iter().enumerate().take(chain.len() - 1).skip(1) {
        let d = dist(ring[i]);
        if d > worst {
            worst = d;
            at = k;
        }
    }
    if worst > tol {
        keep[chain[at]] = true;
        dp(ring, &chain[..=at], tol, keep);
        dp(ring, &chain[at..], tol, keep);
    }
}

/// Whether no two non-adjacent edges of a closed ring meet.
fn is_simple(ring: &[[f64; 2]]) -> bool {
    let n = ring.len();
    for i in 0..n {
        let (a, b) = (ring[i], ring[(i + 1) % n]);
        for j in i + 1..n {
            if j == i + 1 || (i == 0 && j == n - 1) {
                continue;
            }
            let (c, d) = (ring[j], ring[(j + 1) % n]);
            if segments_intersect(a, b, c, d) {
                return false;
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    fn signed_area(ring: &[[f64; 2]]) -> f64 {
        let n = ring.len();
        0.5 * (0..n)
            .map(|i| {
                let (a, b) = (ring[i], ring[(i + 1) % n]);
                a[0] * b[1] - b[0] * a[1]
            })
            .sum::<f64>()
    }

    #[test]
    fn an_l_shaped_group_of_cells_gives_its_outline() {
        // An L: a 10 × 2 bar and a 2 × 6 leg, cells of 1.
        let mut cells = Vec::new();
        for x in 0..10 {
            for y in 0..2 {
                cells.push((x, y));
            }
        }
        for x in 0..2 {
            for y in 2..8 {
                cells.push((x, y));
            }
        }
        let grid = Grid::closed(&cells);
        let comps = grid.components();
        assert_eq!(comps.len(), 1);
        assert_eq!(comps[0].len(), cells.len());
        let ring = grid.outer_ring(&comps[0]).unwrap();
        assert_eq!(ring.len(), 6, "{ring:?}");
        let ring: Vec<[f64; 2]> = ring.iter().map(|&(x, y)| [x as f64, y as f64]).collect();
        assert!((signed_area(&ring) - cells.len() as f64).abs() < 1e-9);
    }

    #[test]
    fn cells_far_apart_cost_their_own_size_not_their_bounding_box() {
        // Two 3 × 3 blocks 500 km apart in 0.5 m cells: a dense grid over their box would
        // need 10^12 cells.
        let far = 1_000_000_000i64;
        let mut cells = Vec::new();
        for (ox, oy) in [(0, 0), (far, far)] {
            for y in 0..3 {
                for x in 0..3 {
                    cells.push((ox + x, oy + y));
                }
            }
        }
        let grid = Grid::closed(&cells);
        assert_eq!(grid.order.len(), 18);
        let comps = grid.components();
        assert_eq!(comps.len(), 2);
        assert_eq!(comps[1][0], (far, far));
        let ring = grid.outer_ring(&comps[1]).unwrap();
        assert_eq!(
            ring,
            vec![
                (far, far),
                (far + 3, far),
                (far + 3, far + 3),
                (far, far + 3)
            ]
        );
    }

    #[test]
    fn the_closing_fills_one_cell_gaps_and_holes_are_filled() {
        // A ring of cells around a 3 × 3 hole, and a line with a one-cell gap.
        let mut cells = Vec::new();
        for x in 0..5 {
            for y in 0..5 {
                if !(1..4).contains(&x) || !(1..4).contains(&y) {
                    cells.push((x, y));
                }
            }
        }
        for x in 20..30 {
            if x != 25 {
                cells.push((x, 0));
            }
        }
        let grid = Grid::closed(&cells);
        let comps = grid.components();
        assert_eq!(comps.len(), 2, "the gap is closed");
        for c in &comps {
            let ring = grid.outer_ring(c).unwrap();
            let ring: Vec<[f64; 2]> = ring.iter().map(|&(x, y)| [x as f64, y as f64]).collect();
            assert!(signed_area(&ring) > 0.0);
        }
        let square = comps
            .iter()
            .find(|c| c.iter().any(|&(x, _)| x < 10))
            .unwrap();
        let ring = grid.outer_ring(square).unwrap();
        let ring: Vec<[f64; 2]> = ring.iter().map(|&(x, y)| [x as f64, y as f64]).collect();
        assert!((signed_area(&ring) - 25.0).abs() < 1e-9, "outer 5 × 5");
    }

    #[test]
    fn simplified_rings_stay_simple_and_within_tolerance() {
        // A staircase diagonal strip, two cells thick.
        let mut cells = Vec::new();
        for k in 0..30 {
            cells.push((k, k));
            cells.push((k + 1, k));
        }
        let grid = Grid::closed(&cells);
        let comps = grid.components();
        let ring = grid.outer_ring(&comps[0]).unwrap();
        let ring: Vec<[f64; 2]> = ring.iter().map(|&(x, y)| [x as f64, y as f64]).collect();
        for tol in [0.3, 0.7, 2.0] {
            let s = simplify_ring(&ring, tol);
            assert!(s.len() >= 3 && s.len() <= ring.len());
            assert!(is_simple(&s));
            assert!(signed_area(&s) > 0.0);
        }
        assert!(simplify_ring(&ring, 0.7).len() < ring.len() / 4);
    }

    #[test]
    fn held_out_scans_are_every_nth_from_the_offset() {
        let h: Vec<usize> = (0..7).filter(|&i| held_out(Some((2, 1)), i)).collect();
        assert_eq!(h, vec![1, 3, 5]);
        assert!(!(0..7).any(|i| held_out(None, i)));
        assert!(check(&FacadeMapOptions {
            hold_out: Some((2, 2)),
            ..FacadeMapOptions::default()
        })
        .is_err());
    }
}
