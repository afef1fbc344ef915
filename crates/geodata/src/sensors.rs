//! Named LiDAR models: beam elevations, azimuth step, range and the usual mount, from the
//! manufacturers' data sheets. The simulator casts their beam patterns; the localizer uses
//! their geometry as defaults when a user names the sensor.

use serde::Serialize;

/// A named LiDAR model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum SensorKind {
    /// A panoramic terrestrial or tilting scanner (tripod or backpack, sees high up).
    Terrestrial,
    /// Velodyne HDL-64E on a car roof (KITTI, KITTI-360).
    Hdl64,
    /// Velodyne VLP-16 (Puck) on a car roof.
    Vlp16,
    /// Ouster OS1-64 on a car roof.
    Os1_64,
    /// Ouster OS1-128 on a car roof.
    Os1_128,
}

impl SensorKind {
    /// Every model, in CLI order.
    pub const ALL: [SensorKind; 5] = [
        SensorKind::Terrestrial,
        SensorKind::Hdl64,
        SensorKind::Vlp16,
        SensorKind::Os1_64,
        SensorKind::Os1_128,
    ];

    /// The CLI name.
    pub fn name(self) -> &'static str {
        match self {
            SensorKind::Terrestrial => "terrestrial",
            SensorKind::Hdl64 => "hdl64",
            SensorKind::Vlp16 => "vlp16",
            SensorKind::Os1_64 => "os1-64",
            SensorKind::Os1_128 => "os1-128",
        }
    }

    /// The model of a CLI name.
    pub fn from_name(name: &str) -> Option<SensorKind> {
        SensorKind::ALL.into_iter().find(|k| k.name() == name)
    }

    /// Whether the model is mounted on a car (scans taken on the road, heading along it).
    pub fn on_car(self) -> bool {
        self != SensorKind::Terrestrial
    }

    /// Usual height of the sensor above the ground below it, metres.
    pub fn mount_height_m(self) -> f64 {
        match self {
            SensorKind::Hdl64 => 1.73,
            _ => 1.8,
        }
    }

    /// Beam elevations, degrees, lowest first.
    pub fn elevations_deg(self) -> Vec<f64> {
        let fan = |lo: f64, hi: f64, n: usize| -> Vec<f64> {
            (0..n)
                .map(|i| lo + (hi - lo) * i as f64 / (n - 1) as f64)
                .collect()
        };
        match self {
            SensorKind::Terrestrial => fan(-40.0, 60.0, 201),
            // Two blocks of 32 lasers: ≈ 1/2° apart below −8.5°, ≈ 1/3° above.
            SensorKind::Hdl64 => {
                let mut v = fan(-24.8, -8.83, 32);
                v.extend(fan(-8.33, 2.0, 32));
                v
            }
            SensorKind::Vlp16 => fan(-15.0, 15.0, 16),
            SensorKind::Os1_64 => fan(-22.5, 22.5, 64),
            SensorKind::Os1_128 => fan(-22.5, 22.5, 128),
        }
    }

    /// Azimuth step, degrees (10 Hz spin).
    pub fn azimuth_step_deg(self) -> f64 {
        match self {
            SensorKind::Terrestrial => 0.4,
            SensorKind::Hdl64 => 0.17,
            SensorKind::Vlp16 => 0.2,
            SensorKind::Os1_64 | SensorKind::Os1_128 => 0.35,
        }
    }

    /// Longest range, metres.
    pub fn range_max_m(self) -> f64 {
        match self {
            SensorKind::Terrestrial => 80.0,
            SensorKind::Vlp16 => 100.0,
            _ => 120.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_patterns_are_sorted() {
        for kind in SensorKind::ALL {
            assert_eq!(SensorKind::from_name(kind.name()), Some(kind));
            let e = kind.elevations_deg();
            assert!(e.windows(2).all(|w| w[0] < w[1]), "{kind:?}");
        }
        assert_eq!(SensorKind::Hdl64.elevations_deg().len(), 64);
        assert_eq!(SensorKind::Os1_128.elevations_deg().len(), 128);
        assert_eq!(SensorKind::from_name("hdl32"), None);
    }
}
