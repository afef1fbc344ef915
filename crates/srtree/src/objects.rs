//! Objects of the map: per object id its cells, centroid, class and an oriented bounding
//! box (thesis §3.3.2).
//!
//! The box's yaw is the mode of the histogram of the horizontal directions of the cell
//! normals, folded modulo 90° (a Manhattan object has its faces at 0°, 90°, 180°, 270°), so
//! the box is aligned with the principal directions of rectangular objects. Normals are the
//! smallest-eigenvalue eigenvectors of the covariance of the object's cell centres within
//! [`ObjectOptions::normal_radius_m`]. Objects without vertical faces (ground surfaces)
//! take the yaw of the major axis of their footprint. The box is then shrunk per axis to
//! the [`ObjectOptions::shrink_percentile`] and `100 −` that percentile of the cell
//! coordinates, which prunes stray cells for a tight fit.
//!
//! Cost: one radius query per cell (O(log n + neighbours)), in parallel.

use crate::map::SrMap;
use geodata::classes::Class;
use geodata::osm::geometry::{major_axis_angle, mean_and_scatter};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// An oriented bounding box: yaw about the vertical axis only.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OrientedBox {
    /// Centre, metres.
    pub centre: [f64; 3],
    /// Half extents along the yaw direction, across it, and up, metres.
    pub half_extents: [f64; 3],
    /// Yaw of the first axis, radians counter-clockwise from x.
    pub yaw_rad: f64,
}

impl OrientedBox {
    /// The 8 corners (bottom face first, counter-clockwise).
    pub fn corners(&self) -> [[f64; 3]; 8] {
        let (s, c) = self.yaw_rad.sin_cos();
        let h = self.half_extents;
        let mut out = [[0.0; 3]; 8];
        for (i, (kx, ky, kz)) in [
            (-1.0, -1.0, -1.0),
            (1.0, -1.0, -1.0),
            (1.0, 1.0, -1.0),
            (-1.0, 1.0, -1.0),
            (-1.0, -1.0, 1.0),
            (1.0, -1.0, 1.0),
            (1.0, 1.0, 1.0),
            (-1.0, 1.0, 1.0),
        ]
        .into_iter()
        .enumerate()
        {
            let (x, y) = (kx * h[0], ky * h[1]);
            out[i] = [
                self.centre[0] + c * x - s * y,
                self.centre[1] + s * x + c * y,
                self.centre[2] + kz * h[2],
            ];
        }
        out
    }

    /// The 4 footprint corners (x, y), counter-clockwise.
    pub fn footprint(&self) -> [[f64; 2]; 4] {
        let c = self.corners();
        [0, 1, 2, 3].map(|i| [c[i][0], c[i][1]])
    }
}

/// Options of [`extract_objects`].
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectOptions {
    /// Objects with fewer occupied cells are left out.
    pub min_cells: usize,
    /// Neighbourhood radius of the normal estimate, metres.
    pub normal_radius_m: f64,
    /// Bins of the yaw histogram over 90°.
    pub yaw_bins: usize,
    /// Percentile cut at each end of each box axis (0–49).
    pub shrink_percentile: f64,
}

impl Default for ObjectOptions {
    fn default() -> Self {
        ObjectOptions {
            min_cells: 5,
            normal_radius_m: 0.3,
            yaw_bins: 45,
            shrink_percentile: 2.0,
        }
    }
}

/// An object with its cells.
#[derive(Debug, Clone, PartialEq)]
pub struct MapObject {
    /// Object id.
    pub id: u32,
    /// Majority class of its cells.
    pub class: Class,
    /// Indices of its occupied cells in the map.
    pub cells: Vec<u32>,
    /// Mean of its cell centres, metres.
    pub centroid: [f64; 3],
    /// Oriented box.
    pub bbox: OrientedBox,
}

/// Eigenvector of the smallest eigenvalue of a symmetric 3×3 matrix (Jacobi rotations).
#[allow(clippy::needless_range_loop)]
pub fn smallest_eigenvector(m: [[f64; 3]; 3]) -> [f64; 3] {
    let mut a = m;
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..30 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        if off < 1e-15 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q].abs() < 1e-300 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for k in 0..3 {
                let (akp, akq) = (a[k][p], a[k][q]);
                a[k][p] = c * akp - s * akq;
                a[k][q] = s * akp + c * akq;
            }
            for k in 0..3 {
                let (apk, aqk) = (a[p][k], a[q][k]);
                a[p][k] = c * apk - s * aqk;
                a[q][k] = s * apk + c * aqk;
            }
            for row in &mut v {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    let k = (0..3)
        .min_by(|&i, &j| a[i][i].total_cmp(&a[j][j]))
        .unwrap_or(0);
    [v[0][k], v[1][k], v[2][k]]
}

/// The `q`-quantile (0–1) of a sorted slice (nearest rank).
fn quantile_sorted(v: &[f64], q: f64) -> f64 {
    let i = ((v.len() - 1) as f64 * q).round() as usize;
    v[i.min(v.len() - 1)]
}

/// The oriented box of a set of points (cell centres) with normals given per point.
pub fn oriented_box(
    points: &[[f64; 3]],
    normals: &[[f64; 3]],
    options: &ObjectOptions,
    half_cell_m: f64,
) -> OrientedBox {
    let bins = options.yaw_bins.max(1);
    let quarter = std::f64::consts::FRAC_PI_2;
    let mut hist = vec![0.0; bins];
    for n in normals {
        let h = n[0].hypot(n[1]);
        if h < 0.7 {
            continue; // not a vertical face
        }
        let yaw = n[1].atan2(n[0]).rem_euclid(quarter);
        let b = ((yaw / quarter * bins as f64) as usize).min(bins - 1);
        hist[b] += h;
    }
    let best = (0..bins)
        .max_by(|&i, &j| hist[i].total_cmp(&hist[j]).then(j.cmp(&i)))
        .unwrap_or(0);
    let yaw = if hist[best] > 0.0 {
        (best as f64 + 0.5) / bins as f64 * quarter
    } else {
        // Footprint major axis (2-D PCA).
        let footprint: Vec<[f64; 2]> = points.iter().map(|p| [p[0], p[1]]).collect();
        major_axis_angle(mean_and_scatter(&footprint).1)
    };
    let (s, c) = yaw.sin_cos();
    let mut axes: [Vec<f64>; 3] = [Vec::new(), Vec::new(), Vec::new()];
    for p in points {
        axes[0].push(c * p[0] + s * p[1]);
        axes[1].push(-s * p[0] + c * p[1]);
        axes[2].push(p[2]);
    }
    let q = (options.shrink_percentile / 100.0).clamp(0.0, 0.49);
    let mut lo = [0.0; 3];
    let mut hi = [0.0; 3];
    for k in 0..3 {
        axes[k].sort_by(f64::total_cmp);
        if axes[k].is_empty() {
            continue;
        }
        lo[k] = quantile_sorted(&axes[k], q) - half_cell_m;
        hi[k] = quantile_sorted(&axes[k], 1.0 - q) + half_cell_m;
    }
    let m = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
    OrientedBox {
        centre: [
            c * m[0] - s * m[1],
            s * m[0] + c * m[1],
            0.5 * (lo[2] + hi[2]),
        ],
        half_extents: [
            0.5 * (hi[0] - lo[0]),
            0.5 * (hi[1] - lo[1]),
            0.5 * (hi[2] - lo[2]),
        ],
        yaw_rad: yaw,
    }
}

/// Every object of the map with at least `min_cells` occupied cells, by id.
pub fn extract_objects(map: &SrMap, options: &ObjectOptions) -> Vec<MapObject> {
    let mut by_id: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
    for (i, c) in map.cells().iter().enumerate() {
        if c.object != 0 && c.object_votes > 0 && c.occupied() {
            by_id.entry(c.object).or_default().push(i as u32);
        }
    }
    let r = map.resolution_m();
    by_id
        .into_par_iter()
        .filter(|(_, cells)| cells.len() >= options.min_cells.max(1))
        .map(|(id, cells)| {
            let points: Vec<[f64; 3]> = cells
                .iter()
                .map(|&i| map.centre(map.cells()[i as usize].key))
                .collect();
            let normals: Vec<[f64; 3]> = points
                .iter()
                .map(|&p| {
                    let near: Vec<[f64; 3]> = map
                        .cells_within_radius(p, options.normal_radius_m)
                        .into_iter()
                        .filter(|&j| map.cells()[j as usize].object == id)
                        .map(|j| map.centre(map.cells()[j as usize].key))
                        .collect();
                    normal_of(&near)
                })
                .collect();
            let mut votes = [0usize; Class::COUNT];
            for &i in &cells {
                votes[usize::from(map.cells()[i as usize].label).min(Class::COUNT - 1)] += 1;
            }
            let class = (0..Class::COUNT)
                .max_by(|&a, &b| votes[a].cmp(&votes[b]).then(b.cmp(&a)))
                .and_then(|j| Class::from_id(j as u8))
                .unwrap_or(Class::Unlabelled);
            let n = points.len() as f64;
            let centroid = [0, 1, 2].map(|k| points.iter().map(|p| p[k]).sum::<f64>() / n);
            let bbox = oriented_box(&points, &normals, options, 0.5 * r);
            MapObject {
                id,
                class,
                cells,
                centroid,
                bbox,
            }
        })
        .collect()
}

/// The normal of a neighbourhood (zero vector for fewer than 3 points).
fn normal_of(points: &[[f64; 3]]) -> [f64; 3] {
    if points.len() < 3 {
        return [0.0; 3];
    }
    let n = points.len() as f64;
    let m = [0, 1, 2].map(|k| points.iter().map(|p| p[k]).sum::<f64>() / n);
    let mut cov = [[0.0; 3]; 3];
    for p in points {
        let d = [p[0] - m[0], p[1] - m[1], p[2] - m[2]];
        for i in 0..3 {
            for j in 0..3 {
                cov[i][j] += d[i] * d[j];
            }
        }
    }
    smallest_eigenvector(cov)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::MapOptions;
    use geodata::cloud::{Columns, PointCloud, PointRecord, Precision};

    #[test]
    fn eigenvector_of_a_plane_is_its_normal() {
        let pts: Vec<[f64; 3]> = (0..10)
            .flat_map(|i| (0..10).map(move |j| [i as f64, j as f64 * 0.5, 0.3 * i as f64]))
            .collect();
        let n = normal_of(&pts);
        // Plane z = 0.3 x: normal ∝ (−0.3, 0, 1).
        let len = (0.09f64 + 1.0).sqrt();
        let dot = (n[0] * -0.3 + n[2]) / len;
        assert!(dot.abs() > 0.999, "normal {n:?}");
    }

    #[test]
    fn box_of_a_rotated_hollow_cuboid_recovers_yaw_and_extents() {
        // Surface points of a 4 × 2 × 1.5 m box rotated by 30°.
        let yaw: f64 = 30f64.to_radians();
        let (s, c) = yaw.sin_cos();
        let mut cloud = PointCloud::with_columns(
            Columns {
                object: true,
                label: true,
                ..Columns::default()
            },
            Precision::F64,
            0,
        );
        let step = 0.05;
        let mut push = |u: f64, v: f64, z: f64| {
            cloud.push(&PointRecord {
                position: [10.0 + c * u - s * v, 5.0 + s * u + c * v, z],
                object: 3,
                label: 1,
                ..PointRecord::default()
            });
        };
        let (nu, nv, nz) = (80, 40, 30);
        for i in 0..=nu {
            for k in 0..=nz {
                push(-2.0 + i as f64 * step, -1.0, k as f64 * step);
                push(-2.0 + i as f64 * step, 1.0, k as f64 * step);
            }
        }
        for j in 0..=nv {
            for k in 0..=nz {
                push(-2.0, -1.0 + j as f64 * step, k as f64 * step);
                push(2.0, -1.0 + j as f64 * step, k as f64 * step);
            }
        }
        let mut map = SrMap::new(MapOptions::default()).unwrap();
        map.insert_cloud(&cloud, None).unwrap();
        let objects = extract_objects(
            &map,
            &ObjectOptions {
                shrink_percentile: 0.0,
                ..ObjectOptions::default()
            },
        );
        assert_eq!(objects.len(), 1);
        let b = objects[0].bbox;
        let folded = b.yaw_rad.rem_euclid(std::f64::consts::FRAC_PI_2);
        assert!(
            (folded - yaw).abs() < 3f64.to_radians(),
            "yaw {}",
            b.yaw_rad.to_degrees()
        );
        let mut h = [b.half_extents[0], b.half_extents[1]];
        h.sort_by(f64::total_cmp);
        assert!(
            (h[0] - 1.0).abs() < 0.2 && (h[1] - 2.0).abs() < 0.2,
            "{h:?}"
        );
        assert!((b.centre[0] - 10.0).abs() < 0.15 && (b.centre[1] - 5.0).abs() < 0.15);
        assert_eq!(objects[0].class, Class::Car);
    }
}
