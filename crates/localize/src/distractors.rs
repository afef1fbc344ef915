//! A harder map for the localization evaluation: a target map's building outlines and streets
//! embedded among distractor buildings and streets cut from another real map.
//!
//! Construction (seeded, deterministic):
//!
//! 1. The *hole* is the bounding box of the target's building outlines grown by `gap_m`; the
//!    *outer box* is that bounding box grown by `ring_m`. The target map is kept unchanged.
//! 2. The outer box is covered by square tiles of side `tile_m`, anchored at its lower-left
//!    corner. Tiles that lie entirely inside the hole are skipped.
//! 3. For each tile (row-major), a rotation θ ∈ [0, 2π) and a source centre c are drawn from
//!    one ChaCha8 stream seeded by `seed`; c is the vertex mean of a uniformly drawn building of
//!    the other map, among those at least half a tile diagonal inside the other map's building
//!    bounding box when there are any (so tiles land in built-up land). The rigid motion
//!    p ↦ R(θ)(p − c) + tile centre carries the other map into the tile.
//! 4. A moved building joins the map when its vertex mean falls inside the tile, its bounding
//!    box does not meet the hole, and it overlaps no distractor already placed from another
//!    tile (at the seams; buildings of one tile keep their shared walls as in the source).
//!    A moved street segment joins when its midpoint falls inside the tile and it does not
//!    meet the hole; each kept segment becomes a two-node highway way with fresh node ids.
//!
//! So the distractors are real buildings and streets (rotated, so no tile repeats another or
//! the target's grid orientation), the street filter cannot reject them, and none of them
//! touches a target building (they stay `gap_m` away from the target's bounding box). The
//! search area grows from the target's bounding box to the outer box.

use crate::{LocalizeError, Result};
use geodata::osm::geometry::rings_overlap;
use geodata::osm::model::{Building, HighwayWay, OsmMap};
use geodata::osm::network::build_network;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rustc_hash::FxHashMap;

/// Options of [`embed_among_distractors`].
#[derive(Debug, Clone, PartialEq)]
pub struct DistractorOptions {
    /// Width of the ring of distractors around the target's building bounding box, metres.
    pub ring_m: f64,
    /// Free margin between the target's building bounding box and any distractor, metres.
    pub gap_m: f64,
    /// Side of one tile cut from the other map, metres.
    pub tile_m: f64,
    /// Seed of the tiles' rotations and source centres.
    pub seed: u64,
}

impl Default for DistractorOptions {
    fn default() -> Self {
        DistractorOptions {
            ring_m: 400.0,
            gap_m: 30.0,
            tile_m: 500.0,
            seed: 1,
        }
    }
}

/// Where one tile of the other map was placed.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct TilePlacement {
    /// Lower-left corner of the tile, metres in the target frame.
    pub min: [f64; 2],
    /// Source centre in the other map's frame, metres.
    pub source_centre: [f64; 2],
    /// Rotation from the other map into the target frame, radians.
    pub yaw_rad: f64,
}

impl TilePlacement {
    /// Maps a point of the other map into the target frame (`side` the tile side).
    pub fn apply(&self, p: [f64; 2], side: f64) -> [f64; 2] {
        let (s, c) = self.yaw_rad.sin_cos();
        let (dx, dy) = (p[0] - self.source_centre[0], p[1] - self.source_centre[1]);
        [
            c * dx - s * dy + self.min[0] + side / 2.0,
            s * dx + c * dy + self.min[1] + side / 2.0,
        ]
    }
}

/// What [`embed_among_distractors`] built.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DistractorSummary {
    /// Buildings of the target map (they come first in the composed map).
    pub target_buildings: usize,
    /// Distractor buildings added.
    pub distractor_buildings: usize,
    /// Distractor buildings dropped because they overlapped one already placed.
    pub dropped_overlapping: usize,
    /// Distractor street segments added.
    pub distractor_street_segments: usize,
    /// The hole kept free of distractors: `[min_x, min_y, max_x, max_y]`, metres.
    pub hole: [f64; 4],
    /// The outer box: `[min_x, min_y, max_x, max_y]`, metres.
    pub outer: [f64; 4],
    /// Area of the target's building bounding box, km².
    pub target_area_km2: f64,
    /// Area of the outer box, km².
    pub outer_area_km2: f64,
    /// The tiles, row-major.
    pub tiles: Vec<TilePlacement>,
}

type Box2 = ([f64; 2], [f64; 2]);

fn ring_box(ring: &[[f64; 2]]) -> Option<Box2> {
    let first = *ring.first()?;
    Some(ring.iter().fold((first, first), |(lo, hi), p| {
        (
            [lo[0].min(p[0]), lo[1].min(p[1])],
            [hi[0].max(p[0]), hi[1].max(p[1])],
        )
    }))
}

fn union(a: Option<Box2>, b: Option<Box2>) -> Option<Box2> {
    match (a, b) {
        (Some((l1, h1)), Some((l2, h2))) => Some((
            [l1[0].min(l2[0]), l1[1].min(l2[1])],
            [h1[0].max(h2[0]), h1[1].max(h2[1])],
        )),
        (x, None) | (None, x) => x,
    }
}

fn boxes_meet(a: &Box2, b: &Box2) -> bool {
    a.0[0] <= b.1[0] && b.0[0] <= a.1[0] && a.0[1] <= b.1[1] && b.0[1] <= a.1[1]
}

fn buildings_box(map: &OsmMap) -> Option<Box2> {
    map.buildings
        .iter()
        .fold(None, |acc, b| union(acc, ring_box(&b.outer)))
}

fn inside(p: [f64; 2], lo: [f64; 2], side: f64) -> bool {
    p[0] >= lo[0] && p[0] < lo[0] + side && p[1] >= lo[1] && p[1] < lo[1] + side
}

/// Buckets of placed distractor boxes for the seam-overlap test.
struct PlacedGrid {
    cell_m: f64,
    buckets: FxHashMap<(i64, i64), Vec<usize>>,
}

impl PlacedGrid {
    fn keys(&self, b: &Box2) -> impl Iterator<Item = (i64, i64)> {
        let k = |v: f64| (v / self.cell_m).floor() as i64;
        let (x0, x1, y0, y1) = (k(b.0[0]), k(b.1[0]), k(b.0[1]), k(b.1[1]));
        (x0..=x1).flat_map(move |x| (y0..=y1).map(move |y| (x, y)))
    }
}

/// The target map with distractor buildings and streets from `other` around it (see the
/// module doc). The composed map keeps the target's frame, bounds and statistics; its
/// buildings are the target's (first, unchanged) followed by the distractors.
///
/// Cost: O(tiles × (|other buildings| + |other street segments|)) plus the overlap tests.
pub fn embed_among_distractors(
    target: &OsmMap,
    other: &OsmMap,
    options: &DistractorOptions,
) -> Result<(OsmMap, DistractorSummary)> {
    for (name, value, ok) in [
        ("ring_m", options.ring_m, options.ring_m >= 0.0),
        ("gap_m", options.gap_m, options.gap_m >= 0.0),
        ("tile_m", options.tile_m, options.tile_m > 1.0),
    ] {
        if !(ok && value.is_finite()) {
            return Err(LocalizeError::InvalidOption {
                name,
                value,
                expected: "a finite length (ring and gap ≥ 0, tile > 1 m)",
            });
        }
    }
    let Some((t_lo, t_hi)) = buildings_box(target) else {
        return Err(LocalizeError::NoBuildings {
            what: "the target map",
        });
    };
    let Some((o_lo, o_hi)) = buildings_box(other) else {
        return Err(LocalizeError::NoBuildings {
            what: "the distractor map",
        });
    };
    let g = options.gap_m;
    let hole: Box2 = ([t_lo[0] - g, t_lo[1] - g], [t_hi[0] + g, t_hi[1] + g]);
    let r = options.ring_m;
    let outer: Box2 = ([t_lo[0] - r, t_lo[1] - r], [t_hi[0] + r, t_hi[1] + r]);
    let side = options.tile_m;
    let nx = ((outer.1[0] - outer.0[0]) / side).ceil().max(1.0) as usize;
    let ny = ((outer.1[1] - outer.0[1]) / side).ceil().max(1.0) as usize;
    let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
    // Source centres: the vertex means of the other map's buildings, those around which a
    // whole (rotated) tile fits in the other map's building box when there are such, so the
    // tiles land in built-up land (Monaco's box is mostly sea).
    let half_diag = side * std::f64::consts::FRAC_1_SQRT_2;
    let means: Vec<[f64; 2]> = other
        .buildings
        .iter()
        .filter_map(|b| vertex_mean(&b.outer))
        .collect();
    let fitting: Vec<[f64; 2]> = means
        .iter()
        .copied()
        .filter(|m| {
            m[0] - half_diag >= o_lo[0]
                && m[0] + half_diag <= o_hi[0]
                && m[1] - half_diag >= o_lo[1]
                && m[1] + half_diag <= o_hi[1]
        })
        .collect();
    let centres = if fitting.is_empty() { &means } else { &fitting };
    let mut tiles = Vec::new();
    for ty in 0..ny {
        for tx in 0..nx {
            let min = [outer.0[0] + tx as f64 * side, outer.0[1] + ty as f64 * side];
            // Draw for every tile so the placements do not depend on the hole.
            let yaw_rad = rng.gen_range(0.0..std::f64::consts::TAU);
            let source_centre = centres[rng.gen_range(0..centres.len())];
            let tile_box: Box2 = (min, [min[0] + side, min[1] + side]);
            let in_hole = tile_box.0[0] >= hole.0[0]
                && tile_box.0[1] >= hole.0[1]
                && tile_box.1[0] <= hole.1[0]
                && tile_box.1[1] <= hole.1[1];
            if !in_hole {
                tiles.push(TilePlacement {
                    min,
                    source_centre,
                    yaw_rad,
                });
            }
        }
    }
    let mut map = target.clone();
    let mut summary = DistractorSummary {
        target_buildings: target.buildings.len(),
        distractor_buildings: 0,
        dropped_overlapping: 0,
        distractor_street_segments: 0,
        hole: [hole.0[0], hole.0[1], hole.1[0], hole.1[1]],
        outer: [outer.0[0], outer.0[1], outer.1[0], outer.1[1]],
        target_area_km2: (t_hi[0] - t_lo[0]) * (t_hi[1] - t_lo[1]) / 1e6,
        outer_area_km2: (outer.1[0] - outer.0[0]) * (outer.1[1] - outer.0[1]) / 1e6,
        tiles: Vec::new(),
    };
    let mut grid = PlacedGrid {
        cell_m: 50.0,
        buckets: FxHashMap::default(),
    };
    // (box, building index, tile index) of every placed distractor.
    let mut placed: Vec<(Box2, usize, usize)> = Vec::new();
    // Fresh ids: above every id of both maps.
    let max_id = target
        .highways
        .iter()
        .flat_map(|h| h.node_ids.iter().copied().chain([h.osm_id]))
        .chain(target.buildings.iter().map(|b| b.osm_id))
        .chain(other.buildings.iter().map(|b| b.osm_id))
        .max()
        .unwrap_or(0)
        .max(0);
    let mut next_id = max_id + 1;
    let mut fresh = || {
        next_id += 1;
        next_id
    };
    for (tile_index, tile) in tiles.iter().enumerate() {
        let tile_box: Box2 = (tile.min, [tile.min[0] + side, tile.min[1] + side]);
        // Quick reject of source elements far from the tile: its preimage lies within the
        // disc of radius half_diag around the source centre.
        let near_source = |p: [f64; 2]| {
            (p[0] - tile.source_centre[0]).hypot(p[1] - tile.source_centre[1]) <= half_diag + 1.0
        };
        for b in &other.buildings {
            let Some(mean) = vertex_mean(&b.outer) else {
                continue;
            };
            if !near_source(mean) {
                continue;
            }
            let moved_mean = tile.apply(mean, side);
            if !inside(moved_mean, tile_box.0, side) {
                continue;
            }
            let outer_ring: Vec<[f64; 2]> = b.outer.iter().map(|&p| tile.apply(p, side)).collect();
            let Some(bb) = ring_box(&outer_ring) else {
                continue;
            };
            if boxes_meet(&bb, &hole) {
                continue;
            }
            let overlaps = grid.keys(&bb).any(|key| {
                grid.buckets.get(&key).is_some_and(|ids| {
                    ids.iter().any(|&id| {
                        let (pb, bi, ti) = placed[id];
                        ti != tile_index
                            && boxes_meet(&pb, &bb)
                            && map
                                .buildings
                                .get(bi)
                                .is_some_and(|o| rings_overlap(&o.outer, &outer_ring))
                    })
                })
            });
            if overlaps {
                summary.dropped_overlapping += 1;
                continue;
            }
            let keys: Vec<(i64, i64)> = grid.keys(&bb).collect();
            for key in keys {
                grid.buckets.entry(key).or_default().push(placed.len());
            }
            placed.push((bb, map.buildings.len(), tile_index));
            map.buildings.push(Building {
                osm_id: fresh(),
                kind: b.kind,
                building: b.building.clone(),
                outer: outer_ring,
                inners: b
                    .inners
                    .iter()
                    .map(|r| r.iter().map(|&p| tile.apply(p, side)).collect())
                    .collect(),
                height_m: b.height_m,
                levels: b.levels,
                name: None,
            });
            summary.distractor_buildings += 1;
        }
        for s in &other.streets.segments {
            let mid = [0.5 * (s.a[0] + s.b[0]), 0.5 * (s.a[1] + s.b[1])];
            if !near_source(mid) {
                continue;
            }
            let (a, b) = (tile.apply(s.a, side), tile.apply(s.b, side));
            let moved_mid = [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])];
            if !inside(moved_mid, tile_box.0, side) {
                continue;
            }
            let sb: Box2 = (
                [a[0].min(b[0]), a[1].min(b[1])],
                [a[0].max(b[0]), a[1].max(b[1])],
            );
            if boxes_meet(&sb, &hole) {
                continue;
            }
            let (from, to) = (fresh(), fresh());
            map.highways.push(HighwayWay::plain(
                fresh(),
                &s.highway,
                vec![from, to],
                vec![a, b],
            ));
            summary.distractor_street_segments += 1;
        }
    }
    map.streets = build_network(&map.highways);
    summary.tiles = tiles;
    Ok((map, summary))
}

fn vertex_mean(ring: &[[f64; 2]]) -> Option<[f64; 2]> {
    if ring.is_empty() {
        return None;
    }
    let n = ring.len() as f64;
    let s = ring
        .iter()
        .fold([0.0, 0.0], |acc, p| [acc[0] + p[0], acc[1] + p[1]]);
    Some([s[0] / n, s[1] / n])
}

#[cfg(test)]
mod tests {
    use super::*;
    use geodata::osm::geometry::signed_area;
    use geodata::osm::model::OsmStats;
    use geodata::projection::LocalFrame;

    fn square(c: [f64; 2], half: f64) -> Vec<[f64; 2]> {
        vec![
            [c[0] - half, c[1] - half],
            [c[0] + half, c[1] - half],
            [c[0] + half, c[1] + half],
            [c[0] - half, c[1] + half],
        ]
    }

    fn map_of(rings: Vec<Vec<[f64; 2]>>, streets: Vec<[[f64; 2]; 2]>) -> OsmMap {
        let highways: Vec<HighwayWay> = streets
            .iter()
            .enumerate()
            .map(|(i, s)| {
                HighwayWay::plain(
                    1000 + i as i64,
                    "residential",
                    vec![2 * i as i64 + 1, 2 * i as i64 + 2],
                    s.to_vec(),
                )
            })
            .collect();
        OsmMap {
            frame: LocalFrame::new(59.35, 18.07).unwrap(),
            bbox_lonlat: [18.0, 59.3, 18.1, 59.4],
            buildings: rings
                .into_iter()
                .enumerate()
                .map(|(i, outer)| Building::outline(i as i64, outer, Vec::new()))
                .collect(),
            streets: build_network(&highways),
            highways,
            stats: OsmStats::default(),
        }
    }

    /// The other map: a lattice of 6 m squares every 20 m over 400 m × 400 m, with a street
    /// along every lattice row.
    fn lattice() -> OsmMap {
        let mut rings = Vec::new();
        for i in 0..20 {
            for j in 0..20 {
                rings.push(square(
                    [10.0 + 20.0 * i as f64, 10.0 + 20.0 * j as f64],
                    3.0,
                ));
            }
        }
        let streets = (0..20)
            .flat_map(|j| {
                (0..20).map(move |i| {
                    let y = 20.0 * j as f64;
                    [[20.0 * i as f64, y], [20.0 * (i + 1) as f64, y]]
                })
            })
            .collect();
        map_of(rings, streets)
    }

    fn target() -> OsmMap {
        map_of(
            vec![square([0.0, 0.0], 10.0), square([60.0, 40.0], 8.0)],
            vec![[[-20.0, -20.0], [80.0, -20.0]]],
        )
    }

    #[test]
    fn composed_map_has_the_target_and_congruent_distractors_around_it() {
        let (t, o) = (target(), lattice());
        let options = DistractorOptions {
            ring_m: 100.0,
            gap_m: 15.0,
            tile_m: 60.0,
            seed: 7,
        };
        let (map, summary) = embed_among_distractors(&t, &o, &options).unwrap();
        // The target comes first, unchanged; its streets too.
        assert_eq!(map.buildings[..2], t.buildings[..]);
        assert_eq!(summary.target_buildings, 2);
        assert_eq!(map.highways[..1], t.highways[..]);
        assert_eq!(
            map.buildings.len(),
            2 + summary.distractor_buildings,
            "{summary:?}"
        );
        let hole: Box2 = ([-25.0, -25.0], [83.0, 63.0]);
        let outer: Box2 = ([-110.0, -110.0], [168.0, 148.0]);
        assert_eq!(summary.hole, [-25.0, -25.0, 83.0, 63.0]);
        assert_eq!(summary.outer, [-110.0, -110.0, 168.0, 148.0]);
        // Every distractor: a 6 m square (a lattice building moved rigidly), counter-clockwise,
        // clear of the hole, its vertex mean in its tile and so in the outer box, and
        // overlapping no other building.
        for (k, b) in map.buildings.iter().enumerate().skip(2) {
            assert_eq!(b.outer.len(), 4);
            assert!((signed_area(&b.outer) - 36.0).abs() < 1e-6, "{k}");
            for i in 0..4 {
                let (p, q) = (b.outer[i], b.outer[(i + 1) % 4]);
                assert!(((p[0] - q[0]).hypot(p[1] - q[1]) - 6.0).abs() < 1e-9);
            }
            let bb = ring_box(&b.outer).unwrap();
            assert!(!boxes_meet(&bb, &hole), "{k} {bb:?}");
            let m = vertex_mean(&b.outer).unwrap();
            assert!(m[0] >= outer.0[0] && m[1] >= outer.0[1]);
            assert!(m[0] <= outer.1[0] + 60.0 && m[1] <= outer.1[1] + 60.0);
            for (l, c) in map.buildings.iter().enumerate() {
                if l != k {
                    assert!(!rings_overlap(&b.outer, &c.outer), "{k} overlaps {l}");
                }
            }
        }
        // The lattice holds one building per 400 m²: the tiles outside the hole cover the
        // outer box (rounded up to whole tiles) minus the hole, give or take the seams.
        let tiled = 5.0 * 5.0 * 3600.0;
        let hole_area = 108.0 * 88.0;
        let expected = (tiled - hole_area) / 400.0;
        let n = summary.distractor_buildings as f64 + summary.dropped_overlapping as f64;
        assert!((n - expected).abs() < 0.12 * expected, "{n} vs {expected}");
        // Each tile's buildings are exactly the lattice squares whose moved centre is in it.
        for tile in &summary.tiles {
            let want: Vec<[f64; 2]> = o
                .buildings
                .iter()
                .map(|b| tile.apply(vertex_mean(&b.outer).unwrap(), 60.0))
                .filter(|&m| inside(m, tile.min, 60.0))
                .filter(|&m| {
                    !boxes_meet(&([m[0] - 4.3, m[1] - 4.3], [m[0] + 4.3, m[1] + 4.3]), &hole)
                })
                .collect();
            for m in &want {
                let found = map.buildings.iter().skip(2).any(|b| {
                    let c = vertex_mean(&b.outer).unwrap();
                    (c[0] - m[0]).hypot(c[1] - m[1]) < 1e-9
                });
                // Dropped only for a seam overlap with a placed building.
                let blocked = map.buildings.iter().skip(2).any(|b| {
                    ring_box(&b.outer).is_some_and(|bb| {
                        boxes_meet(&bb, &([m[0] - 4.3, m[1] - 4.3], [m[0] + 4.3, m[1] + 4.3]))
                    })
                });
                assert!(found || blocked, "{m:?}");
            }
        }
        // Streets around the target, none in the hole, all in the street network.
        assert!(summary.distractor_street_segments > 0);
        assert_eq!(
            map.streets.segments.len(),
            t.streets.segments.len() + summary.distractor_street_segments
        );
        for s in &map.streets.segments[t.streets.segments.len()..] {
            let sb: Box2 = (
                [s.a[0].min(s.b[0]), s.a[1].min(s.b[1])],
                [s.a[0].max(s.b[0]), s.a[1].max(s.b[1])],
            );
            assert!(!boxes_meet(&sb, &hole));
            assert!((s.length_m - 20.0).abs() < 1e-9);
        }
        // Seeded: the same seed gives the same map, another seed another one.
        let (again, _) = embed_among_distractors(&t, &o, &options).unwrap();
        assert_eq!(again.buildings, map.buildings);
        let (other_seed, _) = embed_among_distractors(
            &t,
            &o,
            &DistractorOptions {
                seed: 8,
                ..options.clone()
            },
        )
        .unwrap();
        assert_ne!(other_seed.buildings, map.buildings);
    }

    #[test]
    fn maps_without_buildings_and_bad_options_are_errors() {
        let empty = map_of(Vec::new(), Vec::new());
        let err =
            embed_among_distractors(&target(), &empty, &DistractorOptions::default()).unwrap_err();
        assert!(err.to_string().contains("distractor map"), "{err}");
        let err =
            embed_among_distractors(&empty, &lattice(), &DistractorOptions::default()).unwrap_err();
        assert!(err.to_string().contains("target map"), "{err}");
        let bad = DistractorOptions {
            tile_m: 0.0,
            ..DistractorOptions::default()
        };
        assert!(embed_among_distractors(&target(), &lattice(), &bad).is_err());
    }
}
