//! Scaled-Mercator georeferencing, the convention of the KITTI, KITTI-360 and MCD datasets.
//!
//! The KITTI devkit (`convertOxtsToPose.m`, `latlonToMercator.m`) places a vehicle on a
//! spherical Mercator projection with radius R = 6 378 137 m, scaled by s = cos(lat₀) so
//! that one metre in the world frame is about one metre on the ground near the reference
//! latitude lat₀:
//!
//! x = s·R·λ, y = s·R·ln(tan(π/4 + φ/2)), λ, φ in radians.
//!
//! A dataset's *world* frame is that projection shifted so that a documented origin
//! (lat₀, lon₀) sits at (0, 0): world x = east, world y = north, in metres. The scale
//! error is below 10⁻⁴ within 1 km of lat₀, so world coordinates are metric to ≈ 0.1 m
//! over a campus. [`ScaledMercator`] converts world ↔ WGS84 exactly (closed form both ways).
//!
//! ```
//! use geodata::mercator::ScaledMercator;
//! let kth = ScaledMercator::new(59.347671416, 18.072069652).unwrap();
//! let (lat, lon) = kth.to_wgs84([64.393, 66.483]);
//! assert!((lat - 59.348268650).abs() < 1e-6 && (lon - 18.073204280).abs() < 1e-6);
//! ```

use thiserror::Error;

/// Earth radius of the KITTI/MCD Mercator convention (WGS84 semi-major axis), metres.
pub const EARTH_RADIUS_M: f64 = 6_378_137.0;

/// Errors of [`ScaledMercator`].
#[derive(Debug, Error, PartialEq)]
pub enum MercatorError {
    /// The origin is not a finite position with |lat| < 85°.
    #[error("invalid Mercator origin lat {lat_deg}, lon {lon_deg}: latitude must be finite and within ±85°, longitude finite")]
    InvalidOrigin {
        /// Latitude given, degrees.
        lat_deg: f64,
        /// Longitude given, degrees.
        lon_deg: f64,
    },
}

/// A scaled-Mercator world frame: scale cos(lat₀), origin (lat₀, lon₀) at world (0, 0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScaledMercator {
    origin_lat_deg: f64,
    origin_lon_deg: f64,
    scale: f64,
    origin_xy_m: [f64; 2],
}

impl ScaledMercator {
    /// A world frame whose scale and origin are both given by (lat₀, lon₀) in degrees.
    pub fn new(origin_lat_deg: f64, origin_lon_deg: f64) -> Result<Self, MercatorError> {
        Self::with_scale_latitude(origin_lat_deg, origin_lon_deg, origin_lat_deg)
    }

    /// A world frame with origin (lat₀, lon₀) and scale cos(`scale_lat_deg`).
    ///
    /// KITTI raw uses the first frame's latitude for the scale and its position as origin;
    /// this constructor allows the two to differ.
    pub fn with_scale_latitude(
        origin_lat_deg: f64,
        origin_lon_deg: f64,
        scale_lat_deg: f64,
    ) -> Result<Self, MercatorError> {
        let valid = |lat: f64, lon: f64| lat.is_finite() && lon.is_finite() && lat.abs() < 85.0;
        if !valid(origin_lat_deg, origin_lon_deg) || !valid(scale_lat_deg, 0.0) {
            return Err(MercatorError::InvalidOrigin {
                lat_deg: origin_lat_deg,
                lon_deg: origin_lon_deg,
            });
        }
        let scale = scale_lat_deg.to_radians().cos();
        let origin_xy_m = mercator_xy(scale, origin_lat_deg, origin_lon_deg);
        Ok(Self {
            origin_lat_deg,
            origin_lon_deg,
            scale,
            origin_xy_m,
        })
    }

    /// The origin (lat₀, lon₀) in degrees.
    pub fn origin(&self) -> (f64, f64) {
        (self.origin_lat_deg, self.origin_lon_deg)
    }

    /// The scale s = cos(lat_scale).
    pub fn scale(&self) -> f64 {
        self.scale
    }

    /// World (east, north) in metres of a WGS84 latitude/longitude in degrees.
    pub fn to_world(&self, lat_deg: f64, lon_deg: f64) -> [f64; 2] {
        let [x, y] = mercator_xy(self.scale, lat_deg, lon_deg);
        [x - self.origin_xy_m[0], y - self.origin_xy_m[1]]
    }

    /// WGS84 (lat, lon) in degrees of a world (east, north) position in metres.
    pub fn to_wgs84(&self, world_xy_m: [f64; 2]) -> (f64, f64) {
        let sr = self.scale * EARTH_RADIUS_M;
        let x = world_xy_m[0] + self.origin_xy_m[0];
        let y = world_xy_m[1] + self.origin_xy_m[1];
        let lon = (x / sr).to_degrees();
        let lat = (2.0 * (y / sr).exp().atan() - std::f64::consts::FRAC_PI_2).to_degrees();
        (lat, lon)
    }

    /// Angle in radians from world +x (Mercator east) to grid east of `frame` at that point.
    ///
    /// Mercator is conformal with north up, so a heading θ in the world frame is θ − γ in a
    /// transverse-Mercator [`crate::projection::LocalFrame`], where γ is the local frame's
    /// meridian convergence. This returns −γ, the correction to add to a world yaw.
    pub fn yaw_to_local_rad(
        &self,
        world_xy_m: [f64; 2],
        frame: &crate::projection::LocalFrame,
    ) -> f64 {
        let (lat, lon) = self.to_wgs84(world_xy_m);
        -frame.convergence_rad(frame.to_local(lat, lon))
    }
}

fn mercator_xy(scale: f64, lat_deg: f64, lon_deg: f64) -> [f64; 2] {
    let sr = scale * EARTH_RADIUS_M;
    let x = sr * lon_deg.to_radians();
    let y = sr
        * (std::f64::consts::FRAC_PI_4 + lat_deg.to_radians() / 2.0)
            .tan()
            .ln();
    [x, y]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn origin_maps_to_zero_and_back() {
        let m = ScaledMercator::new(48.9843445, 8.4295857).unwrap();
        let xy = m.to_world(48.9843445, 8.4295857);
        assert!(xy[0].abs() < 1e-9 && xy[1].abs() < 1e-9);
        let (lat, lon) = m.to_wgs84([1234.5, -987.25]);
        let back = m.to_world(lat, lon);
        assert!((back[0] - 1234.5).abs() < 1e-6 && (back[1] + 987.25).abs() < 1e-6);
    }

    #[test]
    fn mcd_first_pose_matches_documented_position() {
        let m = ScaledMercator::new(59.347671416, 18.072069652).unwrap();
        let (lat, lon) = m.to_wgs84([64.393_253_256_515_79, 66.483_233_094_665_75]);
        assert!((lat - 59.348268650).abs() < 2e-7, "{lat}");
        assert!((lon - 18.073204280).abs() < 2e-7, "{lon}");
    }

    #[test]
    fn scaled_distances_are_metric_near_origin() {
        // 1e-3 degree of latitude is ~111.2 m on the ground near 49° N.
        let m = ScaledMercator::new(49.0, 8.4).unwrap();
        let a = m.to_world(49.0, 8.4);
        let b = m.to_world(49.001, 8.4);
        let d = b[1] - a[1];
        assert!((d - 111.2).abs() < 0.3, "{d}");
    }

    #[test]
    fn rejects_bad_origin() {
        assert!(ScaledMercator::new(f64::NAN, 0.0).is_err());
        assert!(ScaledMercator::new(89.0, 0.0).is_err());
    }
}
