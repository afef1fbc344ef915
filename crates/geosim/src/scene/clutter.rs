//! Clutter the map does not have: parked cars, trees, poles, bicycles, pedestrians and
//! construction fences, placed along the streets.

use super::*;

/// How much clutter the world has.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ClutterOptions {
    /// Probability that a 6 m parking slot along a kerb holds a car.
    pub car_probability: f64,
    /// Probability of a street tree per 13 m of sidewalk and side.
    pub tree_probability: f64,
    /// Distance between poles along a street, metres.
    pub pole_spacing_m: f64,
    /// Probability of a bicycle per 20 m of sidewalk and side.
    pub bicycle_probability: f64,
    /// Probability of a pedestrian per 15 m of sidewalk and side.
    pub pedestrian_probability: f64,
    /// Probability that a segment has a fenced construction site on a sidewalk.
    pub construction_probability: f64,
    /// Probability of a tree on grass per 20 m of street and side.
    pub grass_tree_probability: f64,
}

impl Default for ClutterOptions {
    fn default() -> Self {
        ClutterOptions {
            car_probability: 0.35,
            tree_probability: 0.45,
            pole_spacing_m: 30.0,
            bicycle_probability: 0.25,
            pedestrian_probability: 0.3,
            construction_probability: 0.04,
            grass_tree_probability: 0.3,
        }
    }
}

impl Scene {
    pub(super) fn place_clutter(&self, out: &mut Clutter<'_>, o: &ClutterOptions, seed: u64) {
        for (s, (seg, t)) in self.segments.iter().zip(&self.truth).enumerate() {
            if !t.drivable || !t.on_ground || seg.length_m < 20.0 {
                continue;
            }
            let mut rng = stream_rng(seed, purpose::CLUTTER, s as u64);
            let e = [
                (seg.b[0] - seg.a[0]) / seg.length_m,
                (seg.b[1] - seg.a[1]) / seg.length_m,
            ];
            let n = [-e[1], e[0]];
            let yaw = e[1].atan2(e[0]);
            let at = |tt: f64, u: f64| {
                [
                    seg.a[0] + tt * e[0] + u * n[0],
                    seg.a[1] + tt * e[1] + u * n[1],
                ]
            };
            let end_margin = 10.0;
            let (t0, t1) = (end_margin, seg.length_m - end_margin);
            let half_w = 0.5 * t.width_m;
            let sw = t.sidewalk_m;
            // The ground under a clutter object must be of the expected class.
            let ground_is = |p: [f64; 2], class: Class| self.ground_at(p).class == class;
            for side in [-1.0_f64, 1.0] {
                // Parked cars in 6 m slots along the kerb.
                if t.width_m >= 5.5 {
                    let mut tt = t0;
                    while tt + 5.0 <= t1 {
                        let draw: f64 = rng.gen();
                        let (len, wid, hei) = (
                            rng.gen_range(3.8..5.0),
                            rng.gen_range(1.7..1.95),
                            rng.gen_range(1.4..1.8),
                        );
                        let jitter = rng.gen_range(-0.4..0.4);
                        if draw < o.car_probability {
                            let u = t.offset_m + side * (half_w - 0.25 - wid / 2.0);
                            let c = at(tt + 3.0 + jitter, u);
                            let yaw_car = yaw + 0.03 * normal(&mut rng);
                            if ground_is(c, Class::Street) && !out.inside_building(c, 1.0) {
                                let centre = [c[0], c[1], hei / 2.0];
                                let half = [len / 2.0, wid / 2.0, hei / 2.0];
                                out.add(
                                    Class::Car,
                                    vec![Shape::OrientedBox {
                                        centre,
                                        half,
                                        yaw_rad: yaw_car,
                                    }],
                                    (centre, half, yaw_car),
                                    s,
                                );
                            }
                        }
                        tt += 6.0;
                    }
                }
                // Street trees on the sidewalk.
                if sw >= 1.5 {
                    let mut tt = t0 + rng.gen_range(0.0..6.0);
                    while tt <= t1 {
                        let draw: f64 = rng.gen();
                        let trunk_r = rng.gen_range(0.15..0.3);
                        let trunk_h = rng.gen_range(2.0..3.5);
                        let crown_r = rng.gen_range(1.5..3.0);
                        let crown_h = rng.gen_range(1.5..3.0);
                        if draw < o.tree_probability {
                            let u = t.offset_m + side * (half_w + 0.5 * sw.min(3.0));
                            let c = at(tt, u);
                            if ground_is(c, Class::Sidewalk) && !out.inside_building(c, crown_r) {
                                out.add_tree(c, trunk_r, trunk_h, crown_r, crown_h, self.kerb_m, s);
                            }
                        }
                        tt += 13.0;
                    }
                }
                // Poles along the kerb.
                if sw >= 1.0 {
                    let mut tt =
                        t0 + rng.gen_range(0.0..o.pole_spacing_m.min(t1 - t0).max(0.0) + 1e-9);
                    while tt <= t1 {
                        let h = rng.gen_range(5.0..8.0);
                        let c = at(tt, t.offset_m + side * (half_w + 0.4));
                        if ground_is(c, Class::Sidewalk) && !out.inside_building(c, 0.5) {
                            let z0 = self.kerb_m;
                            out.add(
                                Class::Pole,
                                vec![Shape::Cylinder {
                                    centre: c,
                                    radius: 0.08,
                                    z_min: z0,
                                    z_max: z0 + h,
                                }],
                                ([c[0], c[1], z0 + h / 2.0], [0.08, 0.08, h / 2.0], 0.0),
                                s,
                            );
                        }
                        tt += o.pole_spacing_m;
                    }
                }
                // Bicycles near the facade side of the sidewalk.
                if sw >= 2.0 {
                    let mut tt = t0;
                    while tt <= t1 {
                        let draw: f64 = rng.gen();
                        let along = rng.gen_range(0.0..20.0);
                        if draw < o.bicycle_probability && tt + along <= t1 {
                            let c = at(tt + along, t.offset_m + side * (half_w + sw - 0.5));
                            if ground_is(c, Class::Sidewalk) && !out.inside_building(c, 1.0) {
                                let centre = [c[0], c[1], self.kerb_m + 0.525];
                                let half = [0.875, 0.3, 0.525];
                                out.add(
                                    Class::Bicycle,
                                    vec![Shape::OrientedBox {
                                        centre,
                                        half,
                                        yaw_rad: yaw,
                                    }],
                                    (centre, half, yaw),
                                    s,
                                );
                            }
                        }
                        tt += 20.0;
                    }
                }
                // Pedestrians.
                if sw >= 1.5 {
                    let mut tt = t0;
                    while tt <= t1 {
                        let draw: f64 = rng.gen();
                        let along = rng.gen_range(0.0..15.0);
                        let lateral = rng.gen_range(0.5..(sw - 0.5).max(0.51));
                        let h = rng.gen_range(1.6..1.9);
                        if draw < o.pedestrian_probability && tt + along <= t1 {
                            let c = at(tt + along, t.offset_m + side * (half_w + lateral));
                            if ground_is(c, Class::Sidewalk) && !out.inside_building(c, 0.5) {
                                let z0 = self.kerb_m;
                                out.add(
                                    Class::Other,
                                    vec![Shape::Cylinder {
                                        centre: c,
                                        radius: 0.25,
                                        z_min: z0,
                                        z_max: z0 + h,
                                    }],
                                    ([c[0], c[1], z0 + h / 2.0], [0.25, 0.25, h / 2.0], 0.0),
                                    s,
                                );
                            }
                        }
                        tt += 15.0;
                    }
                }
                // Trees on grass behind the sidewalk.
                let mut tt = t0;
                while tt <= t1 {
                    let draw: f64 = rng.gen();
                    let lateral = half_w + sw + rng.gen_range(3.0..15.0);
                    let (trunk_r, trunk_h) = (rng.gen_range(0.2..0.4), rng.gen_range(2.0..4.0));
                    let (crown_r, crown_h) = (rng.gen_range(2.0..4.0), rng.gen_range(2.0..4.0));
                    if draw < o.grass_tree_probability {
                        let c = at(tt, t.offset_m + side * lateral);
                        if ground_is(c, Class::Grass) && !out.inside_building(c, crown_r) {
                            out.add_tree(c, trunk_r, trunk_h, crown_r, crown_h, self.kerb_m, s);
                        }
                    }
                    tt += 20.0;
                }
            }
            // A fenced construction site on one sidewalk.
            let draw: f64 = rng.gen();
            let len = rng.gen_range(6.0..12.0);
            let side = if rng.gen::<bool>() { 1.0 } else { -1.0 };
            if draw < o.construction_probability && sw >= 2.5 && t1 - t0 > len {
                let mid = 0.5 * (t0 + t1);
                let u_mid = t.offset_m + side * (half_w + 0.5 * sw);
                let c = at(mid, u_mid);
                let across = sw - 0.6;
                if ground_is(c, Class::Sidewalk) && !out.inside_building(c, across / 2.0 + 0.2) {
                    let h = 1.8;
                    let z = self.kerb_m + h / 2.0;
                    let th = 0.025;
                    let mut parts = Vec::new();
                    for k in [-1.0, 1.0] {
                        let q = at(mid, u_mid + k * across / 2.0);
                        parts.push(Shape::OrientedBox {
                            centre: [q[0], q[1], z],
                            half: [len / 2.0, th, h / 2.0],
                            yaw_rad: yaw,
                        });
                        let q = at(mid + k * len / 2.0, u_mid);
                        parts.push(Shape::OrientedBox {
                            centre: [q[0], q[1], z],
                            half: [th, across / 2.0, h / 2.0],
                            yaw_rad: yaw,
                        });
                    }
                    out.add(
                        Class::Other,
                        parts,
                        ([c[0], c[1], z], [len / 2.0, across / 2.0, h / 2.0], yaw),
                        s,
                    );
                }
            }
        }
    }
}

impl Clutter<'_> {
    #[allow(clippy::too_many_arguments)]
    fn add_tree(
        &mut self,
        c: [f64; 2],
        trunk_r: f64,
        trunk_h: f64,
        crown_r: f64,
        crown_h: f64,
        z0: f64,
        segment: usize,
    ) {
        let crown_z = z0 + trunk_h + 0.8 * crown_h;
        let top = crown_z + crown_h;
        self.add(
            Class::Tree,
            vec![
                Shape::Cylinder {
                    centre: c,
                    radius: trunk_r,
                    z_min: z0,
                    z_max: z0 + trunk_h + 0.5,
                },
                Shape::Spheroid {
                    centre: [c[0], c[1], crown_z],
                    radius_xy: crown_r,
                    radius_z: crown_h,
                },
            ],
            (
                [c[0], c[1], 0.5 * (z0 + top)],
                [crown_r, crown_r, 0.5 * (top - z0)],
                0.0,
            ),
            segment,
        );
    }
}
