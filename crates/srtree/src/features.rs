//! Pairwise geometric features of two objects in the frame of a viewpoint (thesis §3.3.2).
//!
//! The viewpoint frame has x along the viewing direction, y to the left and z up, with its
//! origin at the observer. For the ordered pair (a, b) the features are, in order
//! ([`FEATURE_NAMES`]):
//!
//! - distances: between centroids, the minimum between the boxes (of their axis-aligned
//!   hulls in the view frame), the maximum between box corners;
//! - per projected axis x, y, z: the centroid difference and the two interval gaps
//!   `lo_a − hi_b` and `lo_b − hi_a` of the boxes' projections;
//! - overlap percentages: the fraction of a's cells inside the convex hull of b's cells in
//!   the projection along each axis (the y–z, x–z and x–y planes), and the same for b in a;
//! - angular features in cylindrical coordinates about the observer (azimuth, left
//!   positive): the centroid azimuth difference, the lateral-boundary differences
//!   `lo_a − hi_b` and `hi_a − lo_b` of the box corners' azimuth intervals, their centre
//!   difference and overlap as a fraction of the narrower, the same two from the cells'
//!   azimuth extents, and the range differences of the centroids and of the nearest corners;
//! - the top-view distance from a's footprint centre to b's nearest cell;
//! - indicators: a in front, b in front ([`ViewObject::in_front`]), a is ground, b is ground
//!   (street or sidewalk class in the map); the heights of both boxes;
//! - support: a's lowest cell above the median height of b's cells within 2.5 m of a's
//!   footprint centre (5 m if there are none), and the fraction of 8 compass sectors
//!   around a's footprint centre in which b has a cell within 4 m;
//! - contact: from a's contact point (the mean of its cells within [`CONTACT_SLICE_M`] of
//!   its lowest one — a tree's trunk foot rather than its crown's centre) the top-view
//!   distance to b's nearest cell, how much farther that is than the nearest ground
//!   surface of the scene, b's share of the scene's ground cells within
//!   [`CONTACT_RADIUS_M`], a's bottom above b's cells there, and whether b is the nearest
//!   ground surface ([`SubjectContext`] carries the scene's part);
//! - occlusion: the fraction of a's lateral edges (azimuth extremes of its cells) at which
//!   b hides a (b has nearer cells at that azimuth, [`edges_occluded_by`]), and the same of
//!   b's edges by a: what a human reads as "partly hidden behind" where the visible
//!   azimuth extents no longer overlap;
//! - amodal geometry ([`crate::amodal`], from class priors learnt on annotated training
//!   boxes): the azimuth overlap of the completed intervals (each continued behind the
//!   other where the other hides it), the centre and nearest-corner range differences of
//!   the completed boxes, and how far each continues behind the other;
//! - ground under the hidden middle: from a's [`expected_centre`] (its box centre moved
//!   back by the class' amodal centre offset; a tree's trunk foot) the top-view distance to
//!   the convex hull of b's cells within [`LOCAL_GROUND_RADIUS_M`] (a car parked at the kerb
//!   hides the street under and behind it, so the nearest visible ground to its near side
//!   is the sidewalk in front of it, while the street's cells on either side still enclose
//!   its middle), how much farther that is than the nearest ground surface's, and whether b
//!   is that ground surface.
//!
//! Cost per pair: O(|a| log |hull b| + |b|) with objects subsampled to at most
//! [`MAX_FEATURE_CELLS`] cells for the hull tests.

use crate::amodal::{completed_view, hidden_extent_m, ClassPrior, ClassPriors};
pub use crate::view::{
    convex_hull, edge_occlusion, ViewObject, CONTACT_SLICE_M, MAX_FEATURE_CELLS, OCCLUSION_DEPTH_M,
    OCCLUSION_WINDOW_RAD,
};
use crate::SrtreeError;
use geodata::classes::Class;
use geodata::osm::geometry::point_segment_distance;

/// Names of the features, in vector order.
pub const FEATURE_NAMES: [&str; 51] = [
    "centroid_distance",
    "box_distance_min",
    "box_distance_max",
    "centroid_dx",
    "centroid_dy",
    "centroid_dz",
    "gap_x_a_after_b",
    "gap_y_a_after_b",
    "gap_z_a_after_b",
    "gap_x_b_after_a",
    "gap_y_b_after_a",
    "gap_z_b_after_a",
    "a_in_b_hull_yz",
    "a_in_b_hull_xz",
    "a_in_b_hull_xy",
    "b_in_a_hull_yz",
    "b_in_a_hull_xz",
    "b_in_a_hull_xy",
    "azimuth_centroid_diff",
    "azimuth_lo_a_minus_hi_b",
    "azimuth_hi_a_minus_lo_b",
    "azimuth_interval_centre_diff",
    "azimuth_overlap_of_narrower",
    "cells_azimuth_lo_a_minus_hi_b",
    "cells_azimuth_overlap_of_narrower",
    "range_centroid_diff",
    "range_nearest_corner_diff",
    "top_view_distance_to_b",
    "a_in_front",
    "b_in_front",
    "a_ground",
    "b_ground",
    "height_a",
    "height_b",
    "a_bottom_above_b_ground_nearby",
    "b_sectors_around_a",
    "contact_distance_to_b",
    "contact_distance_beyond_nearest_ground",
    "b_share_of_ground_near_contact",
    "a_bottom_above_b_near_contact",
    "b_is_nearest_ground_to_contact",
    "a_edges_occluded_by_b",
    "b_edges_occluded_by_a",
    "amodal_azimuth_overlap_of_narrower",
    "amodal_range_centroid_diff",
    "amodal_range_nearest_corner_diff",
    "hidden_extent_a_behind_b",
    "hidden_extent_b_behind_a",
    "centre_distance_to_b_local_hull",
    "centre_distance_beyond_nearest_ground_hull",
    "b_is_ground_nearest_centre_hull",
];

/// The features that are differences between a and b (centroid offsets, box gaps, azimuth
/// differences, the completed boxes' range differences), whose sign means the same on every
/// city's scale; the visible boxes' range differences are left out, as occlusion biases them
/// and the completed ones estimate the same.
pub const SIGNED_FEATURES: &[usize] = &[3, 4, 5, 6, 7, 8, 9, 10, 11, 18, 19, 20, 21, 23, 44, 45];

/// The features the rules do not test: absolute distances and heights (their thresholds
/// fit one city's scale) and the visible boxes' overlap and range differences (the completed
/// boxes' say the same with occlusion undone).
pub const NOT_IN_RULES: &[usize] = &[0, 1, 2, 22, 25, 26, 32, 33];

/// Number of features.
pub const FEATURE_COUNT: usize = FEATURE_NAMES.len();

/// Radius about the contact point within which ground cells are counted, metres.
pub const CONTACT_RADIUS_M: f64 = 1.0;

/// Radius about a thing's estimated footprint centre within which a ground surface's cells
/// form its local hull ([`local_hull_distance`]), metres: a parked car's length plus the
/// visible ground on either side of it.
pub const LOCAL_GROUND_RADIUS_M: f64 = 6.0;

/// The cap of [`local_hull_distance`] (no cells of the surface within the radius), metres.
pub const LOCAL_HULL_CAP_M: f64 = 10.0;

/// Where `a`'s footprint centre is expected to be, top view: the contact point for round
/// classes (a trunk's foot marks a crown's box), else the estimated box centre moved away
/// from the observer by the class prior's median centre-range offset (the scan sees a
/// thing's near side; the ground under its middle is hidden by the thing itself).
pub fn expected_centre(a: &ViewObject, prior: &ClassPrior) -> [f64; 2] {
    if prior.foot_box.is_some() {
        return [a.contact[0], a.contact[1]];
    }
    let c = a.box_centre;
    let r = c[0].hypot(c[1]);
    if r < 1e-9 {
        return [c[0], c[1]];
    }
    let k = (r + prior.centre_range_offset_m.max(0.0)) / r;
    [c[0] * k, c[1] * k]
}

/// Top-view distance from `p` to the convex hull of `b`'s cells within
/// [`LOCAL_GROUND_RADIUS_M`] of it (0 inside; [`LOCAL_HULL_CAP_M`] with fewer than three such
/// cells): whether `p` lies *within* a ground surface whose cells under and behind a thing
/// are hidden by the thing, where the nearest visible cell may belong to the surface in
/// front of it.
pub fn local_hull_distance(p: [f64; 2], b: &ViewObject) -> f64 {
    let r2 = LOCAL_GROUND_RADIUS_M * LOCAL_GROUND_RADIUS_M;
    let near: Vec<[f64; 2]> = b
        .footprint_cells
        .iter()
        .filter(|q| (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) <= r2)
        .map(|q| [q[0], q[1]])
        .collect();
    if near.len() < 3 {
        return LOCAL_HULL_CAP_M;
    }
    let hull = convex_hull(near);
    if hull.len() < 3 {
        return LOCAL_HULL_CAP_M;
    }
    if in_convex(&hull, p, 0.0) {
        return 0.0;
    }
    (0..hull.len())
        .map(|i| point_segment_distance(p, hull[i], hull[(i + 1) % hull.len()]))
        .fold(f64::INFINITY, f64::min)
        .min(LOCAL_HULL_CAP_M)
}

/// Whether a class is a ground surface (no LeftOf/Behind; things stand on it).
pub fn is_ground(class: Class) -> bool {
    matches!(class, Class::Street | Class::Sidewalk)
}

/// Whether a point lies in a convex counter-clockwise polygon (boundary included, with a
/// tolerance of `tol` metres); degenerate hulls (≤ 2 points) test the distance to them.
pub fn in_convex(hull: &[[f64; 2]], p: [f64; 2], tol: f64) -> bool {
    match hull.len() {
        0 => false,
        1 => (p[0] - hull[0][0]).hypot(p[1] - hull[0][1]) <= tol,
        2 => point_segment_distance(p, hull[0], hull[1]) <= tol,
        n => (0..n).all(|i| {
            let (a, b) = (hull[i], hull[(i + 1) % n]);
            let len = (b[0] - a[0]).hypot(b[1] - a[1]).max(1e-12);
            ((b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])) / len >= -tol
        }),
    }
}

/// Overlap of two intervals as a fraction of the narrower one (a point interval: 1 inside
/// the other, else 0).
fn overlap_of_narrower(a: [f64; 2], b: [f64; 2]) -> f64 {
    let narrower = (a[1] - a[0]).min(b[1] - b[0]);
    if narrower <= 1e-12 {
        let (point, other) = if a[1] - a[0] <= b[1] - b[0] {
            (a, b)
        } else {
            (b, a)
        };
        let m = 0.5 * (point[0] + point[1]);
        return f64::from(u8::from(other[0] <= m && m <= other[1]));
    }
    let overlap = (a[1].min(b[1]) - a[0].max(b[0])).max(0.0);
    (overlap / narrower).min(1.0)
}

/// Horizontal distance from `a`'s contact point to `b`'s nearest cell, metres (capped at 50).
pub fn contact_distance(a: &ViewObject, b: &ViewObject) -> f64 {
    b.footprint_cells
        .iter()
        .map(|q| (q[0] - a.contact[0]).hypot(q[1] - a.contact[1]))
        .fold(f64::INFINITY, f64::min)
        .min(50.0)
}

/// What the pair features of a subject need to know about the rest of its scene: the
/// ground surfaces near its contact point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SubjectContext {
    /// Smallest [`contact_distance`] to any ground surface of the scene (50 if none).
    pub nearest_ground_m: f64,
    /// Ground cells of the scene within [`CONTACT_RADIUS_M`] of the contact point.
    pub ground_cells_near: usize,
    /// Smallest [`local_hull_distance`] from the subject's [`expected_centre`] to any ground
    /// surface of the scene ([`LOCAL_HULL_CAP_M`] if none).
    pub nearest_ground_hull_m: f64,
}

impl SubjectContext {
    /// The context of `objects[a]` among `objects`, with the amodal class priors.
    pub fn new(objects: &[ViewObject], a: usize, priors: &ClassPriors) -> SubjectContext {
        let mut out = SubjectContext {
            nearest_ground_m: 50.0,
            ground_cells_near: 0,
            nearest_ground_hull_m: LOCAL_HULL_CAP_M,
        };
        let Some(subject) = objects.get(a) else {
            return out;
        };
        let centre = expected_centre(subject, &priors.get(subject.class));
        for (g, o) in objects.iter().enumerate() {
            if g == a || !is_ground(o.class) {
                continue;
            }
            out.nearest_ground_m = out.nearest_ground_m.min(contact_distance(subject, o));
            out.ground_cells_near += cells_near_contact(subject, o);
            out.nearest_ground_hull_m = out
                .nearest_ground_hull_m
                .min(local_hull_distance(centre, o));
        }
        out
    }
}

fn cells_near_contact(a: &ViewObject, b: &ViewObject) -> usize {
    b.footprint_cells
        .iter()
        .filter(|q| (q[0] - a.contact[0]).hypot(q[1] - a.contact[1]) <= CONTACT_RADIUS_M)
        .count()
}

/// Fraction (0, ½, 1) of the two lateral edges of `a`'s cells at which `b` hides `a`
/// ([`edge_occlusion`]).
pub fn edges_occluded_by(a: &ViewObject, b: &ViewObject) -> f64 {
    edge_share(edge_occlusion(a, b))
}

/// Fraction (0, ½, 1) of two edges that are set.
fn edge_share(e: [bool; 2]) -> f64 {
    f64::from(u8::from(e[0]) + u8::from(e[1])) / 2.0
}

/// The feature vector of the ordered pair (a, b); `context` is `a`'s [`SubjectContext`],
/// `priors` the amodal class priors.
pub fn pair_features(
    a: &ViewObject,
    b: &ViewObject,
    context: &SubjectContext,
    priors: &ClassPriors,
    tol_m: f64,
) -> [f64; FEATURE_COUNT] {
    let mut f = [0.0; FEATURE_COUNT];
    let d3 = |p: [f64; 3], q: [f64; 3]| {
        ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
    };
    f[0] = d3(a.centroid, b.centroid);
    let gap: Vec<f64> = (0..3)
        .map(|k| (a.lo[k] - b.hi[k]).max(b.lo[k] - a.hi[k]).max(0.0))
        .collect();
    f[1] = (gap[0] * gap[0] + gap[1] * gap[1] + gap[2] * gap[2]).sqrt();
    f[2] = a
        .corners
        .iter()
        .flat_map(|&p| b.corners.iter().map(move |&q| d3(p, q)))
        .fold(0.0, f64::max);
    for k in 0..3 {
        f[3 + k] = a.centroid[k] - b.centroid[k];
        f[6 + k] = a.lo[k] - b.hi[k];
        f[9 + k] = b.lo[k] - a.hi[k];
    }
    let planes = [(1, 2), (0, 2), (0, 1)];
    for (h, (i, j)) in planes.into_iter().enumerate() {
        let frac = |x: &ViewObject, y: &ViewObject| {
            let inside = x
                .cells
                .iter()
                .filter(|p| in_convex(&y.hulls[h], [p[i], p[j]], tol_m))
                .count();
            inside as f64 / x.cells.len().max(1) as f64
        };
        f[12 + h] = frac(a, b);
        f[15 + h] = frac(b, a);
    }
    let az = |p: [f64; 3]| p[1].atan2(p[0]);
    f[18] = az(a.centroid) - az(b.centroid);
    f[19] = a.azimuth[0] - b.azimuth[1];
    f[20] = a.azimuth[1] - b.azimuth[0];
    f[21] = 0.5 * (a.azimuth[0] + a.azimuth[1]) - 0.5 * (b.azimuth[0] + b.azimuth[1]);
    f[22] = overlap_of_narrower(a.azimuth, b.azimuth);
    f[23] = a.cells_azimuth[0] - b.cells_azimuth[1];
    f[24] = overlap_of_narrower(a.cells_azimuth, b.cells_azimuth);
    f[25] = a.box_centre[0].hypot(a.box_centre[1]) - b.box_centre[0].hypot(b.box_centre[1]);
    f[26] = a.near_range - b.near_range;
    f[27] = b
        .footprint_cells
        .iter()
        .map(|q| (q[0] - a.box_centre[0]).hypot(q[1] - a.box_centre[1]))
        .fold(f64::INFINITY, f64::min)
        .min(50.0);
    f[28] = f64::from(u8::from(a.in_front()));
    f[29] = f64::from(u8::from(b.in_front()));
    f[30] = f64::from(u8::from(is_ground(a.class)));
    f[31] = f64::from(u8::from(is_ground(b.class)));
    f[32] = a.hi[2] - a.lo[2];
    f[33] = b.hi[2] - b.lo[2];
    let c = a.box_centre;
    let mut near_z: Vec<f64> = Vec::new();
    let mut sectors = [false; 8];
    for q in &b.footprint_cells {
        let (dx, dy) = (q[0] - c[0], q[1] - c[1]);
        let d = dx.hypot(dy);
        if d <= 2.5 {
            near_z.push(q[2]);
        }
        if d <= 4.0 {
            let s = ((dy.atan2(dx) + std::f64::consts::PI) / (std::f64::consts::PI / 4.0)) as usize;
            sectors[s.min(7)] = true;
        }
    }
    f[34] = if near_z.is_empty() || !a.bottom.is_finite() {
        5.0
    } else {
        near_z.sort_by(f64::total_cmp);
        (a.bottom - near_z[near_z.len() / 2]).clamp(-5.0, 5.0)
    };
    f[35] = sectors.iter().filter(|&&s| s).count() as f64 / 8.0;
    let contact_m = contact_distance(a, b);
    f[36] = contact_m;
    f[37] = (contact_m - context.nearest_ground_m).clamp(0.0, 50.0);
    let near = cells_near_contact(a, b);
    f[38] = if context.ground_cells_near > 0 {
        near as f64 / context.ground_cells_near as f64
    } else {
        0.0
    };
    let mut near_z: Vec<f64> = b
        .footprint_cells
        .iter()
        .filter(|q| (q[0] - a.contact[0]).hypot(q[1] - a.contact[1]) <= CONTACT_RADIUS_M)
        .map(|q| q[2])
        .collect();
    f[39] = if near_z.is_empty() || !a.bottom.is_finite() {
        1.0
    } else {
        near_z.sort_by(f64::total_cmp);
        (a.bottom - near_z[near_z.len() / 2]).clamp(-1.0, 1.0)
    };
    f[40] = f64::from(u8::from(
        is_ground(b.class) && contact_m <= context.nearest_ground_m,
    ));
    let (a_by_b, b_by_a) = (edge_occlusion(a, b), edge_occlusion(b, a));
    f[41] = edge_share(a_by_b);
    f[42] = edge_share(b_by_a);
    let (pa, pb) = (priors.get(a.class), priors.get(b.class));
    let (va, vb) = (
        completed_view(a, a_by_b, &pa),
        completed_view(b, b_by_a, &pb),
    );
    f[43] = overlap_of_narrower(va.azimuth, vb.azimuth);
    f[44] = va.centre_range - vb.centre_range;
    f[45] = va.near_range - vb.near_range;
    let behind = |o: &ViewObject, e: [bool; 2], p| {
        if e[0] || e[1] {
            hidden_extent_m(o, p).min(50.0)
        } else {
            0.0
        }
    };
    f[46] = behind(a, a_by_b, &pa);
    f[47] = behind(b, b_by_a, &pb);
    let hull_m = if is_ground(b.class) {
        local_hull_distance(expected_centre(a, &pa), b)
    } else {
        LOCAL_HULL_CAP_M
    };
    f[48] = hull_m;
    f[49] = (hull_m - context.nearest_ground_hull_m).clamp(0.0, LOCAL_HULL_CAP_M);
    f[50] = f64::from(u8::from(
        is_ground(b.class) && hull_m <= context.nearest_ground_hull_m && hull_m < LOCAL_HULL_CAP_M,
    ));
    f
}

/// Feature scaling learnt on training vectors: standardisation (clipped to ±5) plus
/// thermometer indicators `[x > t]` at the training deciles of each feature, so that the
/// linear classifier can place thresholds (an additive model over the features).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FeatureScaler {
    /// Mean per raw feature.
    pub mean: Vec<f64>,
    /// Standard deviation per raw feature (1 where constant).
    pub std: Vec<f64>,
    /// Thresholds per raw feature (distinct training deciles).
    pub thresholds: Vec<Vec<f64>>,
}

impl FeatureScaler {
    /// Learns the scaling from raw training vectors.
    pub fn fit(raw: &[[f64; FEATURE_COUNT]]) -> Result<FeatureScaler, SrtreeError> {
        if raw.is_empty() {
            return Err(SrtreeError::Training {
                relation: "all".into(),
                message: "no training pairs".into(),
            });
        }
        let n = raw.len() as f64;
        let mut mean = vec![0.0; FEATURE_COUNT];
        let mut std = vec![0.0; FEATURE_COUNT];
        let mut thresholds = Vec::with_capacity(FEATURE_COUNT);
        for k in 0..FEATURE_COUNT {
            let mut col: Vec<f64> = raw.iter().map(|v| v[k]).collect();
            mean[k] = col.iter().sum::<f64>() / n;
            let var = col.iter().map(|v| (v - mean[k]).powi(2)).sum::<f64>() / n;
            std[k] = if var > 1e-18 { var.sqrt() } else { 1.0 };
            col.sort_by(f64::total_cmp);
            let mut t: Vec<f64> = (1..10).map(|q| col[(col.len() - 1) * q / 10]).collect();
            t.dedup();
            // A threshold at the maximum never fires.
            t.retain(|&x| x < col[col.len() - 1]);
            thresholds.push(t);
        }
        Ok(FeatureScaler {
            mean,
            std,
            thresholds,
        })
    }

    /// Length of a scaled vector.
    pub fn dims(&self) -> usize {
        FEATURE_COUNT + self.thresholds.iter().map(Vec::len).sum::<usize>()
    }

    /// The scaled vector of a raw one.
    pub fn scale(&self, raw: &[f64; FEATURE_COUNT]) -> Vec<f32> {
        let mut out = Vec::with_capacity(self.dims());
        for ((&v, &m), &s) in raw.iter().zip(&self.mean).zip(&self.std) {
            out.push((((v - m) / s).clamp(-5.0, 5.0)) as f32);
        }
        for (k, ts) in self.thresholds.iter().enumerate() {
            out.extend(ts.iter().map(|&t| f32::from(u8::from(raw[k] > t))));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::Viewpoint;
    use crate::objects::OrientedBox;

    #[test]
    fn hull_and_containment() {
        let hull = convex_hull(vec![
            [0.0, 0.0],
            [1.0, 0.0],
            [1.0, 1.0],
            [0.0, 1.0],
            [0.5, 0.5],
            [0.5, 0.0],
        ]);
        assert_eq!(hull.len(), 4);
        assert!(in_convex(&hull, [0.5, 0.5], 0.0));
        assert!(in_convex(&hull, [1.0, 0.5], 1e-9));
        assert!(!in_convex(&hull, [1.2, 0.5], 0.1));
        assert!(in_convex(&[[0.0, 0.0], [1.0, 0.0]], [0.5, 0.05], 0.1));
    }

    fn object(id: u32, x: f64, y: f64, class: Class) -> ViewObject {
        let vp = Viewpoint {
            position: [0.0, 0.0, 0.0],
            yaw_rad: 0.0,
        };
        let cells: Vec<[f64; 3]> = (0..10)
            .flat_map(|i| {
                (0..10).map(move |j| [x - 0.5 + 0.1 * i as f64, y - 0.5 + 0.1 * j as f64, 0.5])
            })
            .collect();
        let bbox = OrientedBox {
            centre: [x, y, 0.5],
            half_extents: [0.5, 0.5, 0.5],
            yaw_rad: 0.0,
        };
        ViewObject::new(id, class, &cells, &bbox, &vp)
    }

    #[test]
    fn left_and_behind_features_have_the_right_signs() {
        let left = object(1, 10.0, 5.0, Class::Car);
        let right = object(2, 10.0, -5.0, Class::Car);
        let none = SubjectContext {
            nearest_ground_m: 50.0,
            ground_cells_near: 0,
            nearest_ground_hull_m: LOCAL_HULL_CAP_M,
        };
        let f = pair_features(&left, &right, &none, &ClassPriors::default(), 0.05);
        assert!(f[19] > 0.0, "a's right boundary is left of b's left one");
        assert_eq!(f[22], 0.0);
        assert!((f[0] - 10.0).abs() < 1e-9);
        assert!((f[4] - 10.0).abs() < 1e-9);
        let far = object(3, 20.0, 0.0, Class::Car);
        let near = object(4, 8.0, 0.0, Class::Car);
        let f = pair_features(&far, &near, &none, &ClassPriors::default(), 0.05);
        assert!(f[22] > 0.99 && f[25] > 11.0 && f[26] > 11.0);
        assert!(
            f[12] > 0.99,
            "far is hidden behind near in the y-z projection"
        );
        assert_eq!([f[28], f[29], f[30]], [1.0, 1.0, 0.0]);
    }

    /// A vertical plate of cells from azimuth `az0` to `az1` (radians) at `range_m`.
    fn plate(id: u32, range_m: f64, az0: f64, az1: f64) -> ViewObject {
        let vp = Viewpoint {
            position: [0.0, 0.0, 0.0],
            yaw_rad: 0.0,
        };
        let cells: Vec<[f64; 3]> = (0..=40)
            .flat_map(|i| {
                let az = az0 + (az1 - az0) * f64::from(i) / 40.0;
                (0..5).map(move |k| [range_m * az.cos(), range_m * az.sin(), 0.2 * f64::from(k)])
            })
            .collect();
        let bbox = OrientedBox {
            centre: [range_m, 0.5 * range_m * (az0 + az1), 0.5],
            half_extents: [0.1, 0.5 * range_m * (az1 - az0), 0.5],
            yaw_rad: 0.0,
        };
        ViewObject::new(id, Class::Building, &cells, &bbox, &vp)
    }

    #[test]
    fn occlusion_edges_need_a_nearer_neighbour_at_the_edge() {
        // The far plate's visible part ends where the near one begins (it continues behind).
        let far = plate(1, 20.0, 0.0, 0.2);
        let near = plate(2, 10.0, 0.2, 0.4);
        assert_eq!(edges_occluded_by(&far, &near), 0.5);
        assert_eq!(
            edges_occluded_by(&near, &far),
            0.0,
            "the far plate hides nothing"
        );
        // A nearer plate away from the edges hides neither edge.
        let aside = plate(3, 10.0, 0.3, 0.4);
        assert_eq!(edges_occluded_by(&far, &aside), 0.0);
        // Both edges hidden: the far plate seen through a gap between two near ones.
        let left = plate(4, 10.0, -0.2, 0.0);
        let mut both = near.clone();
        both.footprint_cells
            .extend(left.footprint_cells.iter().copied());
        assert_eq!(edges_occluded_by(&far, &both), 1.0);
    }

    #[test]
    fn a_car_at_the_kerb_stands_in_the_street_behind_it() {
        // Seen from the sidewalk (x 1–5 m), a car parked at the kerb (x = 5 m) shows its near
        // side; the street under and behind it (x 5–12 m) is in its shadow, so the nearest
        // visible ground to its foot is the sidewalk. Its expected centre lies in the street.
        let vp = Viewpoint {
            position: [0.0, 0.0, 0.0],
            yaw_rad: 0.0,
        };
        let grid = |x0: f64, x1: f64, keep: &dyn Fn(f64, f64) -> bool| -> Vec<[f64; 3]> {
            let mut v = Vec::new();
            for i in 0..=((x1 - x0) / 0.25) as i32 {
                for j in -40..=40 {
                    let (x, y) = (x0 + 0.25 * f64::from(i), 0.25 * f64::from(j));
                    if keep(x, y) {
                        v.push([x, y, 0.0]);
                    }
                }
            }
            v
        };
        let ground = |id, cells: Vec<[f64; 3]>, x0: f64, x1: f64, class| {
            let bbox = OrientedBox {
                centre: [0.5 * (x0 + x1), 0.0, 0.0],
                half_extents: [0.5 * (x1 - x0), 10.0, 0.05],
                yaw_rad: 0.0,
            };
            ViewObject::new(id, class, &cells, &bbox, &vp)
        };
        let shadow = |x: f64, y: f64| x > 5.3 && y.abs() < 2.25 * x / 5.3;
        let sidewalk = ground(2, grid(1.0, 5.0, &|_, _| true), 1.0, 5.0, Class::Sidewalk);
        let street = ground(
            3,
            grid(5.35, 12.0, &|x, y| !shadow(x, y)),
            5.0,
            12.0,
            Class::Street,
        );
        let car_cells: Vec<[f64; 3]> = (0..=18)
            .flat_map(|j| {
                (1..=6).map(move |k| [5.3, -2.25 + 0.25 * f64::from(j), 0.25 * f64::from(k)])
            })
            .collect();
        let bbox = OrientedBox {
            centre: [5.5, 0.0, 0.75],
            half_extents: [0.2, 2.25, 0.75],
            yaw_rad: 0.0,
        };
        let car = ViewObject::new(1, Class::Car, &car_cells, &bbox, &vp);
        let mut priors = ClassPriors::default();
        priors.classes[usize::from(Class::Car.id())].centre_range_offset_m = 0.7;
        let centre = expected_centre(&car, &priors.get(Class::Car));
        assert!((centre[0] - 6.2).abs() < 1e-9 && centre[1].abs() < 1e-9);
        assert_eq!(local_hull_distance(centre, &street), 0.0);
        assert!((local_hull_distance(centre, &sidewalk) - 1.2).abs() < 1e-9);
        let objects = vec![car, sidewalk, street];
        let context = SubjectContext::new(&objects, 0, &priors);
        let [on_sidewalk, on_street] =
            [1, 2].map(|b| pair_features(&objects[0], &objects[b], &context, &priors, 0.05));
        // The contact point's nearest ground is the sidewalk, the centre's hull the street.
        assert_eq!((on_sidewalk[40], on_street[40]), (1.0, 0.0));
        assert_eq!((on_sidewalk[50], on_street[50]), (0.0, 1.0));
        assert_eq!(on_street[49], 0.0);
        assert!(on_sidewalk[49] > 1.0);
        // Too few cells of a surface within the radius: the cap.
        assert_eq!(
            local_hull_distance([40.0, 0.0], &objects[2]),
            LOCAL_HULL_CAP_M
        );
    }

    #[test]
    fn contact_point_is_the_foot_and_picks_the_nearest_ground() {
        let vp = Viewpoint {
            position: [0.0, 0.0, 0.0],
            yaw_rad: 0.0,
        };
        // A "tree": trunk cells at (10, 0), crown cells spread towards (10, -3).
        let mut cells: Vec<[f64; 3]> = (0..20).map(|k| [10.0, 0.0, 0.1 * f64::from(k)]).collect();
        cells.extend((0..40).map(|k| [10.0, -0.075 * f64::from(k), 3.0]));
        let bbox = OrientedBox {
            centre: [10.0, -1.5, 1.5],
            half_extents: [0.5, 1.5, 1.5],
            yaw_rad: 0.0,
        };
        let tree = ViewObject::new(1, Class::Tree, &cells, &bbox, &vp);
        assert!((tree.contact[0] - 10.0).abs() < 1e-9 && tree.contact[1].abs() < 1e-9);
        let ground = |id, y0: f64, y1: f64, class| {
            let cells: Vec<[f64; 3]> = (0..20)
                .flat_map(|i| {
                    (0..20).map(move |j| {
                        [
                            8.0 + 0.2 * f64::from(i),
                            y0 + (y1 - y0) * f64::from(j) / 19.0,
                            0.0,
                        ]
                    })
                })
                .collect();
            let bbox = OrientedBox {
                centre: [10.0, 0.5 * (y0 + y1), 0.0],
                half_extents: [2.0, 0.5 * (y1 - y0).abs(), 0.05],
                yaw_rad: 0.0,
            };
            ViewObject::new(id, class, &cells, &bbox, &vp)
        };
        // The sidewalk under the trunk, the street under the crown.
        let objects = vec![
            tree,
            ground(2, -0.5, 1.5, Class::Sidewalk),
            ground(3, -4.0, -0.7, Class::Street),
        ];
        let none = ClassPriors::default();
        let context = SubjectContext::new(&objects, 0, &none);
        let [on_sidewalk, on_street] =
            [1, 2].map(|b| pair_features(&objects[0], &objects[b], &context, &none, 0.05));
        assert_eq!((on_sidewalk[40], on_street[40]), (1.0, 0.0));
        assert!(on_sidewalk[38] > on_street[38]);
        assert_eq!(on_sidewalk[37], 0.0);
        assert!(on_street[37] > 0.5);
    }

    #[test]
    fn scaler_adds_decile_indicators() {
        let raw: Vec<[f64; FEATURE_COUNT]> = (0..100)
            .map(|i| {
                let mut v = [0.0; FEATURE_COUNT];
                v[0] = i as f64;
                v
            })
            .collect();
        let s = FeatureScaler::fit(&raw).unwrap();
        assert_eq!(s.thresholds[0].len(), 9);
        assert!(s.thresholds[1].is_empty());
        let x = s.scale(&raw[55]);
        assert_eq!(x.len(), FEATURE_COUNT + 9);
        let on: f32 = x[FEATURE_COUNT..].iter().sum();
        assert_eq!(on, 5.0);
    }
}
