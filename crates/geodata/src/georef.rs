//! The georeference of a user's registered point cloud, and its exact conversion into a map's
//! local frame (issue 17: clouds in the user's frame).
//!
//! A [`CloudFrame`] names the frame a cloud's x, y, z are in:
//! - `local`: already the map's local frame ([`crate::projection::LocalFrame`] about the map);
//! - `utm:ZONE[N|S]`: UTM easting/northing of that zone (WGS84, scale 0.9996, false easting
//!   500 km, false northing 10 000 km south), z the height;
//! - `enu:LAT,LON`: east/north/up metres in the tangent plane at that WGS84 point (height 0),
//!   the frame of a survey or a SLAM map anchored at one GNSS fix.
//!
//! Conversions are exact, not planar approximations: UTM through the same Krüger series as
//! the local frame (checked against PROJ 9.5.1 to micrometres), ENU through Earth-centred
//! Cartesian coordinates and back to geodetic latitude, longitude and ellipsoidal height
//! (iterated to below a micrometre). The height that ENU's up axis loses to the Earth's
//! curvature away from the anchor (8 cm at 1 km) is kept: z becomes the ellipsoidal height
//! above the anchor's.

use crate::cloud::PointCloud;
use crate::projection::{LocalFrame, ProjectionError, WGS84_A, WGS84_F};
use rayon::prelude::*;
use std::str::FromStr;
use thiserror::Error;

/// UTM scale on the central meridian.
const UTM_K0: f64 = 0.9996;
/// UTM false easting, metres.
const UTM_FALSE_EASTING: f64 = 500_000.0;
/// UTM false northing of the southern hemisphere, metres.
const UTM_FALSE_NORTHING_SOUTH: f64 = 10_000_000.0;

/// Why a cloud frame could not be read or used.
#[derive(Debug, Error, PartialEq)]
pub enum GeorefError {
    /// The frame text is not one of the accepted forms.
    #[error("cloud frame {given:?}: {message}; expected local, utm:ZONE[N|S] (e.g. utm:32N) or enu:LAT,LON (e.g. enu:48.98,8.39)")]
    Syntax {
        /// The text given.
        given: String,
        /// What is wrong.
        message: String,
    },
    /// The anchor or zone does not define a projection.
    #[error(transparent)]
    Projection(#[from] ProjectionError),
    /// A point does not convert to a finite position.
    #[error("point {index} ({x}, {y}, {z}) is not a position in the {frame} frame")]
    BadPoint {
        /// Index of the point in the cloud.
        index: usize,
        /// Its x.
        x: f64,
        /// Its y.
        y: f64,
        /// Its z.
        z: f64,
        /// The frame, as written.
        frame: String,
    },
}

/// The frame of a registered cloud's coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CloudFrame {
    /// The map's local frame.
    Local,
    /// UTM of a zone and hemisphere.
    Utm {
        /// Zone 1–60.
        zone: u8,
        /// Northern hemisphere.
        north: bool,
    },
    /// East/north/up about a WGS84 anchor (height 0).
    Enu {
        /// Anchor latitude, degrees.
        lat_deg: f64,
        /// Anchor longitude, degrees.
        lon_deg: f64,
    },
}

impl std::fmt::Display for CloudFrame {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CloudFrame::Local => write!(f, "local"),
            CloudFrame::Utm { zone, north } => {
                write!(f, "utm:{zone}{}", if *north { 'N' } else { 'S' })
            }
            CloudFrame::Enu { lat_deg, lon_deg } => write!(f, "enu:{lat_deg},{lon_deg}"),
        }
    }
}

impl FromStr for CloudFrame {
    type Err = GeorefError;

    fn from_str(s: &str) -> Result<Self, GeorefError> {
        let bad = |message: &str| GeorefError::Syntax {
            given: s.to_owned(),
            message: message.to_owned(),
        };
        let t = s.trim();
        if t.eq_ignore_ascii_case("local") {
            return Ok(CloudFrame::Local);
        }
        let (kind, rest) = t
            .split_once(':')
            .ok_or_else(|| bad("no `:` after the frame kind"))?;
        match kind.to_ascii_lowercase().as_str() {
            "utm" => {
                let rest = rest.trim();
                let (digits, hemi) = rest.split_at(rest.len().saturating_sub(1));
                let north = match hemi {
                    "N" | "n" => true,
                    "S" | "s" => false,
                    _ => return Err(bad("the zone must end in N or S")),
                };
                let zone: u8 = digits
                    .parse()
                    .map_err(|_| bad("the zone must be a number 1–60"))?;
                if !(1..=60).contains(&zone) {
                    return Err(bad("the zone must be a number 1–60"));
                }
                Ok(CloudFrame::Utm { zone, north })
            }
            "enu" => {
                let (lat, lon) = rest
                    .split_once(',')
                    .ok_or_else(|| bad("the anchor must be LAT,LON"))?;
                let lat_deg: f64 = lat
                    .trim()
                    .parse()
                    .map_err(|_| bad("the anchor latitude is not a number"))?;
                let lon_deg: f64 = lon
                    .trim()
                    .parse()
                    .map_err(|_| bad("the anchor longitude is not a number"))?;
                // Checked here so that a bad anchor is a syntax error naming the text.
                LocalFrame::new(lat_deg, lon_deg)?;
                Ok(CloudFrame::Enu { lat_deg, lon_deg })
            }
            _ => Err(bad("unknown frame kind")),
        }
    }
}

/// UTM ↔ WGS84 of one zone.
#[derive(Debug, Clone, Copy)]
struct Utm {
    tm: LocalFrame,
    false_northing: f64,
}

impl Utm {
    fn new(zone: u8, north: bool) -> Result<Utm, GeorefError> {
        let central_meridian = -183.0 + 6.0 * f64::from(zone);
        Ok(Utm {
            tm: LocalFrame::new(0.0, central_meridian)?,
            false_northing: if north { 0.0 } else { UTM_FALSE_NORTHING_SOUTH },
        })
    }

    fn unproject(&self, easting: f64, northing: f64) -> (f64, f64) {
        self.tm.to_wgs84([
            (easting - UTM_FALSE_EASTING) / UTM_K0,
            (northing - self.false_northing) / UTM_K0,
        ])
    }

    fn project(&self, lat_deg: f64, lon_deg: f64) -> (f64, f64) {
        let xy = self.tm.to_local(lat_deg, lon_deg);
        (
            UTM_FALSE_EASTING + UTM_K0 * xy[0],
            self.false_northing + UTM_K0 * xy[1],
        )
    }
}

/// East/north/up about an anchor ↔ geodetic coordinates.
#[derive(Debug, Clone, Copy)]
struct Enu {
    origin: [f64; 3],
    /// Rows: east, north, up unit vectors in Earth-centred coordinates.
    axes: [[f64; 3]; 3],
}

fn e2() -> f64 {
    WGS84_F * (2.0 - WGS84_F)
}

/// Earth-centred Cartesian coordinates of a geodetic position.
fn ecef(lat_deg: f64, lon_deg: f64, h: f64) -> [f64; 3] {
    let (sp, cp) = lat_deg.to_radians().sin_cos();
    let (sl, cl) = lon_deg.to_radians().sin_cos();
    let n = WGS84_A / (1.0 - e2() * sp * sp).sqrt();
    [
        (n + h) * cp * cl,
        (n + h) * cp * sl,
        (n * (1.0 - e2()) + h) * sp,
    ]
}

/// Geodetic latitude, longitude (degrees) and ellipsoidal height of Earth-centred
/// coordinates, by fixed-point iteration on the latitude (converges to 1e-12 rad within a
/// few steps near the surface).
fn geodetic(p: [f64; 3]) -> (f64, f64, f64) {
    let lon = p[1].atan2(p[0]);
    let r = p[0].hypot(p[1]);
    let mut lat = p[2].atan2(r * (1.0 - e2()));
    let mut h = 0.0;
    for _ in 0..20 {
        let s = lat.sin();
        let n = WGS84_A / (1.0 - e2() * s * s).sqrt();
        h = if lat.cos().abs() > 1e-9 {
            r / lat.cos() - n
        } else {
            p[2].abs() / s.abs() - n * (1.0 - e2())
        };
        let next = p[2].atan2(r * (1.0 - e2() * n / (n + h)));
        let done = (next - lat).abs() < 1e-14;
        lat = next;
        if done {
            break;
        }
    }
    (lat.to_degrees(), lon.to_degrees(), h)
}

impl Enu {
    fn new(lat_deg: f64, lon_deg: f64) -> Enu {
        let (sp, cp) = lat_deg.to_radians().sin_cos();
        let (sl, cl) = lon_deg.to_radians().sin_cos();
        Enu {
            origin: ecef(lat_deg, lon_deg, 0.0),
            axes: [
                [-sl, cl, 0.0],
                [-sp * cl, -sp * sl, cp],
                [cp * cl, cp * sl, sp],
            ],
        }
    }

    fn unproject(&self, enu: [f64; 3]) -> (f64, f64, f64) {
        let mut p = self.origin;
        for (k, axis) in self.axes.iter().enumerate() {
            for (pi, a) in p.iter_mut().zip(axis) {
                *pi += a * enu[k];
            }
        }
        geodetic(p)
    }

    fn project(&self, lat_deg: f64, lon_deg: f64, h: f64) -> [f64; 3] {
        let p = ecef(lat_deg, lon_deg, h);
        let d = [
            p[0] - self.origin[0],
            p[1] - self.origin[1],
            p[2] - self.origin[2],
        ];
        self.axes.map(|a| a[0] * d[0] + a[1] * d[1] + a[2] * d[2])
    }
}

impl CloudFrame {
    /// WGS84 latitude, longitude (degrees) and height of a point of this frame (`Local`
    /// needs the map's frame, `map`).
    pub fn to_wgs84(&self, p: [f64; 3], map: &LocalFrame) -> Result<(f64, f64, f64), GeorefError> {
        Ok(match *self {
            CloudFrame::Local => {
                let (lat, lon) = map.to_wgs84([p[0], p[1]]);
                (lat, lon, p[2])
            }
            CloudFrame::Utm { zone, north } => {
                let (lat, lon) = Utm::new(zone, north)?.unproject(p[0], p[1]);
                (lat, lon, p[2])
            }
            CloudFrame::Enu { lat_deg, lon_deg } => Enu::new(lat_deg, lon_deg).unproject(p),
        })
    }

    /// A point of this frame from WGS84 latitude, longitude (degrees) and height.
    pub fn from_wgs84(
        &self,
        lat_deg: f64,
        lon_deg: f64,
        h: f64,
        map: &LocalFrame,
    ) -> Result<[f64; 3], GeorefError> {
        Ok(match *self {
            CloudFrame::Local => {
                let xy = map.to_local(lat_deg, lon_deg);
                [xy[0], xy[1], h]
            }
            CloudFrame::Utm { zone, north } => {
                let (e, n) = Utm::new(zone, north)?.project(lat_deg, lon_deg);
                [e, n, h]
            }
            CloudFrame::Enu {
                lat_deg: a,
                lon_deg: b,
            } => Enu::new(a, b).project(lat_deg, lon_deg, h),
        })
    }

    /// Moves a cloud's positions from this frame into the map's local frame (in parallel;
    /// `Local` leaves them as they are). A point that does not convert to a finite position
    /// is an error naming it.
    pub fn into_map_frame(
        &self,
        cloud: &mut PointCloud,
        map: &LocalFrame,
    ) -> Result<(), GeorefError> {
        if *self == CloudFrame::Local {
            return Ok(());
        }
        let frame = *self;
        // Built once: the conversions below only read them.
        let utm = match frame {
            CloudFrame::Utm { zone, north } => Some(Utm::new(zone, north)?),
            _ => None,
        };
        let enu = match frame {
            CloudFrame::Enu { lat_deg, lon_deg } => Some(Enu::new(lat_deg, lon_deg)),
            _ => None,
        };
        let bad = cloud
            .positions
            .par_iter_mut()
            .enumerate()
            .filter_map(|(i, p)| {
                let (lat, lon, h) = match (&utm, &enu) {
                    (Some(u), _) => {
                        let (lat, lon) = u.unproject(p[0], p[1]);
                        (lat, lon, p[2])
                    }
                    (_, Some(e)) => e.unproject(*p),
                    _ => return None,
                };
                let xy = map.to_local(lat, lon);
                let q = [xy[0], xy[1], h];
                if q.iter().all(|v| v.is_finite()) {
                    *p = q;
                    None
                } else {
                    Some((i, *p))
                }
            })
            .min_by_key(|(i, _)| *i);
        match bad {
            None => Ok(()),
            Some((index, p)) => Err(GeorefError::BadPoint {
                index,
                x: p[0],
                y: p[1],
                z: p[2],
                frame: frame.to_string(),
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// (lat, lon, zone, north, easting, northing) from PROJ 9.5.1 (pyproj 3.7.2,
    /// EPSG:4326 → EPSG:326zz / 327zz).
    const UTM_VECTORS: [(f64, f64, u8, bool, f64, f64); 8] = [
        (48.9812, 8.3934, 32, true, 455615.161954, 5425543.153031),
        (59.3477, 18.0721, 34, true, 333519.184698, 6582430.236182),
        (43.7384, 7.4246, 32, true, 373139.336673, 4844024.124663),
        (60.1699, 24.9384, 35, true, 385611.316686, 6672118.380325),
        (-33.8688, 151.2093, 56, false, 334368.633648, 6250948.345385),
        (-22.9068, -43.1729, 23, false, 687394.593291, 7465634.127714),
        (0.5, -0.5, 30, true, 778265.778296, 55318.039977),
        (71.0, 25.0, 35, true, 427338.667320, 7878596.001606),
    ];

    /// (anchor lat, anchor lon, lat, lon, h, east, north, up) from PROJ 9.5.1
    /// (`+proj=cart` then `+proj=topocentric`, WGS84, anchor height 0).
    type EnuVector = (f64, f64, f64, f64, f64, f64, f64, f64);
    const ENU_VECTORS: [EnuVector; 3] = [
        (
            48.98,
            8.39,
            48.99,
            8.4,
            0.0,
            731.864406,
            1112.142655,
            -0.138966,
        ),
        (
            59.3477,
            18.0721,
            59.35,
            18.06,
            12.0,
            -688.381620,
            256.285659,
            11.957799,
        ),
        (
            -33.87,
            151.2,
            -33.86,
            151.22,
            -5.0,
            1850.719919,
            1109.018603,
            -5.364994,
        ),
    ];

    #[test]
    fn utm_agrees_with_proj_both_ways() {
        let map = LocalFrame::new(0.0, 0.0).unwrap();
        for &(lat, lon, zone, north, e, n) in &UTM_VECTORS {
            let f = CloudFrame::Utm { zone, north };
            let p = f.from_wgs84(lat, lon, 0.0, &map).unwrap();
            assert!(
                (p[0] - e).abs() < 1e-5 && (p[1] - n).abs() < 1e-5,
                "{lat} {lon}: {p:?} vs {e} {n}"
            );
            let (la, lo, _) = f.to_wgs84([e, n, 0.0], &map).unwrap();
            // 1e-10° ≈ 11 µm.
            assert!(
                (la - lat).abs() < 1e-10 && (lo - lon).abs() < 1e-10,
                "{la} {lo}"
            );
        }
    }

    #[test]
    fn enu_agrees_with_proj_both_ways() {
        let map = LocalFrame::new(0.0, 0.0).unwrap();
        for &(a, b, lat, lon, h, e, n, u) in &ENU_VECTORS {
            let f = CloudFrame::Enu {
                lat_deg: a,
                lon_deg: b,
            };
            let p = f.from_wgs84(lat, lon, h, &map).unwrap();
            for (got, want) in p.iter().zip([e, n, u]) {
                assert!((got - want).abs() < 1e-5, "{p:?} vs {e} {n} {u}");
            }
            let (la, lo, hh) = f.to_wgs84([e, n, u], &map).unwrap();
            assert!((la - lat).abs() < 1e-10 && (lo - lon).abs() < 1e-10 && (hh - h).abs() < 1e-5);
        }
    }

    #[test]
    fn a_cloud_moves_into_the_map_frame_exactly() {
        let map = LocalFrame::new(48.98, 8.39).unwrap();
        let utm = CloudFrame::Utm {
            zone: 32,
            north: true,
        };
        let enu: CloudFrame = "enu:48.981,8.392".parse().unwrap();
        let truth: Vec<(f64, f64, f64)> = (0..50)
            .map(|i| {
                (
                    48.975 + 0.0002 * i as f64,
                    8.385 + 0.0003 * i as f64,
                    110.0 + i as f64,
                )
            })
            .collect();
        for frame in [utm, enu, CloudFrame::Local] {
            let mut cloud = PointCloud {
                positions: truth
                    .iter()
                    .map(|&(la, lo, h)| frame.from_wgs84(la, lo, h, &map).unwrap())
                    .collect(),
                ..PointCloud::default()
            };
            frame.into_map_frame(&mut cloud, &map).unwrap();
            for (p, &(la, lo, h)) in cloud.positions.iter().zip(&truth) {
                let xy = map.to_local(la, lo);
                assert!(
                    (p[0] - xy[0]).hypot(p[1] - xy[1]) < 1e-6,
                    "{frame}: {p:?} vs {xy:?}"
                );
                assert!((p[2] - h).abs() < 1e-6, "{frame}: z {} vs {h}", p[2]);
            }
        }
    }

    #[test]
    fn frame_text_is_parsed_or_refused_with_the_forms() {
        assert_eq!("local".parse::<CloudFrame>(), Ok(CloudFrame::Local));
        assert_eq!(
            "utm:32N".parse::<CloudFrame>(),
            Ok(CloudFrame::Utm {
                zone: 32,
                north: true
            })
        );
        assert_eq!(
            "UTM:56s".parse::<CloudFrame>(),
            Ok(CloudFrame::Utm {
                zone: 56,
                north: false
            })
        );
        assert_eq!(
            "enu:48.98, 8.39".parse::<CloudFrame>(),
            Ok(CloudFrame::Enu {
                lat_deg: 48.98,
                lon_deg: 8.39
            })
        );
        for bad in [
            "utm:61N",
            "utm:32",
            "utm:N",
            "enu:48.98",
            "enu:x,8",
            "enu:95,8",
            "wgs84",
            "ecef:1",
        ] {
            let e = bad.parse::<CloudFrame>().unwrap_err().to_string();
            assert!(
                e.contains(bad) || e.contains("invalid frame origin"),
                "{bad}: {e}"
            );
        }
        assert_eq!(
            CloudFrame::Utm {
                zone: 7,
                north: false
            }
            .to_string(),
            "utm:7S"
        );
    }

    #[test]
    fn a_nan_point_is_named() {
        let map = LocalFrame::new(48.98, 8.39).unwrap();
        let mut cloud = PointCloud {
            positions: vec![[455615.0, 5425543.0, 0.0], [f64::NAN, 5425543.0, 0.0]],
            ..PointCloud::default()
        };
        let e = CloudFrame::Utm {
            zone: 32,
            north: true,
        }
        .into_map_frame(&mut cloud, &map)
        .unwrap_err()
        .to_string();
        assert!(e.starts_with("point 1 "), "{e}");
    }
}
