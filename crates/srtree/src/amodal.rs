//! Amodal completion: how far an object extends beyond what the scan shows of it, from
//! class priors learnt on the annotated boxes of the training scenes.
//!
//! A scan sees the near side of a thing, and of a thing partly hidden behind another only
//! the uncovered part; an annotator's box (and with it the thesis' relations, which are
//! defined on boxes) covers the whole thing. Per class, [`ClassPriors::learn`] measures on
//! the training objects
//!
//! - how much farther the annotated box's centre and nearest corner are than the
//!   estimated box's (median over objects: 5 m for buildings, whose depth the scan never
//!   sees, 1.2 m for trees, 0.3 m for cars),
//! - how much wider the annotated box's azimuth interval is at an edge where nothing
//!   hides the object (the box corners of a round crown lie outside its visible outline),
//! - the median footprint of the annotated boxes (long × short side).
//!
//! Classes whose annotated boxes are squares in one map orientation about the thing's foot
//! (tree crowns: the trunk marks the centre, the visible crown width the side) get their
//! box predicted from the contact point instead ([`FootBox`]).
//!
//! At an edge where a nearer object hides the object's cells ([`crate::view::edge_occlusion`])
//! the object is assumed to continue behind it until its lateral extent reaches that of
//! the class' median footprint at the estimated yaw ([`hidden_extent_m`]).
//!
//! A building whose cells stand in outlines of the robot's map ([`MapOutlines`], e.g. its
//! OSM buildings) is completed from them instead: its box is the outlines' bounding
//! rectangle along the longest edge, the convention its annotated boxes follow
//! (`geodata::osm::geometry::longest_edge_box`). The scan sees a façade; the map knows how
//! deep the building is, which no per-class constant does across cities (median depth
//! behind the estimated centre: 5 m on the embedded city, 22 m in Helsinki, 28 m at KTH).
//!
//! Only training scenes' annotations are read; inference uses the learnt priors and the
//! map alone.

pub use crate::boxes::{AnnotatedBox, BoxView, MapOutlines, OUTLINE_MATCH_M, OUTLINE_SHARE};
use crate::graph::Viewpoint;
use crate::view::ViewObject;
use geodata::classes::Class;
use serde::{Deserialize, Serialize};

/// Fewer annotated objects of a class than this leave its prior at zero (no completion).
pub const MIN_PRIOR_SAMPLES: usize = 5;

/// What the annotated boxes of one class add to the estimated ones.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct ClassPrior {
    /// Annotated objects the prior was learnt from.
    pub samples: usize,
    /// Median of annotated minus estimated box centre range, metres.
    pub centre_range_offset_m: f64,
    /// Median of annotated minus estimated nearest footprint corner range, metres.
    pub near_range_offset_m: f64,
    /// Median widening of the azimuth interval at an edge nothing hides, metres at the
    /// estimated centre's range.
    pub free_widening_m: f64,
    /// Median footprint of the annotated boxes, long and short side, metres.
    pub footprint_m: [f64; 2],
    /// Mean share of the [`hidden_extent_m`] by which the annotated box's azimuth
    /// interval is wider at an edge another object hides.
    pub hidden_fraction: f64,
    /// Set if the class' annotated boxes are squares about the thing's foot in fixed map
    /// axes (round things such as tree crowns): the box is then predicted from the foot.
    #[serde(default)]
    pub foot_box: Option<FootBox>,
}

/// How annotated boxes of a round class sit: a square about the contact point (a trunk's
/// foot) whose side follows the visible width, in fixed map axes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct FootBox {
    /// Yaw of the annotated boxes in the map frame, radians (modulo a quarter turn).
    pub map_yaw_rad: f64,
    /// Median ratio of the annotated half side to half the visible width (the cells'
    /// azimuth extent at the contact point's range).
    pub half_side_ratio: f64,
}

/// Half the visible width of an object at its contact point's range, metres.
fn visible_half_width(o: &ViewObject) -> f64 {
    0.5 * (o.cells_azimuth[1] - o.cells_azimuth[0]) * o.contact[0].hypot(o.contact[1])
}

impl FootBox {
    /// The predicted box of `o` in its view frame.
    pub fn predict(&self, o: &ViewObject) -> AnnotatedBox {
        let half = self.half_side_ratio * visible_half_width(o);
        AnnotatedBox {
            centre: o.contact,
            half_extents: [half, half, 0.0],
            yaw_rad: self.map_yaw_rad - o.view_yaw_rad,
        }
    }
}

/// The view frame itself as a viewpoint (boxes already in view coordinates).
const VIEW_FRAME: Viewpoint = Viewpoint {
    position: [0.0; 3],
    yaw_rad: 0.0,
};

/// How `a`'s annotated box is expected to look given which of its edges `b` hides: the box
/// of its map outlines if it has one, the foot box for round classes, else the estimated
/// box completed by the class prior.
pub fn completed_view(a: &ViewObject, occluded_by_b: [bool; 2], prior: &ClassPrior) -> BoxView {
    if let Some(b) = &a.map_box {
        return b.view(&VIEW_FRAME);
    }
    if let Some(foot) = &prior.foot_box {
        return foot.predict(a).view(&VIEW_FRAME);
    }
    BoxView {
        azimuth: completed_azimuth(a, occluded_by_b, prior),
        near_range: a.near_range + prior.near_range_offset_m,
        centre_range: a.centre_range() + prior.centre_range_offset_m,
    }
}

/// One [`ClassPrior`] per class (indexed by class id).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ClassPriors {
    /// Priors by class id; classes without enough samples are all zero.
    pub classes: Vec<ClassPrior>,
}

impl Default for ClassPriors {
    fn default() -> Self {
        ClassPriors {
            classes: vec![ClassPrior::default(); Class::COUNT],
        }
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

impl ClassPriors {
    /// The prior of a class (zero if none was learnt).
    pub fn get(&self, class: Class) -> ClassPrior {
        self.classes
            .get(usize::from(class.id()))
            .copied()
            .unwrap_or_default()
    }

    /// Learns the priors from scenes' objects with their annotated boxes (`None`: not annotated).
    pub fn learn<'a>(
        scenes: impl IntoIterator<Item = (&'a Viewpoint, &'a [ViewObject], &'a [Option<AnnotatedBox>])>,
    ) -> ClassPriors {
        #[derive(Default)]
        struct Acc {
            centre: Vec<f64>,
            near: Vec<f64>,
            free: Vec<f64>,
            long: Vec<f64>,
            short: Vec<f64>,
            /// Widening at edges another object hides, metres at the centre's range, and
            /// the object (scene, index).
            occluded: Vec<(f64, usize, usize)>,
            /// Annotated yaw times 4 as a unit vector (a square's yaw is modulo π/2).
            yaw4: [f64; 2],
            /// Side difference of the annotated footprint over its longer side.
            squareness: Vec<f64>,
            /// Top-view distance of the annotated centre to the contact point, and to the
            /// estimated box centre (as estimated, without the range offset).
            to_foot: Vec<f64>,
            to_centre: Vec<f64>,
            /// Annotated half side over half the visible width.
            half_ratio: Vec<f64>,
        }
        let scenes: Vec<_> = scenes.into_iter().collect();
        let mut acc: Vec<Acc> = (0..Class::COUNT).map(|_| Acc::default()).collect();
        for (scene, &(viewpoint, objects, boxes)) in scenes.iter().enumerate() {
            for (i, (o, b)) in objects.iter().zip(boxes).enumerate() {
                let Some(b) = b else { continue };
                let Some(a) = acc.get_mut(usize::from(o.class.id())) else {
                    continue;
                };
                let truth = b.view(viewpoint);
                let range = o.centre_range();
                if !(truth.centre_range.is_finite() && range.is_finite()) {
                    continue;
                }
                a.centre.push(truth.centre_range - range);
                a.near.push(truth.near_range - o.near_range);
                let mut occluded = [false; 2];
                for (j, other) in objects.iter().enumerate() {
                    if j != i {
                        let e = crate::view::edge_occlusion(o, other);
                        occluded = [occluded[0] || e[0], occluded[1] || e[1]];
                    }
                }
                let widening = [
                    (o.azimuth[0] - truth.azimuth[0]) * range,
                    (truth.azimuth[1] - o.azimuth[1]) * range,
                ];
                for k in 0..2 {
                    if occluded[k] {
                        a.occluded.push((widening[k], scene, i));
                    } else {
                        a.free.push(widening[k]);
                    }
                }
                let (h0, h1) = (b.half_extents[0], b.half_extents[1]);
                a.long.push(2.0 * h0.max(h1));
                a.short.push(2.0 * h0.min(h1));
                a.yaw4[0] += (4.0 * b.yaw_rad).cos();
                a.yaw4[1] += (4.0 * b.yaw_rad).sin();
                a.squareness.push((h0 - h1).abs() / h0.max(h1).max(1e-9));
                let c = viewpoint.to_view(b.centre);
                let top = |p: [f64; 3]| (p[0] - c[0]).hypot(p[1] - c[1]);
                a.to_foot.push(top(o.contact));
                a.to_centre.push(top(o.box_centre));
                let visible = visible_half_width(o);
                if visible > 1e-3 {
                    a.half_ratio.push(h0.max(h1) / visible);
                }
            }
        }
        ClassPriors {
            classes: acc
                .into_iter()
                .map(|a| {
                    let samples = a.centre.len();
                    if samples < MIN_PRIOR_SAMPLES {
                        return ClassPrior::default();
                    }
                    let mut prior = ClassPrior {
                        samples,
                        centre_range_offset_m: median(a.centre),
                        near_range_offset_m: median(a.near),
                        free_widening_m: median(a.free),
                        footprint_m: [median(a.long), median(a.short)],
                        hidden_fraction: 0.0,
                        foot_box: None,
                    };
                    // Round things: square boxes in one map orientation about the foot.
                    let concentration = a.yaw4[0].hypot(a.yaw4[1]) / samples as f64;
                    if median(a.squareness) < 0.05
                        && concentration >= 0.95
                        && median(a.to_foot) < median(a.to_centre)
                    {
                        prior.foot_box = Some(FootBox {
                            map_yaw_rad: 0.25 * a.yaw4[1].atan2(a.yaw4[0]),
                            half_side_ratio: median(a.half_ratio),
                        });
                    }
                    // Edges with at least 0.5 m hidden by the footprint prior.
                    let ratios: Vec<f64> = a
                        .occluded
                        .iter()
                        .filter_map(|&(w, s, i)| {
                            let hidden = hidden_extent_m(&scenes[s].1[i], &prior);
                            (hidden >= 0.5).then(|| (w / hidden).clamp(0.0, 1.0))
                        })
                        .collect();
                    prior.hidden_fraction = if ratios.is_empty() {
                        0.0
                    } else {
                        ratios.iter().sum::<f64>() / ratios.len() as f64
                    };
                    prior
                })
                .collect(),
        }
    }
}

/// How much wider than its visible cells an object of the class' median footprint would
/// appear at the object's estimated yaw and range, metres (0 if no wider).
pub fn hidden_extent_m(o: &ViewObject, prior: &ClassPrior) -> f64 {
    let c = &o.corners;
    let axis = |p: [f64; 3], q: [f64; 3]| {
        let d = [q[0] - p[0], q[1] - p[1]];
        let len = d[0].hypot(d[1]);
        if len > 1e-9 {
            (len, [d[0] / len, d[1] / len])
        } else {
            (0.0, [1.0, 0.0])
        }
    };
    let ((l0, u0), (l1, u1)) = (axis(c[0], c[1]), axis(c[1], c[2]));
    let (long, short) = if l0 >= l1 { (u0, u1) } else { (u1, u0) };
    let range = o.centre_range();
    if range <= 1e-9 {
        return 0.0;
    }
    let across = [-o.box_centre[1] / range, o.box_centre[0] / range];
    let dot = |u: [f64; 2]| (u[0] * across[0] + u[1] * across[1]).abs();
    let expected = prior.footprint_m[0] * dot(long) + prior.footprint_m[1] * dot(short);
    let visible = (o.cells_azimuth[1] - o.cells_azimuth[0]) * range;
    (expected - visible).max(0.0)
}

/// The azimuth interval `a`'s whole box is expected to span given `b`: widened at an edge
/// `b` hides by the hidden extent, at other edges by the class' free widening.
pub fn completed_azimuth(a: &ViewObject, occluded_by_b: [bool; 2], prior: &ClassPrior) -> [f64; 2] {
    let range = a.centre_range().max(1e-9);
    let hidden = hidden_extent_m(a, prior);
    let widen = |occluded: bool| {
        if occluded {
            (prior.hidden_fraction * hidden).max(prior.free_widening_m)
        } else {
            prior.free_widening_m
        }
    };
    let lo = a.azimuth[0] - widen(occluded_by_b[0]) / range;
    let hi = a.azimuth[1] + widen(occluded_by_b[1]) / range;
    if lo <= hi {
        [lo, hi]
    } else {
        let m = 0.5 * (a.azimuth[0] + a.azimuth[1]);
        [m, m]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::objects::OrientedBox;

    fn vp() -> Viewpoint {
        Viewpoint {
            position: [0.0; 3],
            yaw_rad: 0.0,
        }
    }

    /// A car's near side: cells along y at x = `x`, from y0 to y1.
    fn side(id: u32, x: f64, y0: f64, y1: f64) -> ViewObject {
        let mut cells = Vec::new();
        let mut y = y0;
        while y <= y1 + 1e-9 {
            for z in [0.3, 0.6, 0.9] {
                cells.push([x, y, z]);
            }
            y += 0.1;
        }
        let bbox = OrientedBox {
            centre: [x + 0.05, 0.5 * (y0 + y1), 0.6],
            half_extents: [0.5 * (y1 - y0), 0.05, 0.3],
            yaw_rad: std::f64::consts::FRAC_PI_2,
        };
        ViewObject::new(id, Class::Car, &cells, &bbox, &vp())
    }

    #[test]
    fn annotated_box_view_matches_its_corners() {
        let b = AnnotatedBox {
            centre: [10.0, 0.0, 1.0],
            half_extents: [1.0, 2.0, 1.0],
            yaw_rad: 0.0,
        };
        let v = b.view(&vp());
        assert!((v.centre_range - 10.0).abs() < 1e-12);
        assert!((v.near_range - 9.0f64.hypot(2.0)).abs() < 1e-12);
        assert!((v.azimuth[1] - 2.0f64.atan2(9.0)).abs() < 1e-12);
        assert!((v.azimuth[0] + 2.0f64.atan2(9.0)).abs() < 1e-12);
    }

    #[test]
    fn priors_recover_a_constant_offset_and_footprint() {
        // Every car is seen by its near side only; the annotated box is 1.8 m deep.
        let objects: Vec<ViewObject> = (0..6)
            .map(|i| {
                side(
                    i,
                    10.0 + f64::from(i),
                    -10.0 + 4.0 * f64::from(i),
                    -7.0 + 4.0 * f64::from(i),
                )
            })
            .collect();
        let boxes: Vec<Option<AnnotatedBox>> = objects
            .iter()
            .map(|o| {
                Some(AnnotatedBox {
                    centre: [o.box_centre[0] + 0.9, o.box_centre[1], 0.75],
                    half_extents: [1.5, 0.9, 0.75],
                    yaw_rad: std::f64::consts::FRAC_PI_2,
                })
            })
            .collect();
        let v = vp();
        let priors = ClassPriors::learn([(&v, &objects[..], &boxes[..])]);
        let car = priors.get(Class::Car);
        assert_eq!(car.samples, 6);
        assert!(
            (car.footprint_m[0] - 3.0).abs() < 1e-12 && (car.footprint_m[1] - 1.8).abs() < 1e-12
        );
        // The box centre moved 0.9 m along x: about 0.9 m farther.
        assert!((car.centre_range_offset_m - 0.9).abs() < 0.1, "{car:?}");
        assert_eq!(priors.get(Class::Tree), ClassPrior::default());
        // Oblong boxes: no foot box.
        assert_eq!(car.foot_box, None);
    }

    /// A tree at (x, y): a trunk column and the near half of a crown ring of radius r.
    fn tree(id: u32, x: f64, y: f64, r: f64) -> ViewObject {
        let mut cells: Vec<[f64; 3]> = (0..30).map(|k| [x, y, 0.1 * f64::from(k)]).collect();
        let towards = (-y).atan2(-x);
        for k in 0..=60 {
            let t =
                towards - std::f64::consts::FRAC_PI_2 + std::f64::consts::PI * f64::from(k) / 60.0;
            cells.push([x + r * t.cos(), y + r * t.sin(), 4.0]);
        }
        // The estimated box covers the visible near half: its centre is nearer than the trunk.
        let range = x.hypot(y);
        let bbox = OrientedBox {
            centre: [x - 0.5 * r * x / range, y - 0.5 * r * y / range, 2.0],
            half_extents: [r, 0.5 * r, 2.0],
            yaw_rad: y.atan2(x) + std::f64::consts::FRAC_PI_2,
        };
        ViewObject::new(id, Class::Tree, &cells, &bbox, &vp())
    }

    #[test]
    fn round_classes_get_a_foot_box_in_map_axes() {
        let objects: Vec<ViewObject> = (0..6)
            .map(|i| tree(i, 15.0 + f64::from(i), -12.0 + 5.0 * f64::from(i), 2.0))
            .collect();
        let boxes: Vec<Option<AnnotatedBox>> = objects
            .iter()
            .map(|o| {
                Some(AnnotatedBox {
                    centre: [o.contact[0], o.contact[1], 2.0],
                    half_extents: [2.0, 2.0, 2.0],
                    yaw_rad: 0.0,
                })
            })
            .collect();
        let v = vp();
        let priors = ClassPriors::learn([(&v, &objects[..], &boxes[..])]);
        let foot = priors.get(Class::Tree).foot_box;
        let Some(foot) = foot else {
            panic!("no foot box: {:?}", priors.get(Class::Tree));
        };
        assert!(foot.map_yaw_rad.abs() < 1e-9, "{foot:?}");
        assert!((foot.half_side_ratio - 1.0).abs() < 0.05, "{foot:?}");
        // The prediction is the annotated box.
        let b = foot.predict(&objects[2]).view(&VIEW_FRAME);
        let truth = boxes[2].map(|b| b.view(&v));
        let truth = truth.unwrap_or(b);
        assert!((b.centre_range - truth.centre_range).abs() < 1e-9);
        assert!(
            (b.azimuth[0] - truth.azimuth[0]).abs() < 0.01
                && (b.azimuth[1] - truth.azimuth[1]).abs() < 0.01
        );
    }

    #[test]
    fn a_hidden_edge_extends_to_the_class_footprint() {
        // 1 m of a 4 m car visible, side-on: 3 m hidden.
        let a = side(1, 20.0, 0.0, 1.0);
        let prior = ClassPrior {
            samples: 10,
            footprint_m: [4.0, 1.8],
            hidden_fraction: 0.5,
            ..ClassPrior::default()
        };
        let hidden = hidden_extent_m(&a, &prior);
        assert!((hidden - 3.0).abs() < 0.15, "{hidden}");
        let free = completed_azimuth(&a, [false, false], &prior);
        assert_eq!(free, a.azimuth);
        let right = completed_azimuth(&a, [true, false], &prior);
        // Half of the hidden 3 m (the prior's hidden fraction), at the occluded edge only.
        let widened = (a.azimuth[0] - right[0]) * a.centre_range();
        assert!(
            (widened - 1.5).abs() < 0.1 && right[1] == a.azimuth[1],
            "{widened}"
        );
    }

    /// Wall cells along x = `x` from y0 to y1, 0 … 6 m high (a façade facing the origin).
    fn facade(x: f64, y0: f64, y1: f64) -> Vec<[f64; 3]> {
        let mut cells = Vec::new();
        let mut y = y0;
        while y <= y1 + 1e-9 {
            for z in [0.5, 3.0, 6.0] {
                cells.push([x, y, z]);
            }
            y += 0.25;
        }
        cells
    }

    fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Vec<[f64; 2]> {
        vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
    }

    #[test]
    fn a_seen_facade_takes_the_box_of_its_outline() {
        // A 30 m deep block behind a 12 m façade; a second block beside it, a third far away.
        let outlines = MapOutlines::new([
            rect(10.0, -6.0, 40.0, 6.0),
            rect(10.0, 6.5, 20.0, 16.0),
            rect(100.0, 0.0, 110.0, 5.0),
            vec![[0.0, 0.0], [1.0, 1.0]],
        ]);
        assert_eq!(outlines.len(), 3);
        // The wall stands 0.1 m in front of the outline (within the match distance).
        let b = outlines
            .box_of(&facade(9.9, -5.0, 5.0))
            .expect("the façade stands in the first outline");
        assert!((b.centre[0] - 25.0).abs() < 1e-9 && b.centre[1].abs() < 1e-9);
        let mut half = [b.half_extents[0], b.half_extents[1]];
        half.sort_by(f64::total_cmp);
        assert!((half[0] - 6.0).abs() < 1e-9 && (half[1] - 15.0).abs() < 1e-9);
        assert!((b.centre[2] - 3.25).abs() < 1e-9);
        // Seen from a viewpoint at (5, 0) looking along +x, the box's centre is 20 m ahead.
        let v = b.to_view(&Viewpoint {
            position: [5.0, 0.0, 0.0],
            yaw_rad: 0.0,
        });
        assert!((v.view(&VIEW_FRAME).centre_range - 20.0).abs() < 1e-9);
        // A façade across both blocks (60 / 40 of the cells) takes both outlines' box.
        let both = outlines.box_of(&facade(9.9, -5.0, 14.0)).expect("a box");
        assert!(both.half_extents[0].max(both.half_extents[1]) > 15.0 - 1e-9);
        let (lo, hi) = (
            both.centre[1] - both.half_extents[0].min(both.half_extents[1]),
            both.centre[1] + both.half_extents[0].min(both.half_extents[1]),
        );
        assert!(
            (lo + 6.0).abs() < 1e-9 && (hi - 16.0).abs() < 1e-9,
            "{both:?}"
        );
        // Cells in no outline, or spread thinly, get no box.
        assert_eq!(outlines.box_of(&facade(60.0, -5.0, 5.0)), None);
        assert_eq!(outlines.box_of(&[]), None);
        // Touching outlines share a wall: cells near it count for the one they face.
        let row = MapOutlines::new([rect(10.0, -6.0, 40.0, 6.0), rect(10.0, 6.0, 40.0, 20.0)]);
        let one = row.box_of(&facade(9.9, 2.0, 5.9)).expect("a box");
        assert!((one.centre[1]).abs() < 1e-9, "{one:?}");
        let mut spread = facade(9.9, -5.0, 5.0);
        spread.extend(facade(60.0, -5.0, 8.0));
        assert_eq!(outlines.box_of(&spread), None);
    }

    #[test]
    fn a_building_with_a_map_box_is_completed_from_it() {
        let outlines = MapOutlines::new([rect(10.0, -6.0, 40.0, 6.0)]);
        let cells = facade(9.9, -5.0, 5.0);
        let bbox = OrientedBox {
            centre: [9.9, 0.0, 3.0],
            half_extents: [5.0, 0.05, 3.0],
            yaw_rad: std::f64::consts::FRAC_PI_2,
        };
        let mut o = ViewObject::new(1, Class::Building, &cells, &bbox, &vp());
        let prior = ClassPrior {
            samples: 10,
            centre_range_offset_m: 5.0,
            ..ClassPrior::default()
        };
        let without = completed_view(&o, [false; 2], &prior);
        assert!((without.centre_range - 14.9).abs() < 1e-9);
        o.map_box = outlines.box_of(&cells).map(|b| b.to_view(&vp()));
        let with = completed_view(&o, [false; 2], &prior);
        assert!((with.centre_range - 25.0).abs() < 1e-9);
        assert!((with.near_range - 10.0f64.hypot(6.0)).abs() < 1e-9);
    }
}
