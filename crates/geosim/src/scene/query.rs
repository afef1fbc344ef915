//! What is at a point of the world and what a ray meets: ground class and look, buildings,
//! ray casting against shapes and the analytic ground.

use super::*;

impl Scene {
    /// The ground at a point (ignoring the paved strips along facades).
    pub(super) fn ground_class_without_facades(&self, p: [f64; 2]) -> GroundCell {
        let mut street: Option<usize> = None;
        let mut sidewalk: Option<(f64, usize)> = None;
        let mut other_paving: Option<usize> = None;
        for cap in self.ground.near(p) {
            let dist = point_segment_distance(p, cap.a, cap.b);
            if cap.drivable && dist <= cap.street_r {
                if street.is_none_or(|s| cap.segment < s) {
                    street = Some(cap.segment);
                }
            } else if dist <= cap.sidewalk_r {
                if cap.drivable {
                    let excess = dist - cap.street_r;
                    if sidewalk.is_none_or(|(e, s)| excess < e || (excess == e && cap.segment < s))
                    {
                        sidewalk = Some((excess, cap.segment));
                    }
                } else if other_paving.is_none_or(|s| cap.segment < s) {
                    other_paving = Some(cap.segment);
                }
            }
        }
        if let Some(s) = street {
            return GroundCell {
                class: Class::Street,
                object: self.street_object(s),
                z: 0.0,
                segment: Some(s),
            };
        }
        if let Some((_, s)) = sidewalk {
            let lowered = self.ground_model.sidewalk_lowered(s, &self.segments[s], p);
            return GroundCell {
                class: Class::Sidewalk,
                object: self.sidewalk_object(s),
                z: if lowered { 0.0 } else { self.kerb_m },
                segment: Some(s),
            };
        }
        let in_plaza = other_paving.is_some()
            || self.plazas.iter().any(|(ring, lo, hi)| {
                p[0] >= lo[0]
                    && p[0] <= hi[0]
                    && p[1] >= lo[1]
                    && p[1] <= hi[1]
                    && point_in_ring(p, ring)
            });
        GroundCell {
            class: if in_plaza { Class::Other } else { Class::Grass },
            object: 0,
            z: self.kerb_m,
            segment: other_paving,
        }
    }

    /// Whether a surface is ground (street, sidewalk, grass, or other paved ground).
    pub fn is_ground(surface: Surface) -> bool {
        matches!(
            surface.class,
            Class::Street | Class::Sidewalk | Class::Grass
        ) || (surface.class == Class::Other && surface.object == 0)
    }

    /// The look (reflectance and colour) of a ground hit, `None` for anything else.
    pub fn ground_look(&self, hit: &SceneHit) -> Option<Look> {
        let s = hit.surface;
        if !Self::is_ground(s) {
            return None;
        }
        let first_sidewalk = self.sidewalk_object(0);
        let segment = match s.class {
            Class::Street => s.object.checked_sub(self.street_object(0)),
            Class::Sidewalk => s.object.checked_sub(first_sidewalk),
            _ => None,
        }
        .map(|i| i as usize)
        .filter(|&i| i < self.segments.len());
        let street = segment.map(|i| (i, &self.segments[i], &self.truth[i]));
        Some(
            self.ground_model
                .look(s.class, street, [hit.point[0], hit.point[1]]),
        )
    }

    /// The ground at a point: street, sidewalk, other paved ground (footways, plazas, facade
    /// strips; object 0) or grass.
    pub fn ground_at(&self, p: [f64; 2]) -> GroundCell {
        let mut cell = self.ground_class_without_facades(p);
        if cell.class == Class::Grass && self.facade_path_m > 0.0 {
            let r = self.facade_path_m;
            let query = AABB::from_corners([p[0] - r, p[1] - r], [p[0] + r, p[1] + r]);
            let near_facade = self
                .building_boxes
                .locate_in_envelope_intersecting(&query)
                .any(|g| {
                    let b = &self.buildings[g.data];
                    std::iter::once(&b.outer)
                        .chain(b.inners.iter())
                        .any(|ring| {
                            ring_edges(ring).any(|(a, c)| point_segment_distance(p, a, c) <= r)
                        })
                });
            if near_facade {
                cell.class = Class::Other;
            }
        }
        cell
    }

    /// Whether a point lies inside a world building.
    pub fn inside_building(&self, p: [f64; 2]) -> bool {
        let query = AABB::from_point(p);
        self.building_boxes
            .locate_in_envelope_intersecting(&query)
            .any(|g| {
                let b = &self.buildings[g.data];
                point_in_polygon(p, &b.outer, &b.inners)
            })
    }

    /// The first surface the ray `o + t·d` (d unit) meets before `t_max`, ground included.
    pub fn cast(&self, o: [f64; 3], d: [f64; 3], t_max: f64) -> Option<SceneHit> {
        let ground = self.cast_ground(o, d, t_max);
        let limit = ground.map_or(t_max, |g| g.t);
        if let Some(h) = self.caster.cast(o, d, limit) {
            return Some(SceneHit {
                t: h.t,
                point: [o[0] + h.t * d[0], o[1] + h.t * d[1], o[2] + h.t * d[2]],
                normal: h.normal,
                surface: self.surfaces[h.shape],
            });
        }
        ground
    }

    /// The ray's hit with the analytic ground (streets and lowered sidewalks at 0, everything
    /// else at the kerb height).
    fn cast_ground(&self, o: [f64; 3], d: [f64; 3], t_max: f64) -> Option<SceneHit> {
        if d[2] >= -1e-12 || o[2] <= self.kerb_m {
            return None;
        }
        let at = |t: f64| [o[0] + t * d[0], o[1] + t * d[1]];
        let t_kerb = (self.kerb_m - o[2]) / d[2];
        if t_kerb >= t_max {
            return None;
        }
        let upper = self.ground_at(at(t_kerb));
        // Raised ground (kerb height) vs street level (streets, lowered sidewalks).
        let raised = |c: &GroundCell| c.z > 0.5 * self.kerb_m;
        let hit = |t: f64, cell: GroundCell, normal: [f64; 3]| SceneHit {
            t,
            point: [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]],
            normal,
            surface: Surface {
                class: cell.class,
                object: cell.object,
            },
        };
        if raised(&upper) {
            return Some(hit(t_kerb, upper, [0.0, 0.0, 1.0]));
        }
        let t_street = -o[2] / d[2];
        if t_street >= t_max {
            return None;
        }
        let lower = self.ground_at(at(t_street));
        if !raised(&lower) {
            return Some(hit(t_street, lower, [0.0, 0.0, 1.0]));
        }
        // The ray passes the kerb face between the two planes: find the crossing.
        let (mut lo, mut hi) = (t_kerb, t_street);
        let mut cell = lower;
        for _ in 0..12 {
            let mid = 0.5 * (lo + hi);
            let c = self.ground_at(at(mid));
            if !raised(&c) {
                lo = mid;
            } else {
                hi = mid;
                cell = c;
            }
        }
        let horizontal = [-d[0], -d[1], 0.0];
        let len = (horizontal[0] * horizontal[0] + horizontal[1] * horizontal[1]).sqrt();
        let normal = if len > 0.0 {
            [horizontal[0] / len, horizontal[1] / len, 0.0]
        } else {
            [0.0, 0.0, 1.0]
        };
        Some(hit(hi, cell, normal))
    }
}
