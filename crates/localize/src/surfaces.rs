//! Vertical surface cells of a scan: voxel downsampling, a normal per occupied voxel, and
//! the voxels whose normal is horizontal, projected to the ground plane (thesis §5.3.2).
//!
//! The scan is gravity-levelled (z up), so a horizontal normal means a vertical surface.
//! Occupied voxels stand in for the RMAP cuboid cells of the thesis. Walls are tall, so the
//! normal of a voxel comes from its *column*: the points of a vertical surface stack up in
//! one ground-plane cell however far away it is, while a 3-D voxel neighbourhood holds about
//! one point beyond 40 m at a 0.4° scanner step. Per ground-plane column (cells of the voxel
//! size) the mean x, y of its points higher than `clearance_m` above the local ground (the
//! lowest point of a `ground_cell_m` cell and its neighbours) is one sample; a voxel above
//! the clearance gets the normal of the line fitted (2-D PCA) to the column samples within
//! `column_radius_m`, if they are collinear enough. Cars, pedestrians and low fences lie below
//! the clearance; tree crowns and poles give no line. Cost O(n) in the points plus
//! O(c · r²) for c occupied columns and r the radius in cells.

use crate::{LocalizeError, Result};
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
    /// Points lower than this above the local ground are clutter (cars, people), metres.
    pub clearance_m: f64,
    /// Cell side of the local ground estimate (lowest point), metres.
    pub ground_cell_m: f64,
    /// Radius of the column neighbourhood a normal is fitted to, metres.
    pub column_radius_m: f64,
    /// Largest ratio of the smaller to the larger eigenvalue of the columns' 2-D covariance.
    pub max_flatness: f64,
    /// Fewest columns in a neighbourhood for a normal.
    pub min_columns: usize,
    /// Largest share of a column's points with another return more than 1 m behind them in
    /// the same direction (a 0.5° × 0.8° bin): a wall hides what is behind it, a hedge or a
    /// tree crown lets beams through (1: no test).
    pub max_see_through: f64,
}

impl Default for SurfaceOptions {
    fn default() -> Self {
        SurfaceOptions {
            voxel_m: 0.3,
            max_range_m: 75.0,
            min_range_m: 1.5,
            min_z_m: -0.5,
            max_z_m: 30.0,
            clearance_m: 2.5,
            ground_cell_m: 2.0,
            column_radius_m: 1.2,
            max_flatness: 0.3,
            min_columns: 3,
            max_see_through: 1.0,
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

/// Sums of one column's points above the clearance.
#[derive(Clone, Copy, Default)]
struct Column {
    n: f64,
    sx: f64,
    sy: f64,
    /// Points with another return behind them.
    behind: f64,
}

/// Azimuth bin of the see-through test, degrees.
const SEE_AZ_DEG: f64 = 0.5;
/// Elevation bin of the see-through test, degrees.
const SEE_EL_DEG: f64 = 0.8;
/// A return this much farther in the same bin is behind, metres.
const SEE_GAP_M: f64 = 1.0;

/// The (azimuth, elevation) bin of a point for the see-through test, and its range.
fn direction_bin(p: &[f64; 3]) -> ([i32; 2], f64) {
    let r = p[0].hypot(p[1]);
    let az = p[1].atan2(p[0]).to_degrees();
    let el = p[2].atan2(r).to_degrees();
    (
        [
            (az / SEE_AZ_DEG).floor() as i32,
            (el / SEE_EL_DEG).floor() as i32,
        ],
        r,
    )
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
    let ground_inv = 1.0 / options.ground_cell_m.max(options.voxel_m);
    let (r2_max, r2_min) = (
        options.max_range_m * options.max_range_m,
        options.min_range_m * options.min_range_m,
    );
    let kept = |p: &[f64; 3]| {
        let r2 = p[0] * p[0] + p[1] * p[1];
        r2 <= r2_max && r2 >= r2_min && p[2] >= options.min_z_m && p[2] <= options.max_z_m
    };
    let ground_key = |p: &[f64; 3]| {
        [
            (p[0] * ground_inv).floor() as i32,
            (p[1] * ground_inv).floor() as i32,
        ]
    };
    // Local ground: the lowest point per ground cell (every point in range counts).
    let mut lowest: FxHashMap<[i32; 2], f64> = FxHashMap::default();
    for p in points {
        let r2 = p[0] * p[0] + p[1] * p[1];
        if r2 > r2_max || r2 < r2_min {
            continue;
        }
        let z = lowest.entry(ground_key(p)).or_insert(f64::INFINITY);
        *z = z.min(p[2]);
    }
    let ground_at = |key: [i32; 2]| -> f64 {
        let mut g = f64::INFINITY;
        for dx in -1..=1 {
            for dy in -1..=1 {
                if let Some(&z) = lowest.get(&[key[0] + dx, key[1] + dy]) {
                    g = g.min(z);
                }
            }
        }
        g
    };
    let ground: FxHashMap<[i32; 2], f64> = lowest.keys().map(|&k| (k, ground_at(k))).collect();
    // Farthest return per direction bin, for the see-through test.
    let see_through = options.max_see_through < 1.0;
    let mut farthest: FxHashMap<[i32; 2], f64> = FxHashMap::default();
    if see_through {
        for p in points.iter().filter(|p| kept(p)) {
            let (bin, r) = direction_bin(p);
            let f = farthest.entry(bin).or_insert(0.0);
            *f = f.max(r);
        }
    }
    // Columns and voxels of the points above the clearance.
    let mut columns: FxHashMap<[i32; 2], Column> = FxHashMap::default();
    let mut voxels: FxHashMap<[i32; 3], Column> = FxHashMap::default();
    for p in points.iter().filter(|p| kept(p)) {
        let g = ground.get(&ground_key(p)).copied().unwrap_or(f64::INFINITY);
        if p[2] < g + options.clearance_m {
            continue;
        }
        let key = [(p[0] * inv).floor() as i32, (p[1] * inv).floor() as i32];
        let c = columns.entry(key).or_default();
        c.n += 1.0;
        c.sx += p[0];
        c.sy += p[1];
        if see_through {
            let (bin, r) = direction_bin(p);
            if farthest.get(&bin).is_some_and(|&f| f > r + SEE_GAP_M) {
                c.behind += 1.0;
            }
        }
        let v = voxels
            .entry([key[0], key[1], (p[2] * inv).floor() as i32])
            .or_default();
        v.n += 1.0;
        v.sx += p[0];
        v.sy += p[1];
    }
    // A normal per column from the column means around it.
    let reach = (options.column_radius_m * inv).ceil() as i32;
    let r2 = options.column_radius_m * options.column_radius_m;
    let mut normals: FxHashMap<[i32; 2], f64> = FxHashMap::default();
    for (key, own) in &columns {
        if own.behind > options.max_see_through * own.n {
            continue;
        }
        let centre = [own.sx / own.n, own.sy / own.n];
        let (mut n, mut s) = (0.0, [0.0; 2]);
        let mut ss = [0.0; 3];
        for dx in -reach..=reach {
            for dy in -reach..=reach {
                let Some(c) = columns.get(&[key[0] + dx, key[1] + dy]) else {
                    continue;
                };
                let m = [c.sx / c.n, c.sy / c.n];
                let (ex, ey) = (m[0] - centre[0], m[1] - centre[1]);
                if ex * ex + ey * ey > r2 {
                    continue;
                }
                n += 1.0;
                s[0] += ex;
                s[1] += ey;
                ss[0] += ex * ex;
                ss[1] += ex * ey;
                ss[2] += ey * ey;
            }
        }
        if (n as usize) < options.min_columns.max(2) {
            continue;
        }
        let (mx, my) = (s[0] / n, s[1] / n);
        let (cxx, cxy, cyy) = (
            ss[0] / n - mx * mx,
            ss[1] / n - mx * my,
            ss[2] / n - my * my,
        );
        // Eigenvalues of the 2 × 2 covariance.
        let half_trace = 0.5 * (cxx + cyy);
        let root = (0.25 * (cxx - cyy) * (cxx - cyy) + cxy * cxy).sqrt();
        let (l_small, l_large) = (half_trace - root, half_trace + root);
        if l_large <= 0.0 || l_small > options.max_flatness * l_large {
            continue;
        }
        // The line's direction is the large eigenvector; the normal is perpendicular.
        let line_dir = geodata::osm::geometry::major_axis_angle([cxx, cxy, cyy]);
        normals.insert(*key, crate::wrap_pi(line_dir + std::f64::consts::FRAC_PI_2));
    }
    let mut keys: Vec<[i32; 3]> = voxels.keys().copied().collect();
    keys.sort_unstable();
    let mut cells = Vec::new();
    for key in keys {
        let (Some(v), Some(&normal_yaw_rad)) = (voxels.get(&key), normals.get(&[key[0], key[1]]))
        else {
            continue;
        };
        cells.push(SurfaceCell {
            xy: [v.sx / v.n, v.sy / v.n],
            z: (key[2] as f64 + 0.5) * options.voxel_m,
            normal_yaw_rad,
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

    /// A scanner at the origin, 1.8 m up, stepping 0.4° in azimuth and 0.5° in elevation,
    /// seeing a 12 m wall x = `dist` (|y| ≤ 20 m), a 1.5 m car-like box, and the ground.
    fn scanned_wall(dist: f64) -> Vec<[f64; 3]> {
        let mut pts = Vec::new();
        for a in 0..900 {
            let az = (a as f64 * 0.4).to_radians();
            for e in 0..120 {
                let el = (-30.0 + e as f64 * 0.5f64).to_radians();
                let d = [az.cos() * el.cos(), az.sin() * el.cos(), el.sin()];
                let mut t = f64::INFINITY;
                if d[2] < 0.0 {
                    t = t.min(1.8 / -d[2]);
                }
                if d[0] > 0.0 {
                    let tw = dist / d[0];
                    let (y, z) = (tw * d[1], tw * d[2]);
                    if y.abs() <= 20.0 && (-1.8..=10.2).contains(&z) {
                        t = t.min(tw);
                    }
                }
                // A car at x ∈ [-8, -4], y ∈ [-1, 1], up to 1.5 m over the ground.
                if d[0] < 0.0 {
                    let tc = -4.0 / d[0];
                    let (y, z) = (tc * d[1], tc * d[2]);
                    if y.abs() <= 1.0 && z <= -0.3 {
                        t = t.min(tc);
                    }
                }
                if t.is_finite() {
                    pts.push([t * d[0], t * d[1], t * d[2]]);
                }
            }
        }
        pts
    }

    #[test]
    fn far_walls_get_normals_and_low_clutter_does_not() {
        for dist in [10.0, 30.0, 55.0] {
            let cells = vertical_cells(&scanned_wall(dist), &SurfaceOptions::default()).unwrap();
            let on_wall: Vec<_> = cells
                .iter()
                .filter(|c| (c.xy[0] - dist).abs() < 0.3)
                .collect();
            assert!(
                on_wall.len() * 10 >= cells.len() * 9,
                "{dist} m: {} of {}",
                on_wall.len(),
                cells.len()
            );
            let ys: Vec<f64> = on_wall.iter().map(|c| c.xy[1]).collect();
            let span = ys.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
                - ys.iter().cloned().fold(f64::INFINITY, f64::min);
            assert!(span > 30.0, "{dist} m: wall seen over {span:.1} m");
            for c in on_wall {
                assert!(
                    crate::orientation_diff(c.normal_yaw_rad, 0.0) < 0.1,
                    "{c:?}"
                );
            }
            assert!(cells.iter().all(|c| c.xy[0] > 0.0), "the car got a normal");
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
