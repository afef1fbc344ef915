//! R-tree spatial index (rstar) over a map's buildings and street segments.
//!
//! Buildings are indexed by their bounding boxes and every candidate is checked exactly
//! (point in polygon with holes, polygon–box intersection); segments are indexed as lines.
//! Bulk loading is O(n log n); each query is O(log n + k) for k candidates.

use super::geometry::{point_in_polygon, polygon_intersects_box, segment_intersects_box};
use super::model::OsmMap;
use rstar::primitives::{GeomWithData, Line, Rectangle};
use rstar::{PointDistance, RTree, AABB};

type BuildingBox = GeomWithData<Rectangle<[f64; 2]>, usize>;
type SegmentLine = GeomWithData<Line<[f64; 2]>, usize>;

/// Spatial index over one [`OsmMap`]'s building outlines and street segments.
pub struct MapIndex<'m> {
    map: &'m OsmMap,
    buildings: RTree<BuildingBox>,
    segments: RTree<SegmentLine>,
}

fn ring_box(ring: &[[f64; 2]]) -> Option<([f64; 2], [f64; 2])> {
    let first = *ring.first()?;
    Some(ring.iter().fold((first, first), |(lo, hi), p| {
        (
            [lo[0].min(p[0]), lo[1].min(p[1])],
            [hi[0].max(p[0]), hi[1].max(p[1])],
        )
    }))
}

impl<'m> MapIndex<'m> {
    /// Bulk-loads both trees from the map.
    pub fn new(map: &'m OsmMap) -> Self {
        let boxes = map
            .buildings
            .iter()
            .enumerate()
            .filter_map(|(i, b)| {
                ring_box(&b.outer)
                    .map(|(lo, hi)| GeomWithData::new(Rectangle::from_corners(lo, hi), i))
            })
            .collect();
        let lines = map
            .streets
            .segments
            .iter()
            .enumerate()
            .map(|(i, s)| GeomWithData::new(Line::new(s.a, s.b), i))
            .collect();
        MapIndex {
            map,
            buildings: RTree::bulk_load(boxes),
            segments: RTree::bulk_load(lines),
        }
    }

    /// Indices of buildings whose polygon (holes excluded) contains the point, ascending.
    pub fn buildings_containing(&self, p: [f64; 2]) -> Vec<usize> {
        let mut hits: Vec<usize> = self
            .buildings
            .locate_all_at_point(&p)
            .map(|g| g.data)
            .filter(|&i| {
                self.map
                    .buildings
                    .get(i)
                    .is_some_and(|b| point_in_polygon(p, &b.outer, &b.inners))
            })
            .collect();
        hits.sort_unstable();
        hits
    }

    /// The building containing the point (the lowest index if outlines overlap), if any.
    pub fn building_at(&self, p: [f64; 2]) -> Option<usize> {
        self.buildings_containing(p).first().copied()
    }

    /// The map the index covers.
    pub fn map(&self) -> &'m OsmMap {
        self.map
    }

    /// The street segment nearest to the point and its distance in metres.
    pub fn nearest_segment(&self, p: [f64; 2]) -> Option<(usize, f64)> {
        self.segments
            .nearest_neighbor(&p)
            .map(|g| (g.data, g.distance_2(&p).sqrt()))
    }

    /// Indices of segments that meet the axis-aligned box `[min, max]`, ascending.
    pub fn segments_in_box(&self, min: [f64; 2], max: [f64; 2]) -> Vec<usize> {
        let mut hits: Vec<usize> = self
            .segments
            .locate_in_envelope_intersecting(&AABB::from_corners(min, max))
            .map(|g| g.data)
            .filter(|&i| {
                self.map
                    .streets
                    .segments
                    .get(i)
                    .is_some_and(|s| segment_intersects_box(s.a, s.b, min, max))
            })
            .collect();
        hits.sort_unstable();
        hits
    }

    /// Indices of buildings whose polygon meets the axis-aligned box `[min, max]`, ascending.
    pub fn buildings_in_box(&self, min: [f64; 2], max: [f64; 2]) -> Vec<usize> {
        let mut hits: Vec<usize> = self
            .buildings
            .locate_in_envelope_intersecting(&AABB::from_corners(min, max))
            .map(|g| g.data)
            .filter(|&i| {
                self.map
                    .buildings
                    .get(i)
                    .is_some_and(|b| polygon_intersects_box(&b.outer, &b.inners, min, max))
            })
            .collect();
        hits.sort_unstable();
        hits
    }
}
