//! The look of the simulated ground: materials per surface, markings, wet patches, and where
//! sidewalks drop to street level.
//!
//! Real street surfaces are not told apart by one colour per class: asphalt comes in many
//! shades, sidewalks are often asphalt too, setts pave both streets and squares, parking lanes
//! are paved like sidewalks, kerbs are lowered at driveways and crossings, and shared-surface
//! streets have none. Thesis §4.5.5 names exactly this ("the street area directly adjacent to
//! an open space with a surface very similar to the street") as the main failure mode. The
//! model, every draw seeded per way, segment or 8 m cell:
//!
//! - **Street** of a way: asphalt (grey 45–115) or, for 15 % of ways, granite setts; 25 % of
//!   segments at least 7 m wide have 2 m parking lanes along both kerbs paved like a sidewalk
//!   (slabs, setts or pavers); dashed white centre lines on streets ≥ 5.5 m; a zebra crossing
//!   10–14 m before the end of 35 % of segments.
//! - **Sidewalk** of a way: 30 % the street's own surface, else asphalt, concrete slabs, setts
//!   or red pavers. 10 % of segments are level with the street (shared surface), and lowered
//!   kerb sections 3–8 m long (driveways, crossings) come 3 times per 100 m of sidewalk side.
//! - **Other paved ground** (footways, plazas, the strips along facades): per 8 m cell, drawn
//!   from the sidewalk materials.
//! - **Grass**: per 8 m cell, green of varying shade, or (20 %) gravel and dirt.
//! - **Wet or dark patches** on 8 % of 4 m cells of paved ground: 60 % of the reflectance, 65 %
//!   of the colour.
//!
//! With `varied: false` every class has one material (the simulator before this model).
//! Cost: O(1) per point (hashes and a few comparisons), O(segments) to build.

use super::truth::StreetTruth;
use super::{mix64, stream_rng, SimError};
use geodata::classes::Class;
use geodata::osm::model::StreetSegment;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// Random stream purposes of the ground model (beside those of [`super::purpose`]).
const PURPOSE_GROUND_WAY: u64 = 101;
const PURPOSE_GROUND_SEGMENT: u64 = 102;
const PURPOSE_GROUND_CELL: u64 = 103;

/// Options of the ground model.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct GroundOptions {
    /// Vary materials per surface, with markings and wet patches (off: one material per class).
    pub varied: bool,
    /// Probability that a segment's sidewalks are level with the street (shared surface).
    pub flush_probability: f64,
    /// Lowered kerb sections (driveways, crossings) per 100 m of sidewalk side.
    pub lowered_per_100m: f64,
    /// Probability that a way's sidewalk has the street's own surface.
    pub shared_material_probability: f64,
    /// Probability that a segment ≥ 7 m wide has parking lanes paved like a sidewalk.
    pub parking_lane_probability: f64,
    /// Fraction of 4 m cells of paved ground that are wet or dark.
    pub wet_fraction: f64,
}

impl Default for GroundOptions {
    fn default() -> Self {
        GroundOptions {
            varied: true,
            flush_probability: 0.1,
            lowered_per_100m: 3.0,
            shared_material_probability: 0.3,
            parking_lane_probability: 0.25,
            wet_fraction: 0.08,
        }
    }
}

impl GroundOptions {
    /// One material per class, raised sidewalks everywhere (the simple ground).
    pub fn plain() -> Self {
        GroundOptions {
            varied: false,
            flush_probability: 0.0,
            lowered_per_100m: 0.0,
            shared_material_probability: 0.0,
            parking_lane_probability: 0.0,
            wet_fraction: 0.0,
        }
    }

    pub(crate) fn validate(&self) -> Result<(), SimError> {
        for (name, p) in [
            ("ground.flush_probability", self.flush_probability),
            (
                "ground.shared_material_probability",
                self.shared_material_probability,
            ),
            (
                "ground.parking_lane_probability",
                self.parking_lane_probability,
            ),
            ("ground.wet_fraction", self.wet_fraction),
        ] {
            if !(0.0..=1.0).contains(&p) {
                return Err(SimError::InvalidOption {
                    name,
                    value: p,
                    expected: "a probability in [0, 1]",
                });
            }
        }
        if !(self.lowered_per_100m.is_finite() && (0.0..=50.0).contains(&self.lowered_per_100m)) {
            return Err(SimError::InvalidOption {
                name: "ground.lowered_per_100m",
                value: self.lowered_per_100m,
                expected: "a rate in [0, 50] per 100 m",
            });
        }
        Ok(())
    }
}

/// Reflectance, base colour and per-point colour noise of a surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Look {
    /// Reflectance in [0, 1] (the scanner's intensity at normal incidence).
    pub reflectance: f64,
    /// Base colour.
    pub rgb: [i32; 3],
    /// Half range of the uniform per-point colour noise.
    pub speckle: i32,
}

/// The fixed material of a class (the plain ground, and everything that is not ground).
pub fn class_look(class: Class) -> Look {
    let (reflectance, rgb) = match class {
        Class::Building => (0.45, [178, 150, 122]),
        Class::Street => (0.18, [72, 72, 78]),
        Class::Sidewalk => (0.35, [152, 150, 148]),
        Class::Grass => (0.5, [92, 142, 60]),
        Class::Tree => (0.55, [52, 104, 42]),
        Class::Car => (0.3, [128, 128, 128]),
        Class::Pole => (0.4, [118, 118, 124]),
        Class::Bicycle => (0.3, [46, 46, 52]),
        Class::Other => (0.4, [196, 96, 52]),
        Class::Unlabelled => (0.3, [128, 128, 128]),
    };
    Look {
        reflectance,
        rgb,
        speckle: 8,
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Paving {
    Asphalt,
    Slabs,
    Setts,
    Pavers,
}

fn paving_look(kind: Paving, rng: &mut ChaCha8Rng) -> Look {
    match kind {
        Paving::Asphalt => {
            let g = rng.gen_range(45..=115);
            let reflectance = 0.08 + 0.2 * f64::from(g - 45) / 70.0 + rng.gen_range(-0.03..0.03);
            Look {
                reflectance,
                rgb: [g, g, g + rng.gen_range(0..=8)],
                speckle: 10,
            }
        }
        Paving::Slabs => {
            let g = rng.gen_range(105..=185);
            Look {
                reflectance: rng.gen_range(0.22..0.45),
                rgb: [g + 3, g, g - 4],
                speckle: 14,
            }
        }
        Paving::Setts => {
            let g = rng.gen_range(85..=150);
            Look {
                reflectance: rng.gen_range(0.18..0.4),
                rgb: [g + 6, g, g - 6],
                speckle: 28,
            }
        }
        Paving::Pavers => Look {
            reflectance: rng.gen_range(0.28..0.45),
            rgb: [
                rng.gen_range(130..=175),
                rng.gen_range(70..=105),
                rng.gen_range(60..=90),
            ],
            speckle: 16,
        },
    }
}

/// A sidewalk-like paving: asphalt 30 %, slabs 40 %, setts 15 %, pavers 15 %.
fn sidewalk_paving(rng: &mut ChaCha8Rng) -> Look {
    let draw: f64 = rng.gen();
    let kind = if draw < 0.3 {
        Paving::Asphalt
    } else if draw < 0.7 {
        Paving::Slabs
    } else if draw < 0.85 {
        Paving::Setts
    } else {
        Paving::Pavers
    };
    paving_look(kind, rng)
}

/// Where one segment's sidewalks drop to street level, and its street's surface details.
#[derive(Debug, Clone, PartialEq)]
struct SegmentGround {
    /// Both sidewalks level with the street along the whole segment.
    flush: bool,
    /// Lowered sections: (side, t₀, t₁) with side +1 left, −1 right, t along a→b in metres.
    lowered: Vec<(f64, f64, f64)>,
    street: Look,
    sidewalk: Look,
    /// Parking lanes paved like this (`None`: none).
    parking: Option<Look>,
    /// Zebra crossing between these along-coordinates.
    crossing: Option<(f64, f64)>,
}

/// The ground model of a scene (see the module doc).
#[derive(Debug, Clone, PartialEq)]
pub struct GroundModel {
    options: GroundOptions,
    seed: u64,
    segments: Vec<SegmentGround>,
}

impl GroundModel {
    /// Draws the per-way and per-segment ground of a map's street segments.
    pub fn new(
        segments: &[StreetSegment],
        truth: &[StreetTruth],
        options: &GroundOptions,
        seed: u64,
    ) -> GroundModel {
        let o = options;
        let per_segment = segments
            .iter()
            .zip(truth)
            .enumerate()
            .map(|(s, (seg, t))| {
                let mut way = stream_rng(seed, PURPOSE_GROUND_WAY, seg.way_index as u64);
                let street = if way.gen::<f64>() < 0.15 {
                    paving_look(Paving::Setts, &mut way)
                } else {
                    paving_look(Paving::Asphalt, &mut way)
                };
                let sidewalk = if way.gen::<f64>() < o.shared_material_probability {
                    street
                } else {
                    sidewalk_paving(&mut way)
                };
                let mut rng = stream_rng(seed, PURPOSE_GROUND_SEGMENT, s as u64);
                let flush = rng.gen::<f64>() < o.flush_probability;
                let mut lowered = Vec::new();
                if o.lowered_per_100m > 0.0 && t.sidewalk_m > 0.0 {
                    for side in [1.0, -1.0] {
                        let mut at = 0.0;
                        loop {
                            let u: f64 = rng.gen_range(f64::EPSILON..1.0);
                            at += -u.ln() * 100.0 / o.lowered_per_100m;
                            if at >= seg.length_m {
                                break;
                            }
                            let len = rng.gen_range(3.0..8.0);
                            lowered.push((side, at, at + len));
                            at += len;
                        }
                    }
                }
                let parking = (t.width_m >= 7.0 && rng.gen::<f64>() < o.parking_lane_probability)
                    .then(|| sidewalk_paving(&mut rng));
                let crossing = (seg.length_m > 30.0 && rng.gen::<f64>() < 0.35).then(|| {
                    let end = seg.length_m - rng.gen_range(10.0..11.0);
                    (end - 3.0, end)
                });
                SegmentGround {
                    flush,
                    lowered,
                    street,
                    sidewalk,
                    parking,
                    crossing,
                }
            })
            .collect();
        GroundModel {
            options: options.clone(),
            seed,
            segments: per_segment,
        }
    }

    /// Whether segment `s`'s sidewalk is at street level at `p` (shared surface or a lowered kerb).
    pub fn sidewalk_lowered(&self, s: usize, segment: &StreetSegment, p: [f64; 2]) -> bool {
        let Some(g) = self.segments.get(s) else {
            return false;
        };
        if g.flush {
            return true;
        }
        if g.lowered.is_empty() {
            return false;
        }
        let (t, u) = segment.coordinates(p);
        let side = if u >= 0.0 { 1.0 } else { -1.0 };
        g.lowered
            .iter()
            .any(|&(sd, t0, t1)| sd == side && t >= t0 && t <= t1)
    }

    /// A seeded uniform draw in [0, 1) keyed by the cell of `p` of side `cell_m` and a salt.
    fn cell_draw(&self, p: [f64; 2], cell_m: f64, salt: u64) -> f64 {
        let ix = (p[0] / cell_m).floor() as i64 as u64;
        let iy = (p[1] / cell_m).floor() as i64 as u64;
        let h = mix64(self.seed ^ mix64(PURPOSE_GROUND_CELL ^ salt) ^ mix64(ix ^ mix64(iy)));
        (h >> 11) as f64 / (1u64 << 53) as f64
    }

    fn cell_rng(&self, p: [f64; 2], cell_m: f64, salt: u64) -> ChaCha8Rng {
        let ix = (p[0] / cell_m).floor() as i64 as u64;
        let iy = (p[1] / cell_m).floor() as i64 as u64;
        stream_rng(self.seed, PURPOSE_GROUND_CELL ^ salt, mix64(ix) ^ iy)
    }

    /// The look of the ground of class `class` at `p`; `street` is the segment (with its
    /// truth) whose driving area or sidewalk it is, if any.
    pub fn look(
        &self,
        class: Class,
        street: Option<(usize, &StreetSegment, &StreetTruth)>,
        p: [f64; 2],
    ) -> Look {
        if !self.options.varied {
            return class_look(class);
        }
        let mut look = match (class, street) {
            (Class::Street, Some((s, seg, t))) => self.street_look(s, seg, t, p),
            (Class::Sidewalk, Some((s, _, _))) => self
                .segments
                .get(s)
                .map_or(class_look(class), |g| g.sidewalk),
            (Class::Grass, _) => {
                let mut rng = self.cell_rng(p, 8.0, 1);
                if rng.gen::<f64>() < 0.2 {
                    let g = rng.gen_range(110..=160);
                    Look {
                        reflectance: rng.gen_range(0.3..0.45),
                        rgb: [g + 15, g, g - 20],
                        speckle: 20,
                    }
                } else {
                    Look {
                        reflectance: rng.gen_range(0.4..0.55),
                        rgb: [
                            rng.gen_range(70..=110),
                            rng.gen_range(120..=160),
                            rng.gen_range(45..=75),
                        ],
                        speckle: 14,
                    }
                }
            }
            _ => sidewalk_paving(&mut self.cell_rng(p, 8.0, 2)),
        };
        if class != Class::Grass && self.cell_draw(p, 4.0, 3) < self.options.wet_fraction {
            look.reflectance *= 0.6;
            look.rgb = look.rgb.map(|c| c * 65 / 100);
        }
        look
    }

    fn street_look(&self, s: usize, seg: &StreetSegment, t: &StreetTruth, p: [f64; 2]) -> Look {
        let Some(g) = self.segments.get(s) else {
            return class_look(Class::Street);
        };
        let (along, u) = seg.coordinates(p);
        let lateral = u - t.offset_m;
        let white = Look {
            reflectance: 0.75,
            rgb: [225, 225, 220],
            speckle: 10,
        };
        if let Some((t0, t1)) = g.crossing {
            if along >= t0 && along <= t1 && (lateral + 100.0).rem_euclid(1.0) < 0.5 {
                return white;
            }
        }
        if t.width_m >= 5.5 && lateral.abs() < 0.06 && along.rem_euclid(9.0) < 3.0 {
            return white;
        }
        if let Some(parking) = g.parking {
            if lateral.abs() > 0.5 * t.width_m - 2.0 {
                return parking;
            }
        }
        g.street
    }
}

/// Per-point look noise: the base colour plus uniform speckle, clamped to a byte.
pub fn speckled_rgb(look: &Look, rng: &mut impl Rng) -> [u8; 3] {
    let mut rgb = [0u8; 3];
    for (out, base) in rgb.iter_mut().zip(look.rgb) {
        let s = look.speckle.max(0);
        *out = (base + rng.gen_range(-s..=s)).clamp(0, 255) as u8;
    }
    rgb
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::truth::{street_truth, TruthOptions};
    use geodata::osm::OsmMap;

    fn map() -> OsmMap {
        crate::scene::tests::small_map(3)
    }

    #[test]
    fn plain_ground_has_one_look_per_class_and_no_lowered_kerbs() {
        let map = map();
        let truth = street_truth(&map, &TruthOptions::default(), 1).unwrap();
        let g = GroundModel::new(&map.streets.segments, &truth, &GroundOptions::plain(), 1);
        let seg = &map.streets.segments[0];
        for p in [[0.0, 0.0], [13.0, -7.0], [200.0, 55.0]] {
            assert_eq!(
                g.look(Class::Street, Some((0, seg, &truth[0])), p),
                class_look(Class::Street)
            );
            assert!(!g.sidewalk_lowered(0, seg, p));
        }
    }

    #[test]
    fn varied_ground_is_seeded_and_varies_across_ways() {
        let map = map();
        let truth = street_truth(&map, &TruthOptions::default(), 1).unwrap();
        let segs = &map.streets.segments;
        let a = GroundModel::new(segs, &truth, &GroundOptions::default(), 1);
        let b = GroundModel::new(segs, &truth, &GroundOptions::default(), 1);
        assert_eq!(a, b);
        let streets: std::collections::BTreeSet<[i32; 3]> =
            a.segments.iter().map(|g| g.street.rgb).collect();
        assert!(streets.len() > 3, "{streets:?}");
        // Some sidewalks drop to street level somewhere.
        let lowered =
            (0..segs.len()).any(|s| a.segments[s].flush || !a.segments[s].lowered.is_empty());
        assert!(lowered);
        assert!(GroundOptions {
            wet_fraction: 2.0,
            ..GroundOptions::default()
        }
        .validate()
        .is_err());
    }
}
