//! A panoramic terrestrial laser scanner ray-cast into a [`Scene`].
//!
//! The scanner sweeps the full circle in azimuth steps and, per azimuth, a fan of
//! elevations (like a tilting 2-D scanner or a spinning multi-beam scanner). Each ray
//! returns its first hit within `[range_min_m, range_max_m]`, with Gaussian range noise and
//! a dropout probability. Each point carries the class and object id of the surface hit,
//! an intensity from the material's reflectance and the incidence angle, and an RGB colour
//! from the material with per-object tint and per-point noise. Columns are cast in
//! parallel (rayon), each with its own random stream, so the output does not depend on
//! scheduling. Cost: O(rays · (cells crossed + shapes per cell)).

use super::ground::{class_look, speckled_rgb};
pub use super::scene::Pose;
use super::scene::{Scene, SceneHit};
use super::{normal, purpose, stream_rng, SimError};
use geodata::classes::Class;
use geodata::cloud::{Columns, PointCloud, PointRecord, Precision};
use rand::Rng;
use rayon::prelude::*;
use serde::Serialize;

/// Options of the simulated scanner.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SensorOptions {
    /// Azimuth step, degrees.
    pub h_step_deg: f64,
    /// Lowest elevation, degrees (negative: below the horizon).
    pub v_min_deg: f64,
    /// Highest elevation, degrees.
    pub v_max_deg: f64,
    /// Elevation step, degrees.
    pub v_step_deg: f64,
    /// Shortest range returned, metres.
    pub range_min_m: f64,
    /// Longest range returned, metres.
    pub range_max_m: f64,
    /// Standard deviation of the range noise, metres.
    pub range_noise_m: f64,
    /// Probability that a ray with a hit returns nothing.
    pub dropout: f64,
    /// Beam elevations, degrees, when the fan is not uniform (empty: `v_min_deg` to
    /// `v_max_deg` in `v_step_deg` steps).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub elevations_deg: Vec<f64>,
}

impl Default for SensorOptions {
    fn default() -> Self {
        SensorOptions {
            h_step_deg: 0.4,
            v_min_deg: -40.0,
            v_max_deg: 60.0,
            v_step_deg: 0.5,
            range_min_m: 0.5,
            range_max_m: 80.0,
            range_noise_m: 0.02,
            dropout: 0.02,
            elevations_deg: Vec::new(),
        }
    }
}

impl SensorOptions {
    /// Number of azimuth columns.
    pub fn columns(&self) -> usize {
        ((360.0 / self.h_step_deg).round() as usize).max(1)
    }

    /// Number of elevation rows.
    pub fn rows(&self) -> usize {
        if !self.elevations_deg.is_empty() {
            return self.elevations_deg.len();
        }
        (((self.v_max_deg - self.v_min_deg) / self.v_step_deg).floor() as usize) + 1
    }

    /// Elevation of every row, degrees, lowest first.
    pub fn row_elevations_deg(&self) -> Vec<f64> {
        if !self.elevations_deg.is_empty() {
            return self.elevations_deg.clone();
        }
        (0..self.rows())
            .map(|r| self.v_min_deg + r as f64 * self.v_step_deg)
            .collect()
    }

    /// The scanner of a named model (its beams, azimuth step and range; noise and dropout
    /// as the default).
    pub fn of_kind(kind: geodata::sensors::SensorKind) -> SensorOptions {
        let elevations = kind.elevations_deg();
        SensorOptions {
            h_step_deg: kind.azimuth_step_deg(),
            v_min_deg: elevations[0],
            v_max_deg: elevations[elevations.len() - 1],
            range_max_m: kind.range_max_m(),
            elevations_deg: if kind == geodata::sensors::SensorKind::Terrestrial {
                Vec::new()
            } else {
                elevations
            },
            ..SensorOptions::default()
        }
    }

    /// Rays per scan.
    pub fn rays(&self) -> usize {
        self.columns() * self.rows()
    }

    fn validate(&self) -> Result<(), SimError> {
        let bad = |name, value, expected| {
            Err(SimError::InvalidOption {
                name,
                value,
                expected,
            })
        };
        if !(self.h_step_deg.is_finite() && self.h_step_deg >= 0.01 && self.h_step_deg <= 90.0) {
            return bad(
                "h_step_deg",
                self.h_step_deg,
                "a step in [0.01, 90] degrees",
            );
        }
        if !(self.v_step_deg.is_finite() && self.v_step_deg >= 0.01 && self.v_step_deg <= 90.0) {
            return bad(
                "v_step_deg",
                self.v_step_deg,
                "a step in [0.01, 90] degrees",
            );
        }
        if !(self.v_min_deg >= -90.0 && self.v_min_deg <= self.v_max_deg && self.v_max_deg <= 90.0)
        {
            return bad(
                "v_min_deg",
                self.v_min_deg,
                "-90 ≤ v_min_deg ≤ v_max_deg ≤ 90",
            );
        }
        if self
            .elevations_deg
            .iter()
            .any(|e| !(e.is_finite() && (-90.0..=90.0).contains(e)))
        {
            return bad(
                "elevations_deg",
                f64::NAN,
                "finite beam elevations in [-90, 90] degrees",
            );
        }
        if !(self.range_min_m >= 0.0
            && self.range_max_m > self.range_min_m
            && self.range_max_m.is_finite())
        {
            return bad(
                "range_max_m",
                self.range_max_m,
                "0 ≤ range_min_m < range_max_m < ∞",
            );
        }
        if !(self.range_noise_m.is_finite() && self.range_noise_m >= 0.0) {
            return bad("range_noise_m", self.range_noise_m, "a finite value ≥ 0");
        }
        if !(0.0..1.0).contains(&self.dropout) {
            return bad("dropout", self.dropout, "a probability in [0, 1)");
        }
        Ok(())
    }
}

/// In which frame a scan's points are returned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScanFrame {
    /// The gravity-levelled sensor frame: origin at the sensor, x along the heading, z up.
    Sensor,
    /// The map's local frame.
    World,
}

/// Counts of one scan.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct ScanStats {
    /// Rays cast.
    pub rays: usize,
    /// Points returned.
    pub points: usize,
}

/// Intensity and colour of a hit: the ground's look from the scene's ground model, the
/// class material with a per-object tint for everything else.
fn shade(scene: &Scene, hit: &SceneHit, d: [f64; 3], rng: &mut impl Rng) -> (f32, [u8; 3]) {
    let look = scene.ground_look(hit).unwrap_or_else(|| {
        let mut look = class_look(hit.surface.class);
        let tint = match hit.surface.class {
            Class::Car => Scene::object_tint(hit.surface.object).map(|t| t * 3),
            Class::Building | Class::Bicycle | Class::Other => {
                Scene::object_tint(hit.surface.object)
            }
            _ => [0, 0, 0],
        };
        for (c, t) in look.rgb.iter_mut().zip(tint) {
            *c += t;
        }
        look
    });
    let cos = -(hit.normal[0] * d[0] + hit.normal[1] * d[1] + hit.normal[2] * d[2]);
    let intensity =
        (look.reflectance * (0.3 + 0.7 * cos.abs()) + 0.03 * normal(rng)).clamp(0.0, 1.0);
    (intensity as f32, speckled_rgb(&look, rng))
}

/// Scans the scene from a pose; points in the sensor frame (see [`ScanFrame::Sensor`]).
pub fn scan(
    scene: &Scene,
    pose: &Pose,
    options: &SensorOptions,
    seed: u64,
) -> Result<PointCloud, SimError> {
    scan_with(scene, pose, options, seed, ScanFrame::Sensor).map(|(c, _)| c)
}

/// Scans the scene from a pose into the chosen frame, with counts.
pub fn scan_with(
    scene: &Scene,
    pose: &Pose,
    options: &SensorOptions,
    seed: u64,
    frame: ScanFrame,
) -> Result<(PointCloud, ScanStats), SimError> {
    options.validate()?;
    if !(pose.position.iter().all(|v| v.is_finite()) && pose.yaw_rad.is_finite()) {
        return Err(SimError::InvalidOption {
            name: "pose",
            value: f64::NAN,
            expected: "a finite position and yaw",
        });
    }
    let columns = options.columns();
    let rows = options.rows();
    let o = pose.position;
    let (sin_yaw, cos_yaw) = pose.yaw_rad.sin_cos();
    let elevations: Vec<(f64, f64)> = options
        .row_elevations_deg()
        .into_iter()
        .map(|e| e.to_radians().sin_cos())
        .collect();
    debug_assert_eq!(elevations.len(), rows);
    let per_column: Vec<Vec<PointRecord>> = (0..columns)
        .into_par_iter()
        .map(|c| {
            let mut rng = stream_rng(seed, purpose::SENSOR_COLUMN, c as u64);
            let azimuth = (c as f64 * options.h_step_deg).to_radians();
            let (sa, ca) = azimuth.sin_cos();
            // Direction in the world: the sensor heading rotated by the column's azimuth.
            let (sw, cw) = (sin_yaw * ca + cos_yaw * sa, cos_yaw * ca - sin_yaw * sa);
            let mut out = Vec::new();
            for &(se, ce) in &elevations {
                let d = [ce * cw, ce * sw, se];
                let Some(hit) = scene.cast(o, d, options.range_max_m) else {
                    continue;
                };
                let drop_draw: f64 = rng.gen();
                let noise = options.range_noise_m * normal(&mut rng);
                let (intensity, rgb) = shade(scene, &hit, d, &mut rng);
                if hit.t < options.range_min_m || drop_draw < options.dropout {
                    continue;
                }
                let r = hit.t + noise;
                let position = match frame {
                    ScanFrame::World => [o[0] + r * d[0], o[1] + r * d[1], o[2] + r * d[2]],
                    ScanFrame::Sensor => [r * ce * ca, r * ce * sa, r * se],
                };
                out.push(PointRecord {
                    position,
                    intensity,
                    rgb,
                    label: hit.surface.class.id(),
                    raw_label: 0,
                    object: hit.surface.object,
                });
            }
            out
        })
        .collect();
    let total: usize = per_column.iter().map(Vec::len).sum();
    let columns_present = Columns {
        intensity: true,
        rgb: true,
        label: true,
        raw_label: false,
        object: true,
    };
    let mut cloud = PointCloud::with_columns(columns_present, Precision::F32, total);
    for p in per_column.iter().flatten() {
        cloud.push(p);
    }
    Ok((
        cloud,
        ScanStats {
            rays: columns * rows,
            points: total,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::SceneOptions;

    fn scene(seed: u64) -> Scene {
        let map = crate::scene::tests::small_map(seed);
        Scene::build(&map, &SceneOptions::default(), seed).unwrap()
    }

    fn coarse() -> SensorOptions {
        SensorOptions {
            h_step_deg: 1.0,
            v_step_deg: 1.0,
            ..SensorOptions::default()
        }
    }

    #[test]
    fn same_seed_same_points_other_seed_other_noise() {
        let s = scene(2);
        let pose = s.sample_sidewalk_poses(1, 3).unwrap()[0];
        let a = scan(&s, &pose, &coarse(), 1).unwrap();
        let b = scan(&s, &pose, &coarse(), 1).unwrap();
        let c = scan(&s, &pose, &coarse(), 2).unwrap();
        assert_eq!(a, b);
        assert_ne!(a.positions, c.positions);
        assert!(a.len() > 5_000, "{} points", a.len());
    }

    #[test]
    fn labels_agree_with_geometry() {
        let s = scene(3);
        let noiseless = SensorOptions {
            range_noise_m: 0.0,
            dropout: 0.0,
            ..coarse()
        };
        let mut counts = [0usize; Class::COUNT];
        for pose in s.sample_sidewalk_poses(3, 9).unwrap() {
            let (cloud, stats) = scan_with(&s, &pose, &noiseless, 4, ScanFrame::World).unwrap();
            assert_eq!(stats.rays, noiseless.rays());
            let labels = cloud.label.as_ref().unwrap();
            for (p, &l) in cloud.positions.iter().zip(labels) {
                let class = Class::from_id(l).unwrap();
                counts[l as usize] += 1;
                match class {
                    Class::Street => {
                        // On the street surface, inside some segment's true driving area.
                        assert!(p[2].abs() < 1e-6, "street point at z {}", p[2]);
                        let inside = s.segments.iter().zip(&s.truth).any(|(seg, t)| {
                            if !t.drivable {
                                return false;
                            }
                            let [a, b] = crate::truth::offset_centre_line(seg, t);
                            geodata::osm::geometry::point_segment_distance([p[0], p[1]], a, b)
                                <= t.width_m / 2.0 + 1e-6
                        });
                        assert!(inside, "street point {p:?} outside every driving area");
                    }
                    Class::Building => {
                        // On some facade: within a millimetre of a wall line.
                        let d = s
                            .buildings
                            .iter()
                            .flat_map(|b| {
                                (0..b.outer.len())
                                    .map(move |i| (b.outer[i], b.outer[(i + 1) % b.outer.len()]))
                            })
                            .map(|(a, c)| {
                                geodata::osm::geometry::point_segment_distance([p[0], p[1]], a, c)
                            })
                            .fold(f64::INFINITY, f64::min);
                        let d_inner = s
                            .buildings
                            .iter()
                            .flat_map(|b| b.inners.iter())
                            .flat_map(|r| (0..r.len()).map(move |i| (r[i], r[(i + 1) % r.len()])))
                            .map(|(a, c)| {
                                geodata::osm::geometry::point_segment_distance([p[0], p[1]], a, c)
                            })
                            .fold(f64::INFINITY, f64::min);
                        assert!(
                            d.min(d_inner) < 1e-6,
                            "building point {p:?} is {d} m off every wall"
                        );
                    }
                    Class::Sidewalk | Class::Grass => {
                        assert!(p[2] <= s.kerb_m + 1e-6 && p[2] >= -1e-6);
                        assert_ne!(s.ground_at([p[0], p[1]]).class, Class::Street, "{p:?}");
                    }
                    _ => {}
                }
            }
        }
        for class in [Class::Building, Class::Street, Class::Sidewalk] {
            assert!(
                counts[class.id() as usize] > 100,
                "few {class} points: {counts:?}"
            );
        }
    }

    #[test]
    fn a_horizontal_ray_at_a_facade_is_building() {
        let s = scene(4);
        let b = &s.buildings[0];
        // Aim from 5 m outside the middle of the first wall, perpendicular to it.
        let (a, c) = (b.outer[0], b.outer[1]);
        let mid = [(a[0] + c[0]) / 2.0, (a[1] + c[1]) / 2.0];
        let e = [c[0] - a[0], c[1] - a[1]];
        let len = (e[0] * e[0] + e[1] * e[1]).sqrt();
        // Counter-clockwise outer ring: the outward normal is on the right of a→c.
        let out = [e[1] / len, -e[0] / len];
        let o = [mid[0] + 5.0 * out[0], mid[1] + 5.0 * out[1], 2.0];
        let hit = s.cast(o, [-out[0], -out[1], 0.0], 100.0).unwrap();
        if s.clear_of_shapes([o[0], o[1]], 0.1) && (hit.t - 5.0).abs() < 1e-6 {
            assert_eq!(hit.surface.class, Class::Building);
            assert_eq!(hit.surface.object, 1);
        } else {
            // Clutter stands in front of this wall; the hit must be nearer.
            assert!(hit.t <= 5.0 + 1e-6);
        }
    }

    #[test]
    fn sensor_frame_is_the_world_frame_rotated() {
        let s = scene(5);
        let pose = s.sample_sidewalk_poses(1, 1).unwrap()[0];
        let (local, _) = scan_with(&s, &pose, &coarse(), 7, ScanFrame::Sensor).unwrap();
        let (world, _) = scan_with(&s, &pose, &coarse(), 7, ScanFrame::World).unwrap();
        assert_eq!(local.len(), world.len());
        let (sy, cy) = pose.yaw_rad.sin_cos();
        for (l, w) in local.positions.iter().zip(&world.positions) {
            let x = pose.position[0] + cy * l[0] - sy * l[1];
            let y = pose.position[1] + sy * l[0] + cy * l[1];
            assert!((x - w[0]).abs() < 1e-6 && (y - w[1]).abs() < 1e-6);
            assert!((pose.position[2] + l[2] - w[2]).abs() < 1e-6);
        }
    }

    #[test]
    fn rejects_bad_sensor_options() {
        let s = scene(6);
        let pose = s.sample_sidewalk_poses(1, 1).unwrap()[0];
        let bad = SensorOptions {
            dropout: 1.5,
            ..SensorOptions::default()
        };
        assert!(scan(&s, &pose, &bad, 1).is_err());
        let bad = SensorOptions {
            h_step_deg: 0.0,
            ..SensorOptions::default()
        };
        assert!(scan(&s, &pose, &bad, 1).is_err());
    }
}
