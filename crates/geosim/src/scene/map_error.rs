//! The OSM map-error model: a smooth seeded displacement field between the world and the
//! map, and per-node tracing noise.

use super::*;

/// Options of the OSM map-error model (world buildings vs map outlines).
///
/// OSM outlines are traced from aerial imagery, so their error is mostly a spatially
/// correlated offset of a few metres from the imagery's misregistration (Fan, Zipf, Fu and
/// Neis, "Quality assessment for building footprints data on OpenStreetMap", IJGIS 28 (2014),
/// doi:10.1080/13658816.2013.867495: ≈ 4 m average offset in Munich), plus small tracing
/// noise per node, missing buildings and buildings the map lacks. The model: the map point of
/// a world point p is p + D(p) with D a smooth seeded [`DisplacementField`]; every map node
/// gets its own noise keyed by its quantised coordinate, so nodes shared by adjacent buildings
/// stay shared and blocks keep their shape.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MapErrorOptions {
    /// Root mean square of the smooth displacement field per axis, metres.
    pub field_rms_m: f64,
    /// Shortest and longest wavelength of the field's Fourier modes, metres.
    pub field_wavelength_m: [f64; 2],
    /// Number of Fourier modes per axis.
    pub field_modes: usize,
    /// Standard deviation of each map node's own noise per axis, metres.
    pub node_sigma_m: f64,
    /// Largest node noise per axis, metres.
    pub max_node_m: f64,
    /// Probability that a map building does not exist in the world.
    pub removed_probability: f64,
    /// World buildings missing from the map, per km² of map.
    pub extra_per_km2: f64,
}

impl MapErrorOptions {
    /// No map error: the world's buildings are the map's.
    pub fn none() -> Self {
        MapErrorOptions {
            field_rms_m: 0.0,
            field_wavelength_m: [800.0, 3000.0],
            field_modes: 0,
            node_sigma_m: 0.0,
            max_node_m: 0.0,
            removed_probability: 0.0,
            extra_per_km2: 0.0,
        }
    }

    /// Errors of the size reported for OSM outlines: a field of 1.75 m RMS per axis with
    /// wavelengths 0.8–3 km (4 modes per axis), σ = 0.25 m node noise (≤ 0.75 m), 3 % of map
    /// buildings missing from the world, 15 extra buildings per km².
    pub fn osm_like() -> Self {
        MapErrorOptions {
            field_rms_m: 1.75,
            field_wavelength_m: [800.0, 3000.0],
            field_modes: 4,
            node_sigma_m: 0.25,
            max_node_m: 0.75,
            removed_probability: 0.03,
            extra_per_km2: 15.0,
        }
    }
}

/// One plane-wave mode of a [`DisplacementField`]: a cos(k · p + φ).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FieldMode {
    /// Wave vector, radians per metre.
    pub k_rad_per_m: [f64; 2],
    /// Amplitude, metres.
    pub amplitude_m: f64,
    /// Phase, radians.
    pub phase_rad: f64,
}

/// A smooth seeded 2-D displacement field D(p): the map point of the world point p is
/// p + D(p) (the map-error model's imagery misregistration).
///
/// Each axis is a sum of plane waves with random directions, log-uniform wavelengths and
/// random phases, of equal amplitude so that the spatial RMS per axis is the one asked for.
/// O(modes) per evaluation.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct DisplacementField {
    /// Modes of the x (east) component.
    pub x_modes: Vec<FieldMode>,
    /// Modes of the y (north) component.
    pub y_modes: Vec<FieldMode>,
}

impl DisplacementField {
    /// The zero field.
    pub fn zero() -> Self {
        DisplacementField::default()
    }

    /// A seeded field with the options' RMS, wavelengths and mode count.
    pub fn seeded(options: &MapErrorOptions, seed: u64) -> Self {
        if options.field_modes == 0 || options.field_rms_m <= 0.0 {
            return DisplacementField::zero();
        }
        let mut rng = stream_rng(seed, purpose::MAP_ERROR, u64::MAX);
        let amplitude_m = options.field_rms_m * (2.0 / options.field_modes as f64).sqrt();
        let [lo, hi] = options.field_wavelength_m;
        let (ln_lo, ln_hi) = (lo.max(1.0).ln(), hi.max(lo).max(1.0).ln());
        let modes = |rng: &mut rand_chacha::ChaCha8Rng| -> Vec<FieldMode> {
            (0..options.field_modes)
                .map(|_| {
                    let wavelength = if ln_hi > ln_lo {
                        rng.gen_range(ln_lo..ln_hi).exp()
                    } else {
                        ln_lo.exp()
                    };
                    let dir: f64 = rng.gen_range(0.0..std::f64::consts::TAU);
                    let k = std::f64::consts::TAU / wavelength;
                    FieldMode {
                        k_rad_per_m: [k * dir.cos(), k * dir.sin()],
                        amplitude_m,
                        phase_rad: rng.gen_range(0.0..std::f64::consts::TAU),
                    }
                })
                .collect()
        };
        let x_modes = modes(&mut rng);
        let y_modes = modes(&mut rng);
        DisplacementField { x_modes, y_modes }
    }

    fn component(modes: &[FieldMode], p: [f64; 2]) -> f64 {
        modes
            .iter()
            .map(|m| {
                m.amplitude_m
                    * (m.k_rad_per_m[0] * p[0] + m.k_rad_per_m[1] * p[1] + m.phase_rad).cos()
            })
            .sum()
    }

    /// ∂/∂x and ∂/∂y of one component.
    fn gradient(modes: &[FieldMode], p: [f64; 2]) -> [f64; 2] {
        modes.iter().fold([0.0, 0.0], |g, m| {
            let s = -m.amplitude_m
                * (m.k_rad_per_m[0] * p[0] + m.k_rad_per_m[1] * p[1] + m.phase_rad).sin();
            [g[0] + s * m.k_rad_per_m[0], g[1] + s * m.k_rad_per_m[1]]
        })
    }

    /// D(p), metres.
    pub fn displacement_m(&self, p: [f64; 2]) -> [f64; 2] {
        [
            Self::component(&self.x_modes, p),
            Self::component(&self.y_modes, p),
        ]
    }

    /// The map point of a world point: p + D(p).
    pub fn map_from_world(&self, p: [f64; 2]) -> [f64; 2] {
        let d = self.displacement_m(p);
        [p[0] + d[0], p[1] + d[1]]
    }

    /// The world point of a map point m: the q with q + D(q) = m, by fixed-point iteration
    /// (a contraction: |∇D| ≪ 1 for wavelengths of hundreds of metres).
    pub fn world_from_map(&self, m: [f64; 2]) -> [f64; 2] {
        let mut q = m;
        for _ in 0..8 {
            let d = self.displacement_m(q);
            q = [m[0] - d[0], m[1] - d[1]];
        }
        q
    }

    /// The field's local rotation at p, ½(∂Dy/∂x − ∂Dx/∂y), radians counter-clockwise: a
    /// heading in the world turns by this much in the map.
    pub fn rotation_rad(&self, p: [f64; 2]) -> f64 {
        let gx = Self::gradient(&self.x_modes, p);
        let gy = Self::gradient(&self.y_modes, p);
        0.5 * (gy[0] - gx[1])
    }
}

/// A map node's own tracing noise, keyed by its coordinate quantised to 1 mm, so every
/// building sharing the node gets the same noise.
fn node_noise(options: &MapErrorOptions, seed: u64, m: [f64; 2]) -> [f64; 2] {
    if options.node_sigma_m <= 0.0 {
        return [0.0, 0.0];
    }
    let qx = (m[0] * 1000.0).round() as i64 as u64;
    let qy = (m[1] * 1000.0).round() as i64 as u64;
    let key = mix64(qx ^ mix64(qy)) | (1 << 63);
    let mut rng = stream_rng(seed, purpose::MAP_ERROR, key);
    let lim = options.max_node_m;
    [
        (options.node_sigma_m * normal(&mut rng)).clamp(-lim, lim),
        (options.node_sigma_m * normal(&mut rng)).clamp(-lim, lim),
    ]
}

/// The world ring of a map ring: each node through the inverse field, minus its own noise.
pub(super) fn world_ring(
    ring: &[[f64; 2]],
    field: &DisplacementField,
    options: &MapErrorOptions,
    seed: u64,
) -> Vec<[f64; 2]> {
    ring.iter()
        .map(|&m| {
            let q = field.world_from_map(m);
            let n = node_noise(options, seed, m);
            [q[0] - n[0], q[1] - n[1]]
        })
        .collect()
}
