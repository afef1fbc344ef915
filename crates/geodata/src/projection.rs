//! WGS84 longitude/latitude ↔ a local metric frame (east, north in metres).
//!
//! The local frame is a transverse Mercator projection on the WGS84 ellipsoid with its
//! central meridian and origin at a chosen point (usually the map centre), scale factor 1.
//! `x` points east and `y` north at the origin; away from the central meridian grid north
//! deviates from true north by the meridian convergence ([`LocalFrame::convergence_rad`]).
//!
//! The series are Krüger's to sixth order in the third flattening n, as given by
//! Karney, "Transverse Mercator with an accuracy of a few nanometers", J. Geodesy 85 (2011),
//! doi:10.1007/s00190-011-0445-3: within a few kilometres of the origin the error is far
//! below a millimetre. Both directions are O(1).
//!
//! ```
//! use geodata::projection::LocalFrame;
//! let frame = LocalFrame::new(59.3477, 18.0721).unwrap();
//! let xy = frame.to_local(59.3487, 18.0721);
//! assert!((xy[0]).abs() < 1e-9 && (xy[1] - 111.3).abs() < 0.5);
//! let (lat, lon) = frame.to_wgs84(xy);
//! assert!((lat - 59.3487).abs() < 1e-11 && (lon - 18.0721).abs() < 1e-11);
//! ```

use thiserror::Error;

/// WGS84 semi-major axis in metres.
pub(crate) const WGS84_A: f64 = 6_378_137.0;
/// WGS84 flattening.
pub(crate) const WGS84_F: f64 = 1.0 / 298.257_223_563;

/// Why a local frame could not be built.
#[derive(Debug, Error, PartialEq)]
pub enum ProjectionError {
    /// The origin is not a finite WGS84 position.
    #[error("invalid frame origin lat {lat_deg}, lon {lon_deg}: latitude must be finite and within ±85°, longitude finite and within ±180°")]
    InvalidOrigin {
        /// Latitude in degrees that was given.
        lat_deg: f64,
        /// Longitude in degrees that was given.
        lon_deg: f64,
    },
}

/// A local transverse-Mercator frame about an origin: WGS84 ↔ (east, north) metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalFrame {
    origin_lat_deg: f64,
    origin_lon_deg: f64,
    /// Rectifying radius A = a/(1+n)·(1 + n²/4 + n⁴/64 + n⁶/256).
    radius_a: f64,
    /// Northing of the origin on the central meridian (A·ξ at the origin).
    origin_northing_m: f64,
    /// First eccentricity e.
    ecc: f64,
    alpha: [f64; 6],
    beta: [f64; 6],
}

impl LocalFrame {
    /// A frame whose origin (0, 0) is at this WGS84 latitude/longitude in degrees.
    pub fn new(origin_lat_deg: f64, origin_lon_deg: f64) -> Result<Self, ProjectionError> {
        if !origin_lat_deg.is_finite()
            || !origin_lon_deg.is_finite()
            || origin_lat_deg.abs() > 85.0
            || origin_lon_deg.abs() > 180.0
        {
            return Err(ProjectionError::InvalidOrigin {
                lat_deg: origin_lat_deg,
                lon_deg: origin_lon_deg,
            });
        }
        let n = WGS84_F / (2.0 - WGS84_F);
        let n2 = n * n;
        let n3 = n2 * n;
        let n4 = n3 * n;
        let n5 = n4 * n;
        let n6 = n5 * n;
        let radius_a = WGS84_A / (1.0 + n) * (1.0 + n2 / 4.0 + n4 / 64.0 + n6 / 256.0);
        let alpha = [
            n / 2.0 - 2.0 * n2 / 3.0 + 5.0 * n3 / 16.0 + 41.0 * n4 / 180.0 - 127.0 * n5 / 288.0
                + 7891.0 * n6 / 37800.0,
            13.0 * n2 / 48.0 - 3.0 * n3 / 5.0 + 557.0 * n4 / 1440.0 + 281.0 * n5 / 630.0
                - 1_983_433.0 * n6 / 1_935_360.0,
            61.0 * n3 / 240.0 - 103.0 * n4 / 140.0
                + 15061.0 * n5 / 26880.0
                + 167_603.0 * n6 / 181_440.0,
            49561.0 * n4 / 161_280.0 - 179.0 * n5 / 168.0 + 6_601_661.0 * n6 / 7_257_600.0,
            34729.0 * n5 / 80640.0 - 3_418_889.0 * n6 / 1_995_840.0,
            212_378_941.0 * n6 / 319_334_400.0,
        ];
        let beta = [
            n / 2.0 - 2.0 * n2 / 3.0 + 37.0 * n3 / 96.0 - n4 / 360.0 - 81.0 * n5 / 512.0
                + 96199.0 * n6 / 604_800.0,
            n2 / 48.0 + n3 / 15.0 - 437.0 * n4 / 1440.0 + 46.0 * n5 / 105.0
                - 1_118_711.0 * n6 / 3_870_720.0,
            17.0 * n3 / 480.0 - 37.0 * n4 / 840.0 - 209.0 * n5 / 4480.0 + 5569.0 * n6 / 90720.0,
            4397.0 * n4 / 161_280.0 - 11.0 * n5 / 504.0 - 830_251.0 * n6 / 7_257_600.0,
            4583.0 * n5 / 161_280.0 - 108_847.0 * n6 / 3_991_680.0,
            20_648_693.0 * n6 / 638_668_800.0,
        ];
        let ecc = (WGS84_F * (2.0 - WGS84_F)).sqrt();
        let mut frame = LocalFrame {
            origin_lat_deg,
            origin_lon_deg,
            radius_a,
            origin_northing_m: 0.0,
            ecc,
            alpha,
            beta,
        };
        frame.origin_northing_m = frame.project_raw(origin_lat_deg, origin_lon_deg)[1];
        Ok(frame)
    }

    /// The frame origin as (latitude, longitude) in degrees.
    pub fn origin(&self) -> (f64, f64) {
        (self.origin_lat_deg, self.origin_lon_deg)
    }

    /// Projects a WGS84 latitude/longitude (degrees) to local `[east, north]` metres.
    pub fn to_local(&self, lat_deg: f64, lon_deg: f64) -> [f64; 2] {
        let p = self.project_raw(lat_deg, lon_deg);
        [p[0], p[1] - self.origin_northing_m]
    }

    /// Unprojects local `[east, north]` metres to WGS84 (latitude, longitude) in degrees.
    pub fn to_wgs84(&self, xy_m: [f64; 2]) -> (f64, f64) {
        let xi = (xy_m[1] + self.origin_northing_m) / self.radius_a;
        let eta = xy_m[0] / self.radius_a;
        let mut xi_p = xi;
        let mut eta_p = eta;
        for (b, (sc, cs)) in self.beta.iter().zip(harmonics(xi, eta)) {
            xi_p -= b * sc;
            eta_p -= b * cs;
        }
        // Conformal latitude χ and longitude difference.
        let chi = (xi_p.sin() / eta_p.cosh()).asin();
        let dlon = eta_p.sinh().atan2(xi_p.cos());
        let lat = self.geodetic_from_conformal(chi);
        (lat.to_degrees(), self.origin_lon_deg + dlon.to_degrees())
    }

    /// Meridian convergence at a local position: the angle (radians, counter-clockwise) from
    /// true north to grid north. Add it to a grid yaw to get a yaw from geographic east.
    pub fn convergence_rad(&self, xy_m: [f64; 2]) -> f64 {
        let (lat, lon) = self.to_wgs84(xy_m);
        let dlon = (lon - self.origin_lon_deg).to_radians();
        let phi = lat.to_radians();
        // First-order-exact spherical term with the ellipsoidal correction (Snyder 8-3).
        let ep2 = self.ecc * self.ecc / (1.0 - self.ecc * self.ecc);
        let c = ep2 * phi.cos().powi(2);
        let a = dlon * phi.cos();
        let t = phi.tan();
        // γ = A·tanφ·(1 + A²/3·(1 + 3C + 2C²)); sign: east of the meridian grid north turns west.
        -(a * t * (1.0 + a * a / 3.0 * (1.0 + 3.0 * c + 2.0 * c * c)))
    }

    /// Transverse Mercator with false northing 0 at the equator (before the origin shift).
    fn project_raw(&self, lat_deg: f64, lon_deg: f64) -> [f64; 2] {
        let phi = lat_deg.to_radians();
        let dlon = (lon_deg - self.origin_lon_deg).to_radians();
        let e = self.ecc;
        let sin_phi = phi.sin();
        let t = (sin_phi.atanh() - e * (e * sin_phi).atanh()).sinh();
        let xi_p = t.atan2(dlon.cos());
        let eta_p = (dlon.sin() / (1.0 + t * t).sqrt()).atanh();
        let mut xi = xi_p;
        let mut eta = eta_p;
        for (a, (sc, cs)) in self.alpha.iter().zip(harmonics(xi_p, eta_p)) {
            xi += a * sc;
            eta += a * cs;
        }
        [self.radius_a * eta, self.radius_a * xi]
    }

    /// Geodetic latitude from conformal latitude χ (radians), by Newton's method on
    /// τ = tan φ (Karney 2011, eqs. 7–9 and 19–21): converges to machine precision.
    fn geodetic_from_conformal(&self, chi: f64) -> f64 {
        let e = self.ecc;
        let tau_p = chi.tan();
        let mut tau = tau_p;
        for _ in 0..8 {
            let sqrt1 = (1.0 + tau * tau).sqrt();
            let sigma = (e * (e * tau / sqrt1).atanh()).sinh();
            let tau_i = tau * (1.0 + sigma * sigma).sqrt() - sigma * sqrt1;
            let dtau = (tau_p - tau_i) / (1.0 + tau_i * tau_i).sqrt()
                * (1.0 + (1.0 - e * e) * tau * tau)
                / ((1.0 - e * e) * sqrt1);
            tau += dtau;
            if dtau.abs() < 1e-15 * tau.abs().max(1.0) {
                break;
            }
        }
        tau.atan()
    }
}

/// Largest degree + 1 of the Chebyshev interpolants of [`BoxProjector`].
const CHEB_N: usize = 10;
/// Smallest degree + 1 tried: city-sized boxes usually pass at 5 or 6.
const CHEB_N_MIN: usize = 4;

/// Largest disagreement with the exact projection [`BoxProjector`] accepts, metres.
const BOX_TOLERANCE_M: f64 = 1e-4;

/// Fast projection for positions inside one lon/lat box: a tensor Chebyshev interpolant of
/// the frame's exact projection, of the lowest degree (3 to 9 per axis) that stays within
/// 0.1 mm of the exact projection on a check grid at construction; positions outside the
/// box, or boxes where no degree passes, use the exact formulas. On a city-sized box it is
/// about 20× faster than [`LocalFrame::to_local`].
#[derive(Debug, Clone)]
pub struct BoxProjector {
    frame: LocalFrame,
    /// `[min_lon, min_lat, max_lon, max_lat]` in degrees.
    bbox: [f64; 4],
    /// Degree + 1 of the interpolant in use (0 when none passed its check).
    n: usize,
    /// Coefficients of east and north, `[k][l]` for T_k(u(lon))·T_l(v(lat)), `k, l < n`.
    coefficients: Box<[[[f64; CHEB_N]; CHEB_N]; 2]>,
    /// The same interpolant in the power basis, `[i][j]` for u^i·v^j (Horner evaluation).
    monomials: Box<[[[f64; CHEB_N]; CHEB_N]; 2]>,
    /// `u = lon · u_scale + u_offset`, `v = lat · v_scale + v_offset` map the box to [-1, 1]².
    unit_affine: [f64; 4],
}

impl BoxProjector {
    /// A projector for `bbox` = `[min_lon, min_lat, max_lon, max_lat]` (degrees) in `frame`.
    pub fn new(frame: LocalFrame, bbox: [f64; 4]) -> Self {
        let mut p = BoxProjector {
            frame,
            bbox,
            n: 0,
            coefficients: Box::new([[[0.0; CHEB_N]; CHEB_N]; 2]),
            monomials: Box::new([[[0.0; CHEB_N]; CHEB_N]; 2]),
            unit_affine: [
                2.0 / (bbox[2] - bbox[0]),
                -1.0 - 2.0 * bbox[0] / (bbox[2] - bbox[0]),
                2.0 / (bbox[3] - bbox[1]),
                -1.0 - 2.0 * bbox[1] / (bbox[3] - bbox[1]),
            ],
        };
        let valid = bbox.iter().all(|v| v.is_finite())
            && bbox[2] > bbox[0]
            && bbox[3] > bbox[1]
            && bbox[1] > -85.0
            && bbox[3] < 85.0;
        if !valid {
            return p;
        }
        for n in CHEB_N_MIN..=CHEB_N {
            p.fit(n);
            if p.passes_check() {
                return p;
            }
        }
        p.n = 0;
        p
    }

    /// Interpolates the exact projection at the n × n Chebyshev nodes of the box.
    fn fit(&mut self, n: usize) {
        let nodes: Vec<f64> = (0..n)
            .map(|i| (std::f64::consts::PI * (i as f64 + 0.5) / n as f64).cos())
            .collect();
        let mut values = vec![[0.0f64; 2]; n * n];
        for (i, &u) in nodes.iter().enumerate() {
            for (j, &v) in nodes.iter().enumerate() {
                let (lon, lat) = self.unit_to_lon_lat(u, v);
                values[i * n + j] = self.frame.to_local(lat, lon);
            }
        }
        // T_k at the nodes of this degree (cos(k·θ_i)).
        let t: Vec<Vec<f64>> = (0..n)
            .map(|i| {
                let theta = std::f64::consts::PI * (i as f64 + 0.5) / n as f64;
                (0..n).map(|k| (k as f64 * theta).cos()).collect()
            })
            .collect();
        let scale = |d: usize| if d == 0 { 1.0 } else { 2.0 } / n as f64;
        *self.coefficients = [[[0.0; CHEB_N]; CHEB_N]; 2];
        for (axis, c_axis) in self.coefficients.iter_mut().enumerate() {
            for k in 0..n {
                for l in 0..n {
                    let mut sum = 0.0;
                    for i in 0..n {
                        for j in 0..n {
                            sum += values[i * n + j][axis] * t[i][k] * t[j][l];
                        }
                    }
                    c_axis[k][l] = sum * scale(k) * scale(l);
                }
            }
        }
        // Power-basis coefficients of T_k: t[k][i] is the coefficient of x^i in T_k(x).
        let mut power = [[0.0f64; CHEB_N]; CHEB_N];
        power[0][0] = 1.0;
        power[1][1] = 1.0;
        for k in 2..CHEB_N {
            for i in 0..CHEB_N {
                let shifted = if i > 0 {
                    2.0 * power[k - 1][i - 1]
                } else {
                    0.0
                };
                power[k][i] = shifted - power[k - 2][i];
            }
        }
        *self.monomials = [[[0.0; CHEB_N]; CHEB_N]; 2];
        for (m_axis, c_axis) in self.monomials.iter_mut().zip(self.coefficients.iter()) {
            for (k, c_row) in c_axis.iter().enumerate().take(n) {
                for (l, &c) in c_row.iter().enumerate().take(n) {
                    for i in 0..=k {
                        for j in 0..=l {
                            m_axis[i][j] += c * power[k][i] * power[l][j];
                        }
                    }
                }
            }
        }
        self.n = n;
    }

    /// Whether the current interpolant is within tolerance on a grid that includes the box
    /// edges and points between the nodes.
    fn passes_check(&self) -> bool {
        let steps = 24;
        for a in 0..=steps {
            for b in 0..=steps {
                let u = -1.0 + 2.0 * a as f64 / steps as f64;
                let v = -1.0 + 2.0 * b as f64 / steps as f64;
                let (lon, lat) = self.unit_to_lon_lat(u, v);
                let exact = self.frame.to_local(lat, lon);
                let fast = self.interpolate(u, v);
                let error_m = (exact[0] - fast[0]).hypot(exact[1] - fast[1]);
                if error_m.is_nan() || error_m > BOX_TOLERANCE_M {
                    return false;
                }
            }
        }
        true
    }

    /// Whether positions inside the box use the interpolant (else the exact formulas).
    pub fn is_interpolating(&self) -> bool {
        self.n > 0
    }

    /// Degree of the interpolant per axis (`None` when the exact formulas are used).
    pub fn degree(&self) -> Option<usize> {
        self.n.checked_sub(1)
    }

    fn unit_to_lon_lat(&self, u: f64, v: f64) -> (f64, f64) {
        let [x0, y0, x1, y1] = self.bbox;
        (
            x0 + 0.5 * (u + 1.0) * (x1 - x0),
            y0 + 0.5 * (v + 1.0) * (y1 - y0),
        )
    }

    fn interpolate(&self, u: f64, v: f64) -> [f64; 2] {
        let n = self.n;
        if n == 0 {
            let (lon, lat) = self.unit_to_lon_lat(u, v);
            return self.frame.to_local(lat, lon);
        }
        // Unrolled for each degree (the loops are short and run per node).
        match n {
            4 => self.horner::<4>(u, v),
            5 => self.horner::<5>(u, v),
            6 => self.horner::<6>(u, v),
            7 => self.horner::<7>(u, v),
            8 => self.horner::<8>(u, v),
            9 => self.horner::<9>(u, v),
            _ => self.horner::<CHEB_N>(u, v),
        }
    }

    /// Horner in u over rows that are Horner polynomials in v, both axes at once; `N` ≥ the
    /// interpolant's degree + 1 (the extra coefficients are zero).
    #[inline(always)]
    fn horner<const N: usize>(&self, u: f64, v: f64) -> [f64; 2] {
        let [m_east, m_north] = &*self.monomials;
        let row = |m: &[f64; CHEB_N]| {
            let mut acc = 0.0;
            for i in (0..N).rev() {
                acc = acc * v + m[i];
            }
            acc
        };
        let (mut east, mut north) = (0.0, 0.0);
        for i in (0..N).rev() {
            east = east * u + row(&m_east[i]);
            north = north * u + row(&m_north[i]);
        }
        [east, north]
    }

    /// Local `[east, north]` metres of a WGS84 latitude/longitude in degrees.
    pub fn to_local(&self, lat_deg: f64, lon_deg: f64) -> [f64; 2] {
        let [x0, y0, x1, y1] = self.bbox;
        if self.n == 0 || !(lon_deg >= x0 && lon_deg <= x1 && lat_deg >= y0 && lat_deg <= y1) {
            return self.frame.to_local(lat_deg, lon_deg);
        }
        let [u_scale, u_offset, v_scale, v_offset] = self.unit_affine;
        let u = (lon_deg * u_scale + u_offset).clamp(-1.0, 1.0);
        let v = (lat_deg * v_scale + v_offset).clamp(-1.0, 1.0);
        self.interpolate(u, v)
    }
}

/// `(sin 2jx · cosh 2jy, cos 2jx · sinh 2jy)` for j = 1..=6, from one sin/cos and one
/// sinh/cosh by the angle-addition recurrences (4 transcendental calls instead of 24).
fn harmonics(x: f64, y: f64) -> [(f64, f64); 6] {
    let (s1, c1) = (2.0 * x).sin_cos();
    let (sh1, ch1) = ((2.0 * y).sinh(), (2.0 * y).cosh());
    let (mut s, mut c, mut sh, mut ch) = (s1, c1, sh1, ch1);
    let mut out = [(0.0, 0.0); 6];
    for slot in &mut out {
        *slot = (s * ch, c * sh);
        (s, c) = (s * c1 + c * s1, c * c1 - s * s1);
        (sh, ch) = (sh * ch1 + ch * sh1, ch * ch1 + sh * sh1);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn origin_maps_to_zero() {
        let f = LocalFrame::new(48.98, 8.39).unwrap();
        let xy = f.to_local(48.98, 8.39);
        assert!(xy[0].abs() < 1e-9 && xy[1].abs() < 1e-9);
    }

    #[test]
    fn round_trip_over_ten_km() {
        let f = LocalFrame::new(59.3477, 18.0721).unwrap();
        for i in -10..=10 {
            for j in -10..=10 {
                let xy = [f64::from(i) * 500.0, f64::from(j) * 500.0];
                let (lat, lon) = f.to_wgs84(xy);
                let back = f.to_local(lat, lon);
                assert!((back[0] - xy[0]).abs() < 1e-6, "{xy:?} -> {back:?}");
                assert!((back[1] - xy[1]).abs() < 1e-6, "{xy:?} -> {back:?}");
            }
        }
    }

    #[test]
    fn meridian_arc_matches_numerical_integration() {
        // The arc 44.5°N → 45.5°N on the central meridian, integrated numerically from
        // the meridional radius of curvature M(φ) = a(1−e²)/(1−e² sin²φ)^1.5.
        let e2 = WGS84_F * (2.0 - WGS84_F);
        let (lo, hi) = (44.5_f64.to_radians(), 45.5_f64.to_radians());
        let steps = 20_000;
        let h = (hi - lo) / f64::from(steps);
        let arc: f64 = (0..steps)
            .map(|i| {
                let phi = lo + (f64::from(i) + 0.5) * h;
                WGS84_A * (1.0 - e2) / (1.0 - e2 * phi.sin().powi(2)).powf(1.5) * h
            })
            .sum();
        let f = LocalFrame::new(44.5, 0.0).unwrap();
        let d = f.to_local(45.5, 0.0)[1] - f.to_local(44.5, 0.0)[1];
        assert!((d - arc).abs() < 1e-3, "projected {d} vs integrated {arc}");
    }

    /// Test vectors computed with PROJ (pyproj 3.7.2) for
    /// `+proj=tmerc +lat_0=LAT0 +lon_0=LON0 +k=1 +x_0=0 +y_0=0 +ellps=WGS84`, at points
    /// spread over a 5 km extract around the frame origin of each shared OSM file
    /// (Helsinki, KTH Stockholm, Monaco), printed to the micrometre.
    // (origin lat, origin lon, lat, lon, east m, north m) from PROJ 9.5.1
    const PROJ_VECTORS: [(f64, f64, f64, f64, f64, f64); 27] = [
        (
            60.171634,
            24.944295449000002,
            60.1506881,
            24.8990153,
            -2515.133203,
            -2332.825916,
        ),
        (
            60.171634,
            24.944295449000002,
            60.1506881,
            24.9610491,
            930.599098,
            -2333.569903,
        ),
        (
            60.171634,
            24.944295449000002,
            60.1506881,
            24.9895756,
            2515.133314,
            -2332.825916,
        ),
        (
            60.171634,
            24.944295449000002,
            60.171634,
            24.8990153,
            -2513.533418,
            0.861627,
        ),
        (
            60.171634,
            24.944295449000002,
            60.171634,
            24.9610491,
            930.007178,
            0.117957,
        ),
        (
            60.171634,
            24.944295449000002,
            60.171634,
            24.9895756,
            2513.533529,
            0.861627,
        ),
        (
            60.171634,
            24.944295449000002,
            60.1925799,
            24.8990153,
            -2511.933292,
            2334.556599,
        ),
        (
            60.171634,
            24.944295449000002,
            60.1925799,
            24.9610491,
            929.415131,
            2333.813247,
        ),
        (
            60.171634,
            24.944295449000002,
            60.1925799,
            24.9895756,
            2511.933403,
            2334.556599,
        ),
        (
            59.34758,
            18.0727,
            59.3266341,
            18.0285234,
            -2514.974416,
            -2332.559213,
        ),
        (
            59.34758,
            18.0727,
            59.3266341,
            18.0890454,
            930.543874,
            -2333.278956,
        ),
        (
            59.34758,
            18.0727,
            59.3266341,
            18.1168766,
            2514.974416,
            -2332.559213,
        ),
        (
            59.34758,
            18.0727,
            59.34758,
            18.0285234,
            -2513.426853,
            0.833573,
        ),
        (
            59.34758, 18.0727, 59.34758, 18.0890454, 929.971274, 0.114117,
        ),
        (
            59.34758,
            18.0727,
            59.34758,
            18.1168766,
            2513.426853,
            0.833573,
        ),
        (
            59.34758,
            18.0727,
            59.3685259,
            18.0285234,
            -2511.878950,
            2334.233910,
        ),
        (
            59.34758,
            18.0727,
            59.3685259,
            18.0890454,
            929.398548,
            2333.514742,
        ),
        (
            59.34758,
            18.0727,
            59.3685259,
            18.1168766,
            2511.878950,
            2334.233910,
        ),
        (
            43.74,
            7.42,
            43.7190541,
            7.3888263,
            -2512.091875,
            -2326.763013,
        ),
        (43.74, 7.42, 43.7190541, 7.4315343, 929.476490, -2327.170663),
        (
            43.74,
            7.42,
            43.7190541,
            7.4511737,
            2512.091875,
            -2326.763013,
        ),
        (43.74, 7.42, 43.74, 7.3888263, -2511.216601, 0.472325),
        (43.74, 7.42, 43.74, 7.4315343, 929.152638, 0.064662),
        (43.74, 7.42, 43.74, 7.4511737, 2511.216601, 0.472325),
        (
            43.74,
            7.42,
            43.7609459,
            7.3888263,
            -2510.340988,
            2327.716226,
        ),
        (43.74, 7.42, 43.7609459, 7.4315343, 928.828660, 2327.308549),
        (43.74, 7.42, 43.7609459, 7.4511737, 2510.340988, 2327.716226),
    ];

    #[test]
    fn agrees_with_proj_to_micrometres() {
        let mut worst_m = 0.0_f64;
        for &(lat0, lon0, lat, lon, east, north) in &PROJ_VECTORS {
            let f = LocalFrame::new(lat0, lon0).unwrap();
            let xy = f.to_local(lat, lon);
            let err = (xy[0] - east).hypot(xy[1] - north);
            worst_m = worst_m.max(err);
            assert!(err < 2e-6, "({lat}, {lon}) about ({lat0}, {lon0}): ours {xy:?}, PROJ [{east}, {north}], {err} m");
            let (lat_back, lon_back) = f.to_wgs84([east, north]);
            // 1e-9 degrees is about 0.1 mm.
            assert!(
                (lat_back - lat).abs() < 1e-9 && (lon_back - lon).abs() < 1e-9,
                "inverse at ({lat}, {lon})"
            );
        }
        assert!(worst_m < 2e-6, "{worst_m}");
    }

    #[test]
    fn rejects_bad_origin() {
        assert!(LocalFrame::new(f64::NAN, 0.0).is_err());
        assert!(LocalFrame::new(89.0, 0.0).is_err());
        assert!(LocalFrame::new(0.0, 200.0).is_err());
    }

    #[test]
    fn box_projector_agrees_with_the_exact_projection() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        // A city (Monaco's extract), a region of 1° and one far from the frame origin.
        for (origin, bbox) in [
            ((43.74, 7.42), [7.349, 43.71, 7.491, 43.77]),
            ((60.17, 24.94), [24.4, 59.9, 25.4, 60.4]),
            ((48.0, 11.0), [11.5, 48.2, 11.7, 48.3]),
        ] {
            let frame = LocalFrame::new(origin.0, origin.1).unwrap();
            let fast = BoxProjector::new(frame, bbox);
            assert!(fast.is_interpolating(), "{bbox:?}");
            println!("{bbox:?}: degree {:?}", fast.degree());
            for _ in 0..2000 {
                // Inside the box and a little outside (exact there).
                let lon = rng.gen_range(bbox[0] - 0.01..bbox[2] + 0.01);
                let lat = rng.gen_range(bbox[1] - 0.01..bbox[3] + 0.01);
                let (a, b) = (fast.to_local(lat, lon), frame.to_local(lat, lon));
                assert!(
                    (a[0] - b[0]).hypot(a[1] - b[1]) < BOX_TOLERANCE_M,
                    "{lat} {lon}"
                );
            }
        }
    }

    #[test]
    fn box_projector_falls_back_on_boxes_it_cannot_fit() {
        let frame = LocalFrame::new(0.0, 0.0).unwrap();
        let huge = BoxProjector::new(frame, [-60.0, -80.0, 60.0, 80.0]);
        assert!(!huge.is_interpolating());
        assert_eq!(huge.to_local(10.0, 20.0), frame.to_local(10.0, 20.0));
        let empty = BoxProjector::new(frame, [1.0, 1.0, 1.0, 1.0]);
        assert!(!empty.is_interpolating());
    }
}
