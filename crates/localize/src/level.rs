//! Levelling a scan whose sensor is tilted: the up direction estimated from its walls.
//!
//! The extraction assumes a gravity-levelled scan (z up). A sensor mounted with a pitch or a
//! roll, or a car on a camber, breaks that: a 4° tilt moves a wall point 30 m out by 2 m in
//! height, and on simulated HDL-64 scans of Helsinki top-1 fell from 60 to 41 of 80. The
//! ground is no reference for gravity (streets have grades of several degrees), the walls
//! are: a façade is vertical, so its normal is horizontal and the up direction is the one
//! orthogonal to every wall normal.
//!
//! The scan is cut into voxels; a voxel whose points lie on a plane (smallest eigenvalue of
//! their covariance small against the middle one) has that plane's normal. Voxels whose
//! normal is within a band of the horizontal (for the current up) are walls; the new up is
//! the eigenvector of the smallest eigenvalue of Σ n nᵀ over them (the direction least
//! aligned with any wall normal), refined with a narrowing band. Walls facing one direction
//! only (the middle eigenvalue of Σ n nᵀ small against the largest; a straight street) fix
//! the tilt across them; the tilt along them is then the ground's (a plane through the lowest
//! point of each 1 m cell), whose grade across the walls the wall constraint removes.
//! Without walls the scan is left as it is. A tilt below
//! [`LevelOptions::min_tilt_deg`] is left alone too, so a scan that is levelled already is
//! not changed by the estimate's noise. Cost O(points).
//!
//! Off by default ([`crate::pipeline::LocalizeOptions::level`]): on scans that are levelled
//! already (simulated, and MCD since its reader's extrinsic was corrected: the estimate found
//! it rolling every scan by about 3°) it changes no top-1, and on KITTI-360 it lowers the
//! extraction's precision (README, *Tilted sensors*).

use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use rustc_hash::FxHashMap;
use serde::{Deserialize, Serialize};

/// Options of the levelling.
#[derive(Debug, Clone, PartialEq)]
pub struct LevelOptions {
    /// Voxel side, metres.
    pub voxel_m: f64,
    /// Points nearer the sensor than this are left out (the car, the operator), metres.
    pub min_range_m: f64,
    /// Points farther than this are left out, metres.
    pub max_range_m: f64,
    /// Fewest points of a voxel with a normal.
    pub min_points: usize,
    /// Largest ratio of the smallest to the middle eigenvalue of a planar voxel.
    pub max_flatness: f64,
    /// Smallest spread of a planar voxel's points along its second axis, metres (points
    /// of one beam ring lie on a line, whose normal is not fixed).
    pub min_extent_m: f64,
    /// Smallest ratio of the middle to the largest eigenvalue of Σ n nᵀ (walls facing two
    /// directions at least).
    pub min_spread: f64,
    /// With walls facing one direction only, take the tilt along them from the ground.
    pub ground_fallback: bool,
    /// Reach of the ground fit, metres.
    pub ground_range_m: f64,
    /// Tilts below this are not corrected, degrees.
    pub min_tilt_deg: f64,
    /// Tilts above this are not corrected (not a tilted car sensor), degrees.
    pub max_tilt_deg: f64,
}

impl Default for LevelOptions {
    fn default() -> Self {
        LevelOptions {
            voxel_m: 0.5,
            min_range_m: 2.0,
            max_range_m: 40.0,
            min_points: 8,
            max_flatness: 0.05,
            min_extent_m: 0.1,
            min_spread: 0.05,
            ground_fallback: true,
            ground_range_m: 20.0,
            min_tilt_deg: 1.0,
            max_tilt_deg: 30.0,
        }
    }
}

/// The levelling of a mode name as the command line and plans write it: `off` is `None`,
/// `auto` the default options; an unknown name is `Err` with what is expected.
pub fn options_named(name: &str) -> Result<Option<LevelOptions>, &'static str> {
    match name {
        "off" => Ok(None),
        "auto" => Ok(Some(LevelOptions::default())),
        _ => Err("expected off or auto"),
    }
}

/// What the levelling found and did.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Levelling {
    /// The estimated up direction in the scan's frame (`None`: too few walls, or walls
    /// facing one direction only).
    pub up: Option<[f64; 3]>,
    /// Angle between the estimated up and the scan's z axis, degrees (0 without an estimate).
    pub tilt_deg: f64,
    /// Wall voxels of the last refinement.
    pub wall_voxels: usize,
    /// Whether the scan was rotated.
    pub applied: bool,
}

/// Per-voxel sums of the points (count, Σp, Σppᵀ).
#[derive(Default, Clone, Copy)]
struct Moments {
    n: usize,
    s: [f64; 3],
    ss: [[f64; 3]; 3],
}

/// Whether `p` is finite and lies `min_m`–`max_m` from the sensor horizontally.
fn in_ring(p: &[f64; 3], min_m: f64, max_m: f64) -> bool {
    let r = p[0].hypot(p[1]);
    p.iter().all(|v| v.is_finite()) && r >= min_m && r <= max_m
}

/// The indices of a symmetric eigen-decomposition's values, smallest first.
fn ascending(eig: &SymmetricEigen<f64, nalgebra::U3>) -> [usize; 3] {
    let mut idx = [0usize, 1, 2];
    idx.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    idx
}

/// The unit normals of the planar voxels of `points`.
fn planar_normals(points: &[[f64; 3]], o: &LevelOptions) -> Vec<Vector3<f64>> {
    let inv = 1.0 / o.voxel_m;
    let mut voxels: FxHashMap<(i64, i64, i64), Moments> = FxHashMap::default();
    let mut order: Vec<(i64, i64, i64)> = Vec::new();
    for p in points {
        if !in_ring(p, o.min_range_m, o.max_range_m) {
            continue;
        }
        let key = (
            (p[0] * inv).floor() as i64,
            (p[1] * inv).floor() as i64,
            (p[2] * inv).floor() as i64,
        );
        let m = voxels.entry(key).or_insert_with(|| {
            order.push(key);
            Moments::default()
        });
        m.n += 1;
        for i in 0..3 {
            m.s[i] += p[i];
            for j in 0..3 {
                m.ss[i][j] += p[i] * p[j];
            }
        }
    }
    let mut normals = Vec::new();
    for key in order {
        let m = voxels[&key];
        if m.n < o.min_points {
            continue;
        }
        let n = m.n as f64;
        let mean = [m.s[0] / n, m.s[1] / n, m.s[2] / n];
        let cov = Matrix3::from_fn(|i, j| m.ss[i][j] / n - mean[i] * mean[j]);
        let eig = SymmetricEigen::new(cov);
        let idx = ascending(&eig);
        let (l0, l1) = (eig.eigenvalues[idx[0]], eig.eigenvalues[idx[1]]);
        if l1 < o.min_extent_m * o.min_extent_m || l0 > o.max_flatness * l1 {
            continue;
        }
        let v = eig.eigenvectors.column(idx[0]).into_owned();
        let norm = v.norm();
        if norm > 0.0 {
            normals.push(v / norm);
        }
    }
    normals
}

/// The normal of the ground around the sensor (up to `ground_range_m`): a plane fitted to
/// the lowest point of every 1 m cell, twice without the cells more than 0.2 m off it.
fn ground_normal(points: &[[f64; 3]], o: &LevelOptions) -> Option<Vector3<f64>> {
    let mut lowest: FxHashMap<(i64, i64), [f64; 3]> = FxHashMap::default();
    let mut order: Vec<(i64, i64)> = Vec::new();
    for p in points {
        if !in_ring(p, o.min_range_m, o.ground_range_m) {
            continue;
        }
        let key = (p[0].floor() as i64, p[1].floor() as i64);
        let e = lowest.entry(key).or_insert_with(|| {
            order.push(key);
            *p
        });
        if p[2] < e[2] {
            *e = *p;
        }
    }
    let cells: Vec<[f64; 3]> = order.iter().map(|k| lowest[k]).collect();
    let mut plane: Option<Vector3<f64>> = None;
    for _ in 0..3 {
        let mut ata = Matrix3::<f64>::zeros();
        let mut atb = Vector3::<f64>::zeros();
        let mut n = 0;
        for c in &cells {
            if let Some(q) = plane {
                if (c[2] - (q.x * c[0] + q.y * c[1] + q.z)).abs() > 0.2 {
                    continue;
                }
            }
            let v = Vector3::new(c[0], c[1], 1.0);
            ata += v * v.transpose();
            atb += v * c[2];
            n += 1;
        }
        if n < 20 {
            return None;
        }
        plane = Some(ata.lu().solve(&atb)?);
    }
    let q = plane?;
    Some(Vector3::new(-q.x, -q.y, 1.0).normalize())
}

/// The up direction of a scan from its walls, with the wall voxels of the last refinement;
/// `None` when the walls do not fix it. Walls that all face one direction fix only the tilt
/// across them: the component along them is then the ground's (a street's grade included).
pub fn estimate_up(points: &[[f64; 3]], o: &LevelOptions) -> (Option<[f64; 3]>, usize) {
    let normals = planar_normals(points, o);
    let mut up = Vector3::new(0.0, 0.0, 1.0);
    let mut walls = 0;
    for band_deg in [30.0f64, 15.0, 8.0, 4.0, 2.0] {
        let max_dot = band_deg.to_radians().sin();
        let mut m = Matrix3::<f64>::zeros();
        walls = 0;
        for n in &normals {
            if n.dot(&up).abs() < max_dot {
                m += n * n.transpose();
                walls += 1;
            }
        }
        if walls == 0 {
            return (None, 0);
        }
        let eig = SymmetricEigen::new(m);
        let idx = ascending(&eig);
        let (l1, l2) = (eig.eigenvalues[idx[1]], eig.eigenvalues[idx[2]]);
        if l2 <= 0.0 {
            return (None, walls);
        }
        let mut v = if l1 < o.min_spread * l2 {
            // One wall direction w: up ⟂ w, the rest from the ground.
            if !o.ground_fallback {
                return (None, walls);
            }
            let Some(g) = ground_normal(points, o) else {
                return (None, walls);
            };
            let w = eig.eigenvectors.column(idx[2]).into_owned();
            let v = g - w * g.dot(&w);
            if v.norm() < 0.5 {
                return (None, walls);
            }
            v
        } else {
            eig.eigenvectors.column(idx[0]).into_owned()
        };
        if v.z < 0.0 {
            v = -v;
        }
        up = v / v.norm();
    }
    (Some([up.x, up.y, up.z]), walls)
}

/// The rotation that turns `up` into +z about the axis `up × z` (the heading is kept).
fn rotation_to_z(up: [f64; 3]) -> [[f64; 3]; 3] {
    let u = Vector3::new(up[0], up[1], up[2]).normalize();
    let z = Vector3::new(0.0, 0.0, 1.0);
    let axis = u.cross(&z);
    let s = axis.norm();
    let c = u.dot(&z);
    if s < 1e-15 {
        return [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    }
    let k = axis / s;
    let kx = Matrix3::new(0.0, -k.z, k.y, k.z, 0.0, -k.x, -k.y, k.x, 0.0);
    let r = Matrix3::identity() + kx * s + kx * kx * (1.0 - c);
    [
        [r[(0, 0)], r[(0, 1)], r[(0, 2)]],
        [r[(1, 0)], r[(1, 1)], r[(1, 2)]],
        [r[(2, 0)], r[(2, 1)], r[(2, 2)]],
    ]
}

/// Levels `points` in place when their walls show a tilt between the options' bounds.
pub fn level(points: &mut [[f64; 3]], o: &LevelOptions) -> Levelling {
    let (up, wall_voxels) = estimate_up(points, o);
    let Some(u) = up else {
        return Levelling {
            up: None,
            tilt_deg: 0.0,
            wall_voxels,
            applied: false,
        };
    };
    let tilt_deg = u[2].clamp(-1.0, 1.0).acos().to_degrees();
    let applied = tilt_deg >= o.min_tilt_deg && tilt_deg <= o.max_tilt_deg;
    if applied {
        let r = rotation_to_z(u);
        for p in points.iter_mut() {
            let [x, y, z] = *p;
            *p = [
                r[0][0] * x + r[0][1] * y + r[0][2] * z,
                r[1][0] * x + r[1][1] * y + r[1][2] * z,
                r[2][0] * x + r[2][1] * y + r[2][2] * z,
            ];
        }
    }
    Levelling {
        up,
        tilt_deg,
        wall_voxels,
        applied,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two perpendicular walls (x = 10 and y = 12, 8 m high) and a sloping ground (5 %
    /// grade along x), sampled every 0.1 m, then tilted by `pitch` about y and `roll` about x.
    fn corner(pitch_deg: f64, roll_deg: f64) -> Vec<[f64; 3]> {
        let mut pts = Vec::new();
        for i in 0..200 {
            for k in 0..80 {
                let t = -10.0 + 0.1 * i as f64;
                let z = 0.1 * k as f64 - 1.5;
                pts.push([10.0, t, z]);
                pts.push([t, 12.0, z]);
            }
        }
        for i in 0..150 {
            for j in 0..150 {
                let (x, y) = (-7.0 + 0.1 * i as f64, -7.0 + 0.1 * j as f64);
                pts.push([x, y, -1.7 + 0.05 * x]);
            }
        }
        let (sp, cp) = pitch_deg.to_radians().sin_cos();
        let (sr, cr) = roll_deg.to_radians().sin_cos();
        pts.iter()
            .map(|&[x, y, z]| {
                let (x1, z1) = (cp * x + sp * z, -sp * x + cp * z);
                [x1, cr * y - sr * z1, sr * y + cr * z1]
            })
            .collect()
    }

    #[test]
    fn a_tilted_corner_is_levelled_by_its_walls_not_by_the_sloping_ground() {
        let o = LevelOptions::default();
        let mut pts = corner(4.0, -2.5);
        let l = level(&mut pts, &o);
        assert!(l.applied, "{l:?}");
        let expected = (4.0f64.to_radians().cos() * 2.5f64.to_radians().cos()).acos();
        assert!(
            (l.tilt_deg - expected.to_degrees()).abs() < 0.05,
            "{l:?} vs {}",
            expected.to_degrees()
        );
        // After levelling both walls are vertical again: the top and bottom of a wall
        // column have the same x (wall x = 10) or y (wall y = 12).
        let (est, _) = estimate_up(&pts, &o);
        let up = est.unwrap();
        assert!(up[2] > (0.02f64).to_radians().cos(), "{up:?}");
    }

    #[test]
    fn a_levelled_scan_on_a_grade_is_left_alone() {
        let o = LevelOptions::default();
        let mut pts = corner(0.0, 0.0);
        let before = pts.clone();
        let l = level(&mut pts, &o);
        assert!(!l.applied && l.tilt_deg < 0.05, "{l:?}");
        assert_eq!(pts, before);
    }

    #[test]
    fn the_extraction_levels_a_tilted_scan_when_asked() {
        let tilted = corner(6.0, 3.0);
        let mut o = crate::pipeline::LocalizeOptions::default();
        let off = crate::pipeline::scan_segments(&o, &tilted).unwrap();
        assert_eq!(off.levelling, None);
        o.level = Some(LevelOptions::default());
        let on = crate::pipeline::scan_segments(&o, &tilted).unwrap();
        let l = on.levelling.unwrap();
        assert!(l.applied && (l.tilt_deg - 6.7).abs() < 0.1, "{l:?}");
        // Levelled, both walls come out as segments along x = 10 and y = 12.
        let on_wall = |s: &crate::Segment| {
            let xs = [s.a[0], s.b[0]];
            let ys = [s.a[1], s.b[1]];
            xs.iter().all(|x| (x - 10.0).abs() < 0.3) || ys.iter().all(|y| (y - 12.0).abs() < 0.3)
        };
        assert!(on.segments.len() >= 2, "{:?}", on.segments);
        assert!(on.segments.iter().all(on_wall), "{:?}", on.segments);
    }

    #[test]
    fn one_wall_takes_the_tilt_along_it_from_the_ground_or_gives_no_estimate() {
        // Pitched 3° about y: the wall x = 10 faces along x, the ground's 5 % grade runs
        // along x too, so the wall removes the grade and the ground gives the rest.
        let one: Vec<[f64; 3]> = corner(3.0, 0.0)
            .into_iter()
            .filter(|p| p[1] < 11.0)
            .collect();
        let (up, _) = estimate_up(&one, &LevelOptions::default());
        let up = up.unwrap();
        let tilt = up[2].acos().to_degrees();
        assert!((tilt - 3.0).abs() < 0.1, "{up:?}");
        let walls_only = LevelOptions {
            ground_fallback: false,
            ..LevelOptions::default()
        };
        assert!(estimate_up(&one, &walls_only).0.is_none());
        let o = LevelOptions::default();
        let mut empty: Vec<[f64; 3]> = Vec::new();
        let l = level(&mut empty, &o);
        assert!(l.up.is_none() && !l.applied);
        let mut nan = vec![[f64::NAN; 3]; 10];
        assert!(!level(&mut nan, &o).applied);
    }
}
