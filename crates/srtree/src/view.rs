//! An object as seen from a viewpoint: its cells in the view frame, azimuth interval, hulls,
//! contact point and, where the map knows it, its box from the map's outlines; and whether a
//! nearer object hides one of its lateral edges ([`edge_occlusion`]).

use crate::boxes::{AnnotatedBox, MapOutlines};
use crate::graph::Viewpoint;
use crate::objects::{MapObject, OrientedBox};
use geodata::classes::Class;

/// Cells at most this far above an object's lowest cell form its contact region, metres.
pub const CONTACT_SLICE_M: f64 = 0.3;

/// Azimuth window about an object's lateral edge in which an occluder is looked for, radians.
pub const OCCLUSION_WINDOW_RAD: f64 = 0.03;

/// How much nearer than the occluded object an occluder must be, metres.
pub const OCCLUSION_DEPTH_M: f64 = 0.5;

/// Objects are subsampled to at most this many cells for the hull and azimuth features.
pub const MAX_FEATURE_CELLS: usize = 600;

/// An object seen from a viewpoint, with everything the pair features need.
#[derive(Debug, Clone)]
pub struct ViewObject {
    /// Object id.
    pub id: u32,
    /// Class.
    pub class: Class,
    /// Subsampled cell centres in the view frame.
    pub cells: Vec<[f64; 3]>,
    /// All cell centres in the view frame.
    pub footprint_cells: Vec<[f64; 3]>,
    /// Lowest cell centre height in the view frame.
    pub bottom: f64,
    /// Contact point: mean of the cells within [`CONTACT_SLICE_M`] of the lowest one
    /// (where a thing touches what supports it: a tree's trunk foot, a car's underside).
    pub contact: [f64; 3],
    /// Centroid in the view frame.
    pub centroid: [f64; 3],
    /// Box corners in the view frame.
    pub corners: [[f64; 3]; 8],
    /// Box footprint centre in the view frame.
    pub box_centre: [f64; 3],
    /// Axis-aligned hull of the corners in the view frame.
    pub lo: [f64; 3],
    /// Axis-aligned hull of the corners in the view frame.
    pub hi: [f64; 3],
    /// Azimuth interval of the box corners (lo, hi), radians, left positive.
    pub azimuth: [f64; 2],
    /// Azimuth interval of the cells.
    pub cells_azimuth: [f64; 2],
    /// Range of the nearest footprint corner, metres.
    pub near_range: f64,
    /// Convex hulls of the cells projected along x (y–z), y (x–z) and z (x–y).
    pub hulls: [Vec<[f64; 2]>; 3],
    /// Yaw of the viewing direction in the map frame, radians.
    pub view_yaw_rad: f64,
    /// The box of the map outlines the object stands in, view frame (buildings the map
    /// knows; [`MapOutlines`]).
    pub map_box: Option<AnnotatedBox>,
}

impl ViewObject {
    /// The object seen from `viewpoint`; `cells` are its cell centres in the map frame.
    pub fn new(
        id: u32,
        class: Class,
        cells_in_map: &[[f64; 3]],
        bbox: &OrientedBox,
        viewpoint: &Viewpoint,
    ) -> ViewObject {
        let stride = cells_in_map.len().div_ceil(MAX_FEATURE_CELLS).max(1);
        let all: Vec<[f64; 3]> = cells_in_map.iter().map(|&p| viewpoint.to_view(p)).collect();
        let cells: Vec<[f64; 3]> = all.iter().step_by(stride).copied().collect();
        let n = all.len().max(1) as f64;
        let centroid = [0, 1, 2].map(|k| all.iter().map(|p| p[k]).sum::<f64>() / n);
        let corners = bbox.corners().map(|c| viewpoint.to_view(c));
        let box_centre = viewpoint.to_view(bbox.centre);
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for c in &corners {
            for k in 0..3 {
                lo[k] = lo[k].min(c[k]);
                hi[k] = hi[k].max(c[k]);
            }
        }
        let azimuth = interval(corners.iter().map(|c| c[1].atan2(c[0])));
        let cells_azimuth = interval(all.iter().map(|c| c[1].atan2(c[0])));
        let near_range = corners[..4]
            .iter()
            .map(|c| c[0].hypot(c[1]))
            .fold(f64::INFINITY, f64::min);
        let hulls = [(1, 2), (0, 2), (0, 1)]
            .map(|(i, j)| convex_hull(cells.iter().map(|p| [p[i], p[j]]).collect()));
        let bottom = all.iter().map(|p| p[2]).fold(f64::INFINITY, f64::min);
        let slice: Vec<&[f64; 3]> = all
            .iter()
            .filter(|p| p[2] <= bottom + CONTACT_SLICE_M)
            .collect();
        let m = slice.len().max(1) as f64;
        let contact = [0, 1, 2].map(|k| slice.iter().map(|p| p[k]).sum::<f64>() / m);
        ViewObject {
            id,
            class,
            bottom,
            contact,
            footprint_cells: all.clone(),
            cells,
            centroid,
            corners,
            box_centre,
            lo,
            hi,
            azimuth,
            cells_azimuth,
            near_range,
            hulls,
            view_yaw_rad: viewpoint.yaw_rad,
            map_box: None,
        }
    }

    /// Whether the object lies in front of the observer: the centre of its map box if it
    /// has one, else the centroid of its cells.
    pub fn in_front(&self) -> bool {
        self.map_box.map_or(self.centroid[0], |b| b.centre[0]) > 0.0
    }

    /// Range of the estimated box's centre from the observer, metres.
    pub fn centre_range(&self) -> f64 {
        self.box_centre[0].hypot(self.box_centre[1])
    }

    /// A map object seen from `viewpoint`.
    pub fn from_map_object(
        map: &crate::map::SrMap,
        o: &MapObject,
        viewpoint: &Viewpoint,
    ) -> ViewObject {
        Self::from_map_object_with_outlines(map, o, viewpoint, &Default::default())
    }

    /// A map object seen from `viewpoint`, a building completed from the map's outlines.
    pub fn from_map_object_with_outlines(
        map: &crate::map::SrMap,
        o: &MapObject,
        viewpoint: &Viewpoint,
        outlines: &MapOutlines,
    ) -> ViewObject {
        let cells: Vec<[f64; 3]> = o
            .cells
            .iter()
            .map(|&i| map.centre(map.cells()[i as usize].key))
            .collect();
        let mut v = ViewObject::new(o.id, o.class, &cells, &o.bbox, viewpoint);
        if o.class == Class::Building {
            v.map_box = outlines.box_of(&cells).map(|b| b.to_view(viewpoint));
        }
        v
    }
}

fn interval(angles: impl Iterator<Item = f64>) -> [f64; 2] {
    let mut out = [f64::INFINITY, f64::NEG_INFINITY];
    for a in angles {
        out[0] = out[0].min(a);
        out[1] = out[1].max(a);
    }
    if out[0] > out[1] {
        [0.0, 0.0]
    } else {
        out
    }
}

/// Convex hull (Andrew's monotone chain), counter-clockwise, no collinear points.
pub fn convex_hull(mut pts: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    pts.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    pts.dedup();
    if pts.len() < 3 {
        return pts;
    }
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut hull: Vec<[f64; 2]> = Vec::with_capacity(2 * pts.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(pts.iter())
        } else {
            Box::new(pts.iter().rev())
        };
        for &p in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    hull
}

/// Whether `b` hides `a` at each lateral edge of `a`'s cells (lowest, highest azimuth):
/// `b` has a cell within [`OCCLUSION_WINDOW_RAD`] of the edge's azimuth at least
/// [`OCCLUSION_DEPTH_M`] nearer than `a`'s cells there, so `a`'s visible extent ends there
/// because `b` hides the rest and `a` continues behind `b`.
pub fn edge_occlusion(a: &ViewObject, b: &ViewObject) -> [bool; 2] {
    let az = |p: &[f64; 3]| p[1].atan2(p[0]);
    let range = |p: &[f64; 3]| p[0].hypot(p[1]);
    a.cells_azimuth.map(|edge| {
        let near_edge = |p: &&[f64; 3]| (az(p) - edge).abs() <= OCCLUSION_WINDOW_RAD;
        let a_range = a
            .footprint_cells
            .iter()
            .filter(near_edge)
            .map(range)
            .fold(f64::INFINITY, f64::min);
        a_range.is_finite()
            && b.footprint_cells
                .iter()
                .filter(near_edge)
                .any(|p| range(p) + OCCLUSION_DEPTH_M <= a_range)
    })
}
