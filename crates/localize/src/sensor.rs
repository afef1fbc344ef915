//! Sensor profiles: the geometry of the LiDAR a scan came from (mount height above the
//! ground, vertical field of view, beam count), named or detected from the scan itself, and
//! the surface-extraction options that follow from it.
//!
//! Why it matters: the extraction keeps wall points above a clearance over the local ground
//! (cars and people are below it). A terrestrial scanner or an Ouster looking 22° up sees a
//! façade above 2.5 m from a few metres on; a Velodyne HDL-64E on a car roof (1.73 m, +2° up)
//! sees it above 2.5 m only beyond ≈ 22 m, so a fixed 2.5 m clearance drops every near wall.
//! [`extraction_options`] puts the clearance where the sensor's top beam crosses it a few
//! metres out, and lets single-voxel wall bands count when the sensor only sees a thin band.
//!
//! Detection ([`measure`], [`classify`]) reads a gravity-levelled scan: the mount height is
//! the median over 1 m ground-plane cells (2.5–15 m out) of each cell's lowest point; over
//! 1° azimuth sectors, the vertical field of view is the median of the sectors' lowest and
//! highest elevation (a tilted sensor's excess up on one side and down on the other cancel;
//! directions where the top beam sees sky lower it) and the beam count the 90th percentile
//! of the number of elevation clusters (gaps > 0.12°) in a sector. Cost O(n log n).

use crate::segments::SegmentOptions;
use crate::surfaces::SurfaceOptions;
use serde::Serialize;

pub use geodata::sensors::SensorKind;

/// A sensor's geometry as the extraction needs it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SensorGeometry {
    /// Height of the sensor above the ground below it, metres.
    pub mount_height_m: f64,
    /// Lowest and highest beam elevation, degrees (negative: below the horizon).
    pub vfov_deg: [f64; 2],
    /// Number of beams (rows of the scan pattern).
    pub beams: usize,
}

/// The sensor a scan was processed as: profile, whether it was detected, and its geometry.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SensorReport {
    /// Profile name (`terrestrial`, `hdl64`, `vlp16`, `os1-64`, `os1-128`).
    pub profile: &'static str,
    /// Whether the profile and geometry were estimated from the scan (`--sensor auto`).
    pub detected: bool,
    /// Geometry used for the extraction options.
    #[serde(flatten)]
    pub geometry: SensorGeometry,
}

/// Data-sheet geometry of a model (its usual mount).
pub fn nominal(kind: SensorKind) -> SensorGeometry {
    let e = kind.elevations_deg();
    SensorGeometry {
        mount_height_m: kind.mount_height_m(),
        vfov_deg: [e[0], e[e.len() - 1]],
        beams: e.len(),
    }
}

/// The report of a named model with its nominal geometry.
pub fn report_of(kind: SensorKind) -> SensorReport {
    SensorReport {
        profile: kind.name(),
        detected: false,
        geometry: nominal(kind),
    }
}

/// Fewest ground cells for a measured mount height; below it the nominal 1.8 m is used.
const MIN_GROUND_CELLS: usize = 8;

/// Measures a gravity-levelled scan's sensor geometry (points in the sensor frame).
///
/// Non-finite points are skipped. An empty or tiny scan yields the terrestrial nominal values
/// for what cannot be measured.
pub fn measure(points: &[[f64; 3]]) -> SensorGeometry {
    let fallback = nominal(SensorKind::Terrestrial);
    // (azimuth sector, elevation) for the field of view and the beam count.
    let mut sectors: Vec<(u16, f32)> = Vec::with_capacity(points.len());
    let mut lowest: rustc_hash::FxHashMap<[i32; 2], f64> = Default::default();
    for p in points.iter().filter(|p| p.iter().all(|v| v.is_finite())) {
        let r = p[0].hypot(p[1]);
        if !(2.0..=150.0).contains(&r) {
            continue;
        }
        let el = p[2].atan2(r).to_degrees();
        let az = p[1].atan2(p[0]).to_degrees().rem_euclid(360.0);
        sectors.push(((az as u16).min(359), el as f32));
        if (2.5..=15.0).contains(&r) {
            let key = [p[0].floor() as i32, p[1].floor() as i32];
            let z = lowest.entry(key).or_insert(f64::INFINITY);
            *z = z.min(p[2]);
        }
    }
    let mount_height_m = if lowest.len() < MIN_GROUND_CELLS {
        fallback.mount_height_m
    } else {
        let mut zs: Vec<f64> = lowest.into_values().collect();
        -quantile(&mut zs, 0.5)
    };
    match sector_stats(&mut sectors) {
        Some((vfov_deg, beams)) => SensorGeometry {
            mount_height_m,
            vfov_deg,
            beams,
        },
        None => SensorGeometry {
            mount_height_m,
            ..fallback
        },
    }
}

/// Gap between elevation clusters of one sector that separates two beams, degrees.
const BEAM_GAP_DEG: f32 = 0.12;
/// Fewest points of a sector that counts.
const MIN_SECTOR_POINTS: usize = 8;
/// Fewest counting sectors for a measurement.
const MIN_SECTORS: usize = 30;

/// Field of view and beams from the 1° azimuth sectors: the medians of the sectors' lowest
/// and highest elevation (a tilt of the levelled sensor cancels out), and the 90th
/// percentile of the sectors' elevation clusters.
fn sector_stats(sectors: &mut [(u16, f32)]) -> Option<([f64; 2], usize)> {
    sectors.sort_unstable_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let (mut counts, mut lows, mut highs) = (Vec::new(), Vec::new(), Vec::new());
    for group in sectors.chunk_by(|a, b| a.0 == b.0) {
        if group.len() < MIN_SECTOR_POINTS {
            continue;
        }
        let clusters = 1 + group
            .windows(2)
            .filter(|w| w[1].1 - w[0].1 > BEAM_GAP_DEG)
            .count();
        counts.push(clusters as f64);
        lows.push(f64::from(group[0].1));
        highs.push(f64::from(group[group.len() - 1].1));
    }
    if counts.len() < MIN_SECTORS {
        return None;
    }
    let vfov = [quantile(&mut lows, 0.5), quantile(&mut highs, 0.5)];
    Some((vfov, quantile(&mut counts, 0.9).round() as usize))
}

/// The `q` quantile (nearest rank) of `v`; reorders `v`. `v` must not be empty.
fn quantile(v: &mut [f64], q: f64) -> f64 {
    let k = ((v.len() - 1) as f64 * q).round() as usize;
    let (_, x, _) = v.select_nth_unstable_by(k, f64::total_cmp);
    *x
}

/// The named profile closest to a measured geometry.
///
/// Sees far above the horizon (≥ 35°) or has more than 160 rows: terrestrial; ≤ 24 beams:
/// VLP-16; top beam below 10°: HDL-64; otherwise OS1-64 or OS1-128 by beam count.
pub fn classify(g: &SensorGeometry) -> SensorKind {
    if g.vfov_deg[1] >= 35.0 || g.beams > 160 {
        SensorKind::Terrestrial
    } else if g.beams <= 24 {
        SensorKind::Vlp16
    } else if g.vfov_deg[1] < 10.0 {
        SensorKind::Hdl64
    } else if g.beams <= 90 {
        SensorKind::Os1_64
    } else {
        SensorKind::Os1_128
    }
}

/// The sensor of a scan: the named profile's nominal geometry, or (`None`) measured.
pub fn resolve(profile: Option<SensorKind>, points: &[[f64; 3]]) -> SensorReport {
    match profile {
        Some(kind) => report_of(kind),
        None => {
            let geometry = measure(points);
            SensorReport {
                profile: classify(&geometry).name(),
                detected: true,
                geometry,
            }
        }
    }
}

/// Distance at which the top beam should clear the wall clearance, metres.
const CLEAR_FROM_M: f64 = 4.0;
/// The clearance of sensors that see high up (cars, people and low fences stay below), metres.
const MAX_CLEARANCE_M: f64 = 2.5;
/// Lowest clearance ever used (car bonnets and crouching people stay below), metres.
const MIN_CLEARANCE_M: f64 = 1.2;
/// Largest share of see-through points of a wall column (chosen on KITTI-360 drive 0009:
/// precision 0.64 → 0.73, recall 0.48 → 0.42; MCD unchanged).
const MAX_SEE_THROUGH: f64 = 0.35;

/// Extraction options for a sensor geometry (the defaults everywhere else).
///
/// Clearance: where the top beam is `CLEAR_FROM_M` out, at most 2.5 m, at least 1.2 m. A
/// sensor whose wall band above the clearance is thinner than two voxels 10 m out lets a
/// single surface cell count in the segment histogram. Every profile rejects wall columns
/// that beams see through (hedges, crowns).
pub fn extraction_options(g: &SensorGeometry) -> (SurfaceOptions, SegmentOptions) {
    let mut surfaces = SurfaceOptions::default();
    let mut segments = SegmentOptions::default();
    let up = g.vfov_deg[1].clamp(-10.0, 89.0).to_radians().tan();
    let h = if g.mount_height_m.is_finite() {
        g.mount_height_m
    } else {
        nominal(SensorKind::Terrestrial).mount_height_m
    };
    surfaces.clearance_m = (h + CLEAR_FROM_M * up).clamp(MIN_CLEARANCE_M, MAX_CLEARANCE_M);
    surfaces.max_see_through = MAX_SEE_THROUGH;
    let band_at_10m = h + 10.0 * up - surfaces.clearance_m;
    if band_at_10m < 2.0 * surfaces.voxel_m {
        segments.min_cell_count = 1;
    }
    (surfaces, segments)
}

/// The lowest beam of a car-mounted profile is above this (HDL-64E −24.8°, OS1-128 −22.5°,
/// OS1-64 −16.6°, VLP-16 −15°), degrees: a scan seeing further down comes from a scanner
/// that is not one of them (a terrestrial scanner in a street canyon can look like an HDL-64
/// from above).
pub const CAR_LOWEST_BEAM_DEG: f64 = -30.0;

/// What carries the sensor, for the pose prior of the search.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Vehicle {
    /// A car when the scan's sensor profile (named or detected) is a car-mounted one
    /// ([`SensorKind::on_car`]) and, when detected, the scan sees no lower than such a sensor
    /// does ([`CAR_LOWEST_BEAM_DEG`]), else free.
    #[default]
    Auto,
    /// A car: it stands on a street and heads along it.
    Car,
    /// Anything else (a person, a tripod, a robot on the sidewalk): any heading.
    Free,
}

impl Vehicle {
    /// Every choice, in CLI order.
    pub const ALL: [Vehicle; 3] = [Vehicle::Auto, Vehicle::Car, Vehicle::Free];

    /// The CLI name.
    pub fn name(self) -> &'static str {
        match self {
            Vehicle::Auto => "auto",
            Vehicle::Car => "car",
            Vehicle::Free => "free",
        }
    }

    /// The choice of a CLI name.
    pub fn from_name(name: &str) -> Option<Vehicle> {
        Vehicle::ALL.into_iter().find(|v| v.name() == name)
    }

    /// Whether poses must head along a street, for a scan processed as `sensor` (`None`:
    /// segments given directly, no sensor known).
    pub fn along_streets(self, sensor: Option<&SensorReport>) -> bool {
        match self {
            Vehicle::Car => true,
            Vehicle::Free => false,
            Vehicle::Auto => sensor.is_some_and(|s| {
                SensorKind::from_name(s.profile).is_some_and(SensorKind::on_car)
                    && (!s.detected || s.geometry.vfov_deg[0] >= CAR_LOWEST_BEAM_DEG)
            }),
        }
    }
}

/// How the extraction options of a scan are chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SensorChoice {
    /// Measure the sensor from each scan ([`resolve`] with `None`).
    #[default]
    Auto,
    /// A named profile's nominal geometry.
    Named(SensorKind),
    /// The options exactly as given (`LocalizeOptions::surfaces` and `segments`).
    Manual,
}

/// User values that replace the profile's extraction options (every knob of the CLI).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ExtractOverrides {
    /// [`SurfaceOptions::voxel_m`].
    pub voxel_m: Option<f64>,
    /// [`SurfaceOptions::max_range_m`].
    pub max_range_m: Option<f64>,
    /// [`SurfaceOptions::min_range_m`].
    pub min_range_m: Option<f64>,
    /// [`SurfaceOptions::min_z_m`].
    pub min_z_m: Option<f64>,
    /// [`SurfaceOptions::max_z_m`].
    pub max_z_m: Option<f64>,
    /// [`SurfaceOptions::clearance_m`].
    pub clearance_m: Option<f64>,
    /// [`SurfaceOptions::ground_cell_m`].
    pub ground_cell_m: Option<f64>,
    /// [`SurfaceOptions::column_radius_m`].
    pub column_radius_m: Option<f64>,
    /// [`SurfaceOptions::max_flatness`].
    pub max_flatness: Option<f64>,
    /// [`SurfaceOptions::min_columns`].
    pub min_columns: Option<usize>,
    /// [`SurfaceOptions::max_see_through`].
    pub max_see_through: Option<f64>,
    /// [`SegmentOptions::min_cell_count`].
    pub min_cell_count: Option<u32>,
    /// [`SegmentOptions::final_min_length_m`].
    pub min_segment_m: Option<f64>,
}

impl ExtractOverrides {
    /// Writes every value that is set into the options.
    pub fn apply(&self, s: &mut SurfaceOptions, seg: &mut SegmentOptions) {
        let set = |dst: &mut f64, v: Option<f64>| {
            if let Some(v) = v {
                *dst = v;
            }
        };
        set(&mut s.voxel_m, self.voxel_m);
        set(&mut s.max_range_m, self.max_range_m);
        set(&mut s.min_range_m, self.min_range_m);
        set(&mut s.min_z_m, self.min_z_m);
        set(&mut s.max_z_m, self.max_z_m);
        set(&mut s.clearance_m, self.clearance_m);
        set(&mut s.ground_cell_m, self.ground_cell_m);
        set(&mut s.column_radius_m, self.column_radius_m);
        set(&mut s.max_flatness, self.max_flatness);
        set(&mut s.max_see_through, self.max_see_through);
        if let Some(v) = self.min_columns {
            s.min_columns = v;
        }
        if let Some(v) = self.min_cell_count {
            seg.min_cell_count = v;
        }
        set(&mut seg.final_min_length_m, self.min_segment_m);
    }
}

/// The sensor report and extraction options of one scan.
///
/// `manual` are the options used as they are under [`SensorChoice::Manual`] (no report).
pub fn options_for_scan(
    choice: SensorChoice,
    overrides: &ExtractOverrides,
    manual: (&SurfaceOptions, &SegmentOptions),
    points: &[[f64; 3]],
) -> (Option<SensorReport>, SurfaceOptions, SegmentOptions) {
    let (report, mut s, mut seg) = match choice {
        SensorChoice::Manual => (None, manual.0.clone(), manual.1.clone()),
        SensorChoice::Auto | SensorChoice::Named(_) => {
            let named = match choice {
                SensorChoice::Named(k) => Some(k),
                _ => None,
            };
            let r = resolve(named, points);
            let (s, seg) = extraction_options(&r.geometry);
            (Some(r), s, seg)
        }
    };
    overrides.apply(&mut s, &mut seg);
    (report, s, seg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_takes_a_car_mounted_profile_for_a_car() {
        let report = |kind| Some(report_of(kind));
        for kind in SensorKind::ALL {
            assert_eq!(
                Vehicle::Auto.along_streets(report(kind).as_ref()),
                kind != SensorKind::Terrestrial,
                "{kind:?}"
            );
            assert!(Vehicle::Car.along_streets(report(kind).as_ref()));
            assert!(!Vehicle::Free.along_streets(report(kind).as_ref()));
        }
        // A detected car profile whose scan sees down to −40° is a terrestrial scanner in a
        // street canyon (the demo's first scan): free.
        let canyon = SensorReport {
            profile: "hdl64",
            detected: true,
            geometry: SensorGeometry {
                mount_height_m: 1.8,
                vfov_deg: [-40.0, 6.0],
                beams: 67,
            },
        };
        assert!(!Vehicle::Auto.along_streets(Some(&canyon)));
        let kitti = SensorReport {
            geometry: SensorGeometry {
                vfov_deg: [-24.8, 2.0],
                ..canyon.geometry
            },
            ..canyon
        };
        assert!(Vehicle::Auto.along_streets(Some(&kitti)));
        assert!(!Vehicle::Auto.along_streets(None));
        assert!(Vehicle::Car.along_streets(None));
        for v in Vehicle::ALL {
            assert_eq!(Vehicle::from_name(v.name()), Some(v));
        }
        assert_eq!(Vehicle::from_name("bicycle"), None);
    }

    /// A spinning sensor `h` m above flat ground with `beams` rows spread over `vfov`, and a
    /// ring of walls 20 m away (60 m high, so that every upward beam hits).
    fn spinning(h: f64, vfov: [f64; 2], beams: usize) -> Vec<[f64; 3]> {
        let mut pts = Vec::new();
        for a in 0..1800 {
            let az = (a as f64 * 0.2).to_radians();
            for b in 0..beams {
                let el =
                    (vfov[0] + (vfov[1] - vfov[0]) * b as f64 / (beams - 1) as f64).to_radians();
                let d = [az.cos() * el.cos(), az.sin() * el.cos(), el.sin()];
                let r_h = d[0].hypot(d[1]);
                let mut t = 20.0 / r_h;
                if d[2] < 0.0 {
                    t = t.min(h / -d[2]);
                }
                if t * d[2] > 60.0 - h {
                    continue;
                }
                pts.push([t * d[0], t * d[1], t * d[2]]);
            }
        }
        pts
    }

    #[test]
    fn measures_and_names_each_nominal_sensor() {
        for kind in SensorKind::ALL {
            let n = nominal(kind);
            let pts = spinning(n.mount_height_m, n.vfov_deg, n.beams);
            let g = measure(&pts);
            assert!(
                (g.mount_height_m - n.mount_height_m).abs() < 0.05,
                "{kind:?}: {g:?}"
            );
            assert!(
                (g.vfov_deg[0] - n.vfov_deg[0]).abs() < 1.0,
                "{kind:?}: {g:?}"
            );
            assert!(
                (g.vfov_deg[1] - n.vfov_deg[1]).abs() < 1.0,
                "{kind:?}: {g:?}"
            );
            assert!(g.beams.abs_diff(n.beams) <= n.beams / 10, "{kind:?}: {g:?}");
            assert_eq!(classify(&g), kind, "{g:?}");
            assert_eq!(resolve(None, &pts).profile, kind.name());
        }
    }

    #[test]
    fn car_roof_sensor_gets_a_low_clearance_and_terrestrial_keeps_the_default() {
        let (s, seg) = extraction_options(&nominal(SensorKind::Hdl64));
        assert!(s.clearance_m > 1.73 && s.clearance_m < 2.0, "{s:?}");
        assert_eq!(seg.min_cell_count, 1);
        let (s, seg) = extraction_options(&nominal(SensorKind::Terrestrial));
        assert_eq!(
            s,
            SurfaceOptions {
                max_see_through: MAX_SEE_THROUGH,
                ..SurfaceOptions::default()
            }
        );
        assert_eq!(seg, SegmentOptions::default());
    }

    #[test]
    fn empty_and_non_finite_scans_fall_back() {
        let g = measure(&[]);
        assert_eq!(g, nominal(SensorKind::Terrestrial));
        let g = measure(&[[f64::NAN, 0.0, 0.0]; 10]);
        assert_eq!(g, nominal(SensorKind::Terrestrial));
    }
}
