//! Vertical surface cells of a scan: voxel downsampling, a normal per occupied voxel, and
//! the voxels whose normal is horizontal, projected to the ground plane (thesis §5.3.2).
//!
//! The scan is gravity-levelled (z up), so a horizontal normal means a vertical surface.
//! Occupied voxels stand in for the RMAP cuboid cells of the thesis; each voxel's normal is
//! the smallest-eigenvalue eigenvector of the covariance of the points in its 3 × 3 × 3
//! voxel neighbourhood. Cost O(n) in the points plus O(v) in the occupied voxels.

use crate::{LocalizeError, Result};
use nalgebra::{Matrix3, SymmetricEigen};
use rustc_hash::FxHashMap;

/// Options of the surface extraction.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceOptions {
    /// Voxel edge length, metres.
    pub voxel_m: f64,
    /// Points farther than this (horizontally) from the sensor are ignored, metres.
    pub max_range_m: f64,
    /// Points closer than this (horizontally) are ignored (the robot itself), metres.
    pub min_range_m: f64,
    /// Lowest point height relative to the sensor kept (drops cars and pedestrians), metres.
    pub min_z_m: f64,
    /// Highest point height relative to the sensor kept, metres.
    pub max_z_m: f64,
    /// Largest |n_z| of a normal counted as horizontal.
    pub max_normal_z: f64,
    /// Largest ratio of the smallest to the middle covariance eigenvalue (planarity).
    pub max_flatness: f64,
    /// Fewest points in a voxel neighbourhood for a normal.
    pub min_points: usize,
}

impl Default for SurfaceOptions {
    fn default() -> Self {
        SurfaceOptions {
            voxel_m: 0.3,
            max_range_m: 60.0,
            min_range_m: 1.5,
            min_z_m: -0.5,
            max_z_m: 30.0,
            max_normal_z: 0.3,
            max_flatness: 0.2,
            min_points: 6,
        }
    }
}

/// One occupied voxel with a horizontal normal, projected to the ground plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceCell {
    /// Centroid of the voxel's points (x, y) in the sensor frame, metres.
    pub xy: [f64; 2],
    /// Height of the voxel's centroid, metres.
    pub z: f64,
    /// Orientation of the normal in [0, π) radians (the surface line is perpendicular).
    pub normal_yaw_rad: f64,
}

#[derive(Clone, Copy, Default)]
struct Moments {
    n: f64,
    s: [f64; 3],
    ss: [f64; 6],
}

impl Moments {
    fn add_point(&mut self, p: [f64; 3]) {
        self.n += 1.0;
        for (s, v) in self.s.iter_mut().zip(p) {
            *s += v;
        }
        self.ss[0] += p[0] * p[0];
        self.ss[1] += p[0] * p[1];
        self.ss[2] += p[0] * p[2];
        self.ss[3] += p[1] * p[1];
        self.ss[4] += p[1] * p[2];
        self.ss[5] += p[2] * p[2];
    }

    fn add(&mut self, o: &Moments) {
        self.n += o.n;
        for k in 0..3 {
            self.s[k] += o.s[k];
        }
        for k in 0..6 {
            self.ss[k] += o.ss[k];
        }
    }

    fn mean(&self) -> [f64; 3] {
        [self.s[0] / self.n, self.s[1] / self.n, self.s[2] / self.n]
    }

    fn covariance(&self) -> Matrix3<f64> {
        let m = self.mean();
        let c = |k: usize, i: usize, j: usize| self.ss[k] / self.n - m[i] * m[j];
        let (xx, xy, xz, yy, yz, zz) = (
            c(0, 0, 0),
            c(1, 0, 1),
            c(2, 0, 2),
            c(3, 1, 1),
            c(4, 1, 2),
            c(5, 2, 2),
        );
        Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz)
    }
}

/// Checks that every point is finite.
pub fn check_points(points: &[[f64; 3]]) -> Result<()> {
    for (index, p) in points.iter().enumerate() {
        if !p.iter().all(|v| v.is_finite()) {
            return Err(LocalizeError::NonFinitePoint { index, value: *p });
        }
    }
    Ok(())
}

/// The vertical-surface cells of a gravity-levelled scan (points in the sensor frame).
///
/// Errors on non-finite points or a non-positive voxel size.
pub fn vertical_cells(points: &[[f64; 3]], options: &SurfaceOptions) -> Result<Vec<SurfaceCell>> {
    check_points(points)?;
    if !(options.voxel_m > 0.0 && options.voxel_m.is_finite()) {
        return Err(LocalizeError::InvalidOption {
            name: "voxel_m",
            value: options.voxel_m,
            expected: "a positive number of metres",
        });
    }
    let inv = 1.0 / options.voxel_m;
    let mut voxels: FxHashMap<[i32; 3], Moments> = FxHashMap::default();
    let (r2_max, r2_min) = (
        options.max_range_m * options.max_range_m,
        options.min_range_m * options.min_range_m,
    );
    for p in points {
        let r2 = p[0] * p[0] + p[1] * p[1];
        if r2 > r2_max || r2 < r2_min || p[2] < options.min_z_m || p[2] > options.max_z_m {
            continue;
        }
        let key = [
            (p[0] * inv).floor() as i32,
            (p[1] * inv).floor() as i32,
            (p[2] * inv).floor() as i32,
        ];
        voxels.entry(key).or_default().add_point(*p);
    }
    let mut keys: Vec<[i32; 3]> = voxels.keys().copied().collect();
    keys.sort_unstable();
    let mut cells = Vec::new();
    for key in keys {
        let Some(own) = voxels.get(&key) else {
            continue;
        };
        let mut m = Moments::default();
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(v) = voxels.get(&[key[0] + dx, key[1] + dy, key[2] + dz]) {
                        m.add(v);
                    }
                }
            }
        }
        if (m.n as usize) < options.min_points {
            continue;
        }
        let eig = SymmetricEigen::new(m.covariance());
        let mut order = [0usize, 1, 2];
        order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
        let (l0, l1) = (eig.eigenvalues[order[0]], eig.eigenvalues[order[1]]);
        if l1 <= 0.0 || l0 > options.max_flatness * l1 {
            continue;
        }
        let n = eig.eigenvectors.column(order[0]);
        if n[2].abs() > options.max_normal_z {
            continue;
        }
        let c = own.mean();
        cells.push(SurfaceCell {
            xy: [c[0], c[1]],
            z: c[2],
            normal_yaw_rad: crate::wrap_pi(n[1].atan2(n[0])),
        });
    }
    Ok(cells)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A vertical wall x = 5 (y ∈ [-5, 5], z ∈ [0, 6]) and a canopy z = 3 beside it.
    fn wall_and_floor() -> Vec<[f64; 3]> {
        let mut pts = Vec::new();
        for i in 0..100 {
            for k in 0..60 {
                pts.push([5.0, -5.0 + i as f64 * 0.1, k as f64 * 0.1]);
            }
        }
        for i in 0..85 {
            for j in 0..100 {
                pts.push([-5.0 + i as f64 * 0.1, -5.0 + j as f64 * 0.1, 3.0]);
            }
        }
        pts
    }

    #[test]
    fn keeps_the_wall_and_drops_the_floor() {
        let cells = vertical_cells(&wall_and_floor(), &SurfaceOptions::default()).unwrap();
        assert!(cells.len() > 50, "{} cells", cells.len());
        for c in &cells {
            assert!((c.xy[0] - 5.0).abs() < 0.2, "{c:?}");
            assert!(
                crate::orientation_diff(c.normal_yaw_rad, 0.0) < 0.05,
                "{c:?}"
            );
        }
    }

    #[test]
    fn nan_point_is_an_error() {
        let mut pts = wall_and_floor();
        pts[17] = [f64::NAN, 0.0, 0.0];
        let err = vertical_cells(&pts, &SurfaceOptions::default()).unwrap_err();
        assert!(err.to_string().contains("point 17"), "{err}");
    }

    #[test]
    fn empty_scan_gives_no_cells() {
        assert!(vertical_cells(&[], &SurfaceOptions::default())
            .unwrap()
            .is_empty());
    }
}
