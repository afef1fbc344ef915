//! Per-bin features of thesis §4.4.2, one pass over a grid's bins.
//!
//! Per bin: mean, median, standard deviation and range of z (mean, median and minimum are
//! taken relative to the local ground, the lowest bin median within ±2.5 m, so that they do
//! not depend on the absolute height of the scene); the polar angle of the normal of the
//! points in the 3 × 3 bin neighbourhood; the same four statistics of intensity; the number of
//! points (log); 4-bin histograms of R, G, B and of H, S, V. Bins without points get no
//! features. The bin's true class (for training and evaluation) is the majority label of its
//! points within 0.25 m of the bin's lowest point (ground under a car or a tree counts, the car
//! or canopy does not) when that is a ground class ([`is_ground_class`]); a bin whose lowest
//! points are a car, a bicycle, a pole, a trunk or a wall has no true class: the ground under
//! it is not seen (the thesis' Fig. 4.4 leaves such bins unlabelled too), so it is left out of
//! training and scoring, though the model still uses its prediction.
//!
//! Cost: O(P log P) for the per-bin sorts plus O(B·w) for the local ground (w = window).

use crate::grid::BinGrid;
use geodata::classes::Class;
use geodata::cloud::PointCloud;
use nalgebra::{Matrix3, SymmetricEigen};

/// Number of features per bin.
pub const FEATURE_DIMS: usize = 35;

/// Names of the features, in order.
pub const FEATURE_NAMES: [&str; FEATURE_DIMS] = [
    "z_mean_above_ground",
    "z_median_above_ground",
    "z_std",
    "z_range",
    "normal_polar_angle",
    "intensity_mean",
    "intensity_median",
    "intensity_std",
    "intensity_range",
    "log_points",
    "z_min_above_ground",
    "r0",
    "r1",
    "r2",
    "r3",
    "g0",
    "g1",
    "g2",
    "g3",
    "b0",
    "b1",
    "b2",
    "b3",
    "h0",
    "h1",
    "h2",
    "h3",
    "s0",
    "s1",
    "s2",
    "s3",
    "v0",
    "v1",
    "v2",
    "v3",
];

/// Options of feature extraction.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FeatureOptions {
    /// Use the colour histograms (off: they are zero, e.g. to transfer to a cloud without RGB).
    pub colour: bool,
    /// Half window of the local ground estimate, metres.
    pub ground_window_m: f64,
    /// Standardise the geometric, intensity and density features per grid (a scan or a
    /// corridor): minus their median, over their inter-quartile range, across the grid's
    /// observed bins. What a street looks like then no longer depends on one sensor's
    /// intensity scale, noise level or point density, so a classifier trained on one sensor
    /// (or the simulator) transfers to another. Off by default (the models of issue 5).
    #[serde(default)]
    pub normalise: bool,
}

impl Default for FeatureOptions {
    fn default() -> Self {
        FeatureOptions {
            colour: true,
            ground_window_m: 2.5,
            normalise: false,
        }
    }
}

/// Features and true classes of a grid's bins.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BinFeatures {
    /// Row-major `bins × FEATURE_DIMS` (zeros for bins without points).
    pub values: Vec<f32>,
    /// Whether the bin holds points.
    pub observed: Vec<bool>,
    /// True class of the bin (majority label of its ground points), when labelled.
    pub truth: Vec<Option<Class>>,
    /// Height of the bin's lowest point above the local ground, metres, as measured (not
    /// standardised by [`FeatureOptions::normalise`]); NaN for bins without points.
    pub z_min_above_ground_m: Vec<f32>,
}

impl BinFeatures {
    /// The feature vector of bin k.
    pub fn row(&self, k: usize) -> &[f32] {
        &self.values[k * FEATURE_DIMS..(k + 1) * FEATURE_DIMS]
    }
}

/// Whether a class is a ground surface a bin can be labelled with: street, sidewalk, grass,
/// or other ground (KITTI-360's `ground`, the simulator's footways, squares and facade strips).
pub fn is_ground_class(class: Class) -> bool {
    matches!(
        class,
        Class::Street | Class::Sidewalk | Class::Grass | Class::Other
    )
}

fn hsv(rgb: [u8; 3]) -> [f32; 3] {
    let [r, g, b] = rgb.map(|c| f32::from(c) / 255.0);
    let max = r.max(g).max(b);
    let min = r.min(g).min(b);
    let d = max - min;
    let h = if d <= 0.0 {
        0.0
    } else if max == r {
        ((g - b) / d).rem_euclid(6.0) / 6.0
    } else if max == g {
        ((b - r) / d + 2.0) / 6.0
    } else {
        ((r - g) / d + 4.0) / 6.0
    };
    let s = if max <= 0.0 { 0.0 } else { d / max };
    [h, s, max]
}

fn stats(values: &mut [f32]) -> [f32; 4] {
    let n = values.len() as f32;
    let mean = values.iter().sum::<f32>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / n;
    values.sort_unstable_by(f32::total_cmp);
    let median = values[values.len() / 2];
    let range = values[values.len() - 1] - values[0];
    [mean, median, var.sqrt(), range]
}

/// Features of every bin of `grid`; `origin` is subtracted from positions (keeps f32 precise).
pub fn bin_features(
    grid: &BinGrid,
    cloud: &PointCloud,
    origin: [f64; 3],
    options: &FeatureOptions,
) -> BinFeatures {
    let n = grid.len();
    let mut values = vec![0f32; n * FEATURE_DIMS];
    let mut observed = vec![false; n];
    let mut truth = vec![None; n];
    let mut median_z = vec![f32::NAN; n];
    // Per-bin moment sums for the normals: n, Σp, Σppᵀ (relative to origin).
    let mut moments = vec![[0f64; 10]; n];
    let mut zs: Vec<f32> = Vec::new();
    let mut is: Vec<f32> = Vec::new();
    for k in 0..n {
        let ids = grid.points(k);
        if ids.is_empty() {
            continue;
        }
        observed[k] = true;
        zs.clear();
        is.clear();
        let mut zmin = f64::INFINITY;
        let m = &mut moments[k];
        for &id in ids {
            let p = cloud.positions[id as usize];
            let q = [p[0] - origin[0], p[1] - origin[1], p[2] - origin[2]];
            zs.push(q[2] as f32);
            zmin = zmin.min(q[2]);
            if let Some(i) = cloud.intensity.as_ref().and_then(|v| v.get(id as usize)) {
                is.push(*i);
            }
            m[0] += 1.0;
            m[1] += q[0];
            m[2] += q[1];
            m[3] += q[2];
            m[4] += q[0] * q[0];
            m[5] += q[0] * q[1];
            m[6] += q[0] * q[2];
            m[7] += q[1] * q[1];
            m[8] += q[1] * q[2];
            m[9] += q[2] * q[2];
        }
        let row = &mut values[k * FEATURE_DIMS..(k + 1) * FEATURE_DIMS];
        let z = stats(&mut zs);
        median_z[k] = z[1];
        row[0] = z[0];
        row[1] = z[1];
        row[2] = z[2];
        row[3] = z[3];
        row[10] = zmin as f32;
        if !is.is_empty() {
            let i = stats(&mut is);
            row[5..9].copy_from_slice(&i);
        }
        row[9] = (ids.len() as f32).ln_1p();
        if options.colour {
            if let Some(rgb) = &cloud.rgb {
                let w = 1.0 / ids.len() as f32;
                for &id in ids {
                    if let Some(&c) = rgb.get(id as usize) {
                        for ch in 0..3 {
                            row[11 + ch * 4 + (usize::from(c[ch]) >> 6)] += w;
                        }
                        let h = hsv(c);
                        for ch in 0..3 {
                            let b = ((h[ch] * 4.0) as usize).min(3);
                            row[23 + ch * 4 + b] += w;
                        }
                    }
                }
            }
        }
        // True class: majority label of points near the bin's lowest point.
        if let Some(labels) = &cloud.label {
            let mut hist = [0u32; Class::COUNT];
            for &id in ids {
                let p = cloud.positions[id as usize][2] - origin[2];
                if p <= zmin + 0.25 {
                    if let Some(&l) = labels.get(id as usize) {
                        if l != Class::Unlabelled.id() && usize::from(l) < Class::COUNT {
                            hist[usize::from(l)] += 1;
                        }
                    }
                }
            }
            let best = (0..Class::COUNT).max_by_key(|&c| (hist[c], std::cmp::Reverse(c)));
            truth[k] = best
                .filter(|&c| hist[c] > 0)
                .and_then(|c| Class::from_id(c as u8))
                .filter(|&c| is_ground_class(c));
        }
    }
    // Local ground: the lowest bin median within the window (separable sliding minimum).
    let (rows, cols) = (grid.rows, grid.cols);
    let w = (options.ground_window_m / grid.bin_m).round().max(0.0) as usize;
    let mut tmp = vec![f32::NAN; n];
    for r in 0..rows {
        for c in 0..cols {
            let lo = c.saturating_sub(w);
            let hi = (c + w).min(cols - 1);
            tmp[r * cols + c] = (lo..=hi)
                .map(|cc| median_z[r * cols + cc])
                .fold(f32::NAN, f32::min);
        }
    }
    let mut ground = vec![f32::NAN; n];
    for r in 0..rows {
        let lo = r.saturating_sub(w);
        let hi = (r + w).min(rows.saturating_sub(1));
        for c in 0..cols {
            ground[r * cols + c] = (lo..=hi)
                .map(|rr| tmp[rr * cols + c])
                .fold(f32::NAN, f32::min);
        }
    }
    for k in 0..n {
        if !observed[k] {
            continue;
        }
        let g = ground[k];
        let row = &mut values[k * FEATURE_DIMS..(k + 1) * FEATURE_DIMS];
        row[0] -= g;
        row[1] -= g;
        row[10] -= g;
        // Normal of the 3 × 3 neighbourhood: smallest eigenvector of the covariance.
        let (r, c) = (k / cols, k % cols);
        let mut m = [0f64; 10];
        for rr in r.saturating_sub(1)..=(r + 1).min(rows - 1) {
            for cc in c.saturating_sub(1)..=(c + 1).min(cols - 1) {
                let o = &moments[rr * cols + cc];
                for (a, b) in m.iter_mut().zip(o) {
                    *a += b;
                }
            }
        }
        let cnt = m[0];
        let angle = if cnt >= 3.0 {
            let mean = [m[1] / cnt, m[2] / cnt, m[3] / cnt];
            let cov = Matrix3::new(
                m[4] / cnt - mean[0] * mean[0],
                m[5] / cnt - mean[0] * mean[1],
                m[6] / cnt - mean[0] * mean[2],
                m[5] / cnt - mean[0] * mean[1],
                m[7] / cnt - mean[1] * mean[1],
                m[8] / cnt - mean[1] * mean[2],
                m[6] / cnt - mean[0] * mean[2],
                m[8] / cnt - mean[1] * mean[2],
                m[9] / cnt - mean[2] * mean[2],
            );
            let eig = SymmetricEigen::new(cov);
            let (imin, _) = eig
                .eigenvalues
                .iter()
                .enumerate()
                .min_by(|a, b| a.1.total_cmp(b.1))
                .unwrap_or((2, &0.0));
            let nz = eig.eigenvectors[(2, imin)].abs().min(1.0);
            nz.acos() as f32
        } else {
            0.0
        };
        row[4] = angle;
    }
    let z_min_above_ground_m = (0..n)
        .map(|k| {
            if observed[k] {
                values[k * FEATURE_DIMS + 10]
            } else {
                f32::NAN
            }
        })
        .collect();
    if options.normalise {
        standardise(&mut values, &observed);
    }
    BinFeatures {
        values,
        observed,
        truth,
        z_min_above_ground_m,
    }
}

/// The features [`FeatureOptions::normalise`] standardises: z statistics, normal angle,
/// intensity statistics, point count, lowest z (not the colour histograms).
pub const NORMALISED_FEATURES: std::ops::RangeInclusive<usize> = 0..=10;

/// Robust standardisation of [`NORMALISED_FEATURES`] over the observed bins: (x − median) / IQR
/// (the IQR floored at 10⁻³ so that a constant feature stays finite).
fn standardise(values: &mut [f32], observed: &[bool]) {
    let rows: Vec<usize> = (0..observed.len()).filter(|&k| observed[k]).collect();
    if rows.is_empty() {
        return;
    }
    let mut column: Vec<f32> = Vec::with_capacity(rows.len());
    for f in NORMALISED_FEATURES {
        column.clear();
        column.extend(rows.iter().map(|&k| values[k * FEATURE_DIMS + f]));
        let n = column.len();
        let q1 = *column.select_nth_unstable_by(n / 4, f32::total_cmp).1;
        let median = *column.select_nth_unstable_by(n / 2, f32::total_cmp).1;
        let q3 = *column.select_nth_unstable_by(3 * n / 4, f32::total_cmp).1;
        let iqr = (q3 - q1).max(1e-3);
        for &k in &rows {
            let v = &mut values[k * FEATURE_DIMS + f];
            *v = (*v - median) / iqr;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use geodata::cloud::{Columns, PointRecord, Precision};

    /// A 6 × 6 grid of 0.5 m bins: street (z 0, intensity `i_street`) in columns 0..3, a kerb
    /// 0.12 m up (intensity `i_kerb`) in 3..5, column 5 empty; `noise` roughens the heights.
    fn kerb_scene(
        i_street: f32,
        i_kerb: f32,
        points_per_bin: usize,
        noise: f64,
    ) -> (BinGrid, PointCloud) {
        let cols = Columns {
            intensity: true,
            label: true,
            ..Columns::default()
        };
        let mut cloud = PointCloud::with_columns(cols, Precision::F64, 0);
        let mut pairs = Vec::new();
        for r in 0..6 {
            for c in 0..5 {
                for k in 0..points_per_bin {
                    let x = 0.5 * c as f64 + 0.05 + 0.4 * (k % 3) as f64 / 3.0;
                    let y = 0.5 * r as f64 + 0.05 + 0.4 * (k / 3 % 3) as f64 / 3.0;
                    let wobble = noise * (((r * 7 + c * 3 + k) % 5) as f64 - 2.0) / 2.0;
                    let z = if c < 3 { 0.0 } else { 0.12 } + wobble;
                    pairs.push(((r * 6 + c) as u32, cloud.len() as u32));
                    cloud.push(&PointRecord {
                        position: [x, y, z],
                        intensity: if c < 3 { i_street } else { i_kerb },
                        label: if c < 3 {
                            Class::Street.id()
                        } else {
                            Class::Sidewalk.id()
                        },
                        ..PointRecord::default()
                    });
                }
            }
        }
        (BinGrid::from_pairs(6, 6, 0.5, &pairs), cloud)
    }

    #[test]
    fn normalised_features_do_not_depend_on_the_intensity_scale_or_the_density() {
        let options = FeatureOptions {
            normalise: true,
            ..FeatureOptions::default()
        };
        let (grid, cloud) = kerb_scene(0.3, 0.5, 9, 0.0);
        let a = bin_features(&grid, &cloud, [0.0; 3], &options);
        // Another sensor: intensities on a 0–255 scale, a third of the points.
        let (grid, cloud) = kerb_scene(0.3 * 255.0, 0.5 * 255.0, 3, 0.0);
        let b = bin_features(&grid, &cloud, [0.0; 3], &options);
        assert_eq!(a.observed, b.observed);
        for k in (0..36).filter(|&k| a.observed[k]) {
            for f in [0, 1, 5, 6, 9, 10] {
                assert!(
                    (a.row(k)[f] - b.row(k)[f]).abs() < 1e-4,
                    "bin {k} feature {} differs: {} vs {}",
                    FEATURE_NAMES[f],
                    a.row(k)[f],
                    b.row(k)[f]
                );
            }
        }
        // The raw features differ (the test could fail); the measured height of the lowest
        // point is kept as it is (corridors decide with it which bins saw the ground).
        let raw = bin_features(&grid, &cloud, [0.0; 3], &FeatureOptions::default());
        assert!((raw.row(0)[5] - a.row(0)[5]).abs() > 1.0);
        for k in (0..36).filter(|&k| raw.observed[k]) {
            assert_eq!(b.z_min_above_ground_m[k], raw.row(k)[10]);
        }
        assert!((b.z_min_above_ground_m[4] - 0.12).abs() < 1e-6);
        assert!(b.z_min_above_ground_m[5].is_nan());
        // Standardised over the observed bins: median 0; the empty column stays zero.
        for f in NORMALISED_FEATURES {
            let mut col: Vec<f32> = (0..36)
                .filter(|&k| a.observed[k])
                .map(|k| a.row(k)[f])
                .collect();
            col.sort_unstable_by(f32::total_cmp);
            assert!(col[col.len() / 2].abs() < 1e-6, "{}", FEATURE_NAMES[f]);
        }
        assert!(!a.observed[5] && a.row(5).iter().all(|&v| v == 0.0));
        // The kerb stays above the street after standardisation, with or without noise.
        let (grid, cloud) = kerb_scene(0.3, 0.5, 9, 0.02);
        let c = bin_features(&grid, &cloud, [0.0; 3], &options);
        for f in [&a, &c] {
            assert!(f.row(4)[1] > f.row(0)[1]);
        }
    }

    #[test]
    fn an_empty_grid_normalises_to_nothing() {
        let cloud = PointCloud::with_columns(Columns::default(), Precision::F64, 0);
        let grid = BinGrid::from_pairs(3, 3, 0.5, &[]);
        let options = FeatureOptions {
            normalise: true,
            ..FeatureOptions::default()
        };
        let f = bin_features(&grid, &cloud, [0.0; 3], &options);
        assert!(f.values.iter().all(|&v| v == 0.0) && !f.observed.iter().any(|&o| o));
    }

    #[test]
    fn flat_ground_and_a_wall_have_the_right_features() {
        let cols = Columns {
            intensity: true,
            rgb: true,
            label: true,
            ..Columns::default()
        };
        let mut cloud = PointCloud::with_columns(cols, Precision::F64, 0);
        let mut pairs = Vec::new();
        // 4 × 4 bins of 1 m; flat ground at z = 0 in columns 0..2, a kerb 0.15 m up in 2..4.
        for r in 0..4 {
            for c in 0..4 {
                for k in 0..9 {
                    let x = c as f64 + 0.1 + 0.1 * (k % 3) as f64;
                    let y = r as f64 + 0.1 + 0.1 * (k / 3) as f64;
                    let z = if c < 2 { 0.0 } else { 0.15 };
                    pairs.push(((r * 4 + c) as u32, cloud.len() as u32));
                    cloud.push(&PointRecord {
                        position: [x, y, z],
                        intensity: 0.5,
                        rgb: [200, 10, 10],
                        label: if c < 2 {
                            Class::Street.id()
                        } else {
                            Class::Sidewalk.id()
                        },
                        ..PointRecord::default()
                    });
                }
            }
        }
        let grid = BinGrid::from_pairs(4, 4, 1.0, &pairs);
        let f = bin_features(&grid, &cloud, [0.0; 3], &FeatureOptions::default());
        let street = f.row(0);
        let kerb = f.row(3);
        assert!(street[0].abs() < 1e-6, "street above ground {}", street[0]);
        assert!((kerb[0] - 0.15).abs() < 1e-6);
        assert!(street[4] < 1e-3, "flat ground normal angle {}", street[4]);
        assert!(
            f.row(1)[4] > 0.01,
            "step between street and kerb tilts the normal"
        );
        assert!((street[5] - 0.5).abs() < 1e-6);
        assert!((street[11 + 3] - 1.0).abs() < 1e-6, "red histogram top bin");
        assert_eq!(f.truth[0], Some(Class::Street));
        assert_eq!(f.truth[3], Some(Class::Sidewalk));
        assert!(f.observed.iter().all(|&o| o));
    }

    #[test]
    fn a_bin_whose_lowest_points_are_a_car_has_no_true_class() {
        let cols = Columns {
            label: true,
            ..Columns::default()
        };
        let mut cloud = PointCloud::with_columns(cols, Precision::F64, 0);
        let mut pairs = Vec::new();
        // Bin 0: car side points from 0.1 m up, no ground seen. Bin 1: other paved ground
        // under a few car points. Bin 2: a wall base.
        let mut add = |bin: u32, z: f64, class: Class| {
            pairs.push((bin, cloud.len() as u32));
            cloud.push(&PointRecord {
                position: [f64::from(bin) + 0.5, 0.5, z],
                label: class.id(),
                ..PointRecord::default()
            });
        };
        for k in 0..5 {
            add(0, 0.1 + 0.1 * f64::from(k), Class::Car);
            add(1, 0.15, Class::Other);
            add(2, 0.05 * f64::from(k), Class::Building);
        }
        add(1, 0.9, Class::Car);
        let grid = BinGrid::from_pairs(1, 3, 1.0, &pairs);
        let f = bin_features(&grid, &cloud, [0.0; 3], &FeatureOptions::default());
        assert_eq!(f.truth, vec![None, Some(Class::Other), None]);
        assert!(f.observed.iter().all(|&o| o));
    }
}
