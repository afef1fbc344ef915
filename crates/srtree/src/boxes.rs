//! Boxes in the map frame: an object's annotated box and how it looks from a viewpoint, and
//! the building outlines of the robot's map that complete a building's box
//! ([`MapOutlines`]).

use crate::graph::Viewpoint;
use geodata::osm::geometry::{bounding_box_at, longest_edge_box, point_ring_distance, ring_bounds};

/// An annotated box of an object, map frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnnotatedBox {
    /// Centre, metres.
    pub centre: [f64; 3],
    /// Half extents along the yaw axis, across it, and up, metres.
    pub half_extents: [f64; 3],
    /// Yaw of the first axis, counter-clockwise from the map's x axis, radians.
    pub yaw_rad: f64,
}

/// Azimuth interval, nearest footprint corner range and centre range of a box seen from a viewpoint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxView {
    /// Azimuth interval (lo, hi), radians, left positive.
    pub azimuth: [f64; 2],
    /// Range of the nearest footprint corner, metres.
    pub near_range: f64,
    /// Range of the centre, metres.
    pub centre_range: f64,
}

impl AnnotatedBox {
    /// How the box looks from `viewpoint` (top view).
    pub fn view(&self, viewpoint: &Viewpoint) -> BoxView {
        let (s, c) = self.yaw_rad.sin_cos();
        let h = self.half_extents;
        let mut out = BoxView {
            azimuth: [f64::INFINITY, f64::NEG_INFINITY],
            near_range: f64::INFINITY,
            centre_range: 0.0,
        };
        for (kx, ky) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            let (x, y) = (kx * h[0], ky * h[1]);
            let p = viewpoint.to_view([
                self.centre[0] + c * x - s * y,
                self.centre[1] + s * x + c * y,
                self.centre[2],
            ]);
            let a = p[1].atan2(p[0]);
            out.azimuth = [out.azimuth[0].min(a), out.azimuth[1].max(a)];
            out.near_range = out.near_range.min(p[0].hypot(p[1]));
        }
        let v = viewpoint.to_view(self.centre);
        out.centre_range = v[0].hypot(v[1]);
        out
    }
}

/// Cells within this distance of an outline's boundary stand in it (walls lie on it), metres;
/// a cell within reach of several outlines counts for the one it is inside, else the nearest.
pub const OUTLINE_MATCH_M: f64 = 1.0;

/// Share of an object's cells an outline must hold to be the object's (the best one), and
/// to join it (others: an object the segmentation merged over several buildings).
pub const OUTLINE_SHARE: [f64; 2] = [0.5, 0.2];

/// At most this many of an object's cells are tested against the outlines.
const OUTLINE_TEST_CELLS: usize = 512;

/// Building outlines of the robot's map, in the map frame.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MapOutlines {
    rings: Vec<Vec<[f64; 2]>>,
    /// Bounds of each ring grown by [`OUTLINE_MATCH_M`].
    bounds: Vec<([f64; 2], [f64; 2])>,
}

impl MapOutlines {
    /// Outlines from outer rings (rings with fewer than three vertices are left out).
    pub fn new(rings: impl IntoIterator<Item = Vec<[f64; 2]>>) -> MapOutlines {
        let rings: Vec<Vec<[f64; 2]>> = rings.into_iter().filter(|r| r.len() >= 3).collect();
        let bounds = rings
            .iter()
            .map(|r| {
                let (lo, hi) = ring_bounds(r);
                (
                    lo.map(|v| v - OUTLINE_MATCH_M),
                    hi.map(|v| v + OUTLINE_MATCH_M),
                )
            })
            .collect();
        MapOutlines { rings, bounds }
    }

    /// The building outlines of an OSM map, moved into the frame of a cloud (`frame`: the
    /// cloud's georeference; `Local` is the map's own frame).
    pub fn from_osm(
        osm: &geodata::osm::OsmMap,
        frame: &geodata::georef::CloudFrame,
    ) -> std::result::Result<MapOutlines, geodata::georef::GeorefError> {
        if *frame == geodata::georef::CloudFrame::Local {
            return Ok(MapOutlines::new(
                osm.buildings.iter().map(|b| b.outer.clone()),
            ));
        }
        let mut rings = Vec::with_capacity(osm.buildings.len());
        for b in &osm.buildings {
            let mut ring = Vec::with_capacity(b.outer.len());
            for &v in &b.outer {
                let (lat, lon) = osm.frame.to_wgs84(v);
                let p = frame.from_wgs84(lat, lon, 0.0, &osm.frame)?;
                ring.push([p[0], p[1]]);
            }
            rings.push(ring);
        }
        Ok(MapOutlines::new(rings))
    }

    /// Number of outlines.
    pub fn len(&self) -> usize {
        self.rings.len()
    }

    /// Whether there are no outlines.
    pub fn is_empty(&self) -> bool {
        self.rings.is_empty()
    }

    /// The box (map frame) of the outlines an object's cells (map frame) stand in: `None`
    /// unless one outline holds [`OUTLINE_SHARE`]`[0]` of them.
    pub fn box_of(&self, cells: &[[f64; 3]]) -> Option<AnnotatedBox> {
        if cells.is_empty() {
            return None;
        }
        let stride = cells.len().div_ceil(OUTLINE_TEST_CELLS).max(1);
        let mut counts: std::collections::BTreeMap<usize, usize> = Default::default();
        let mut tested = 0usize;
        for c in cells.iter().step_by(stride) {
            tested += 1;
            let p = [c[0], c[1]];
            // Each cell to one outline: one it stands in, else the nearest boundary within
            // reach (touching outlines share a wall; the cell counts for one of them).
            let mut owner: Option<(usize, f64)> = None;
            for (i, (lo, hi)) in self.bounds.iter().enumerate() {
                if p[0] < lo[0] || p[0] > hi[0] || p[1] < lo[1] || p[1] > hi[1] {
                    continue;
                }
                let d = point_ring_distance(p, &self.rings[i]);
                if d <= OUTLINE_MATCH_M && owner.is_none_or(|(_, best)| d < best) {
                    owner = Some((i, d));
                }
            }
            if let Some((i, _)) = owner {
                *counts.entry(i).or_default() += 1;
            }
        }
        let share = |n: usize| n as f64 / tested as f64;
        let (&best, &n) = counts
            .iter()
            .max_by_key(|&(&i, &n)| (n, std::cmp::Reverse(i)))?;
        if share(n) < OUTLINE_SHARE[0] {
            return None;
        }
        let mut points: Vec<[f64; 2]> = Vec::new();
        for (&i, &n) in &counts {
            if share(n) >= OUTLINE_SHARE[1] {
                points.extend_from_slice(&self.rings[i]);
            }
        }
        let yaw = longest_edge_box(&self.rings[best])?.yaw_rad;
        let b = bounding_box_at(&points, yaw);
        let (z_lo, z_hi) = cells
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), c| {
                (l.min(c[2]), h.max(c[2]))
            });
        Some(AnnotatedBox {
            centre: [b.centre[0], b.centre[1], 0.5 * (z_lo + z_hi)],
            half_extents: [b.half[0], b.half[1], 0.5 * (z_hi - z_lo)],
            yaw_rad: b.yaw_rad,
        })
    }
}

impl AnnotatedBox {
    /// The box in the frame of `viewpoint` (given in the map frame).
    pub fn to_view(&self, viewpoint: &Viewpoint) -> AnnotatedBox {
        AnnotatedBox {
            centre: viewpoint.to_view(self.centre),
            half_extents: self.half_extents,
            yaw_rad: self.yaw_rad - viewpoint.yaw_rad,
        }
    }
}
