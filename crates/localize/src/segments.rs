//! Building outline segments from vertical-surface cells: one 2-D histogram per normal-yaw
//! bin, the progressive probabilistic Hough transform per histogram, and merging of
//! parallel near-coincident and collinear segments (thesis §5.3.2).
//!
//! The Hough transform is the progressive probabilistic one of Matas, Galambos and Kittler,
//! "Robust detection of lines using the progressive probabilistic Hough transform", CVIU 78
//! (2000), doi:10.1006/cviu.1999.0831, with the normal angle restricted to the bin (± one bin
//! width). Each found segment is refitted by total least squares to the pixels it claimed.
//! Cost per bin: O(p · a) for p on-pixels and a angles, plus the walks along found lines.

use crate::surfaces::SurfaceCell;
use crate::{orientation_diff, Segment};
use geodata::osm::geometry::{major_axis_angle, mean_and_scatter};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// Options of the segment extraction.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentOptions {
    /// Number of normal-yaw bins over [0, π).
    pub yaw_bins: usize,
    /// Histogram cell size, metres.
    pub cell_m: f64,
    /// Fewest surface cells in a histogram pixel for it to count.
    pub min_cell_count: u32,
    /// Angular step of the Hough accumulator, degrees.
    pub theta_step_deg: f64,
    /// Votes a line needs before it is walked.
    pub votes_threshold: u32,
    /// Shortest segment the Hough transform returns, metres.
    pub min_length_m: f64,
    /// Longest gap bridged while walking a line, metres.
    pub max_gap_m: f64,
    /// Half-width of the band of pixels a line claims, pixels.
    pub band_px: i32,
    /// Largest orientation difference of merged segments, radians.
    pub merge_angle_rad: f64,
    /// Largest perpendicular distance of merged segments, metres.
    pub merge_distance_m: f64,
    /// Largest gap along the line between merged collinear segments, metres.
    pub merge_gap_m: f64,
    /// Shortest segment kept after merging, metres.
    pub final_min_length_m: f64,
    /// Seed of the Hough transform's random point order.
    pub seed: u64,
}

impl Default for SegmentOptions {
    fn default() -> Self {
        SegmentOptions {
            yaw_bins: 12,
            cell_m: 0.3,
            min_cell_count: 2,
            theta_step_deg: 1.0,
            votes_threshold: 8,
            min_length_m: 2.0,
            max_gap_m: 1.2,
            band_px: 1,
            merge_angle_rad: 8f64.to_radians(),
            merge_distance_m: 0.35,
            merge_gap_m: 2.0,
            final_min_length_m: 2.5,
            seed: 1,
        }
    }
}

/// A 2-D histogram of counts on a square grid.
#[derive(Debug, Clone, PartialEq)]
pub struct Histogram {
    /// Lower-left corner of pixel (0, 0), metres.
    pub origin: [f64; 2],
    /// Pixel size, metres.
    pub cell_m: f64,
    /// Pixels along x.
    pub width: usize,
    /// Pixels along y.
    pub height: usize,
    /// Counts, row-major (y · width + x).
    pub counts: Vec<u32>,
}

impl Histogram {
    /// An empty histogram covering `min..max`.
    pub fn new(min: [f64; 2], max: [f64; 2], cell_m: f64) -> Histogram {
        let width = (((max[0] - min[0]) / cell_m).ceil() as usize).max(1) + 1;
        let height = (((max[1] - min[1]) / cell_m).ceil() as usize).max(1) + 1;
        Histogram {
            origin: min,
            cell_m,
            width,
            height,
            counts: vec![0; width * height],
        }
    }

    /// Adds one count at a point (ignored outside).
    pub fn add(&mut self, p: [f64; 2]) {
        let x = ((p[0] - self.origin[0]) / self.cell_m).floor();
        let y = ((p[1] - self.origin[1]) / self.cell_m).floor();
        if x >= 0.0 && y >= 0.0 && (x as usize) < self.width && (y as usize) < self.height {
            self.counts[y as usize * self.width + x as usize] += 1;
        }
    }

    fn centre(&self, x: i32, y: i32) -> [f64; 2] {
        [
            self.origin[0] + (x as f64 + 0.5) * self.cell_m,
            self.origin[1] + (y as f64 + 0.5) * self.cell_m,
        ]
    }
}

/// Segments of the surface cells, merged, in the sensor frame.
pub fn extract_segments(cells: &[SurfaceCell], options: &SegmentOptions) -> Vec<Segment> {
    if cells.is_empty() || options.yaw_bins == 0 || options.cell_m <= 0.0 {
        return Vec::new();
    }
    let (mut min, mut max) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for c in cells {
        for k in 0..2 {
            min[k] = min[k].min(c.xy[k]);
            max[k] = max[k].max(c.xy[k]);
        }
    }
    let bins = options.yaw_bins;
    let width = std::f64::consts::PI / bins as f64;
    let mut histograms: Vec<Histogram> = (0..bins)
        .map(|_| Histogram::new(min, max, options.cell_m))
        .collect();
    for c in cells {
        // Each cell goes into its two nearest bins (bins overlap by half a bin each side).
        let f = c.normal_yaw_rad / width;
        let lower = f.floor() as i64;
        let near = f.round() as i64;
        let other = if near == lower { lower - 1 } else { lower + 1 };
        for b in [near, other] {
            let b = b.rem_euclid(bins as i64) as usize;
            if let Some(h) = histograms.get_mut(b) {
                h.add(c.xy);
            }
        }
    }
    let mut all = Vec::new();
    for (b, h) in histograms.iter().enumerate() {
        let centre = b as f64 * width;
        let seed = options.seed ^ (b as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        all.extend(hough_segments(
            h,
            (centre - width, centre + width),
            options,
            seed,
        ));
    }
    let merged = merge_segments(all, options);
    merged
        .into_iter()
        .filter(|s| s.length() >= options.final_min_length_m)
        .collect()
}

/// Line segments in one histogram by the progressive probabilistic Hough transform, with
/// the line normal angle restricted to `normal_range_rad`.
pub fn hough_segments(
    image: &Histogram,
    normal_range_rad: (f64, f64),
    options: &SegmentOptions,
    seed: u64,
) -> Vec<Segment> {
    let (w, h) = (image.width as i32, image.height as i32);
    let on = |x: i32, y: i32| -> bool {
        x >= 0
            && y >= 0
            && x < w
            && y < h
            && image.counts[(y * w + x) as usize] >= options.min_cell_count
    };
    let step = options.theta_step_deg.to_radians().max(1e-4);
    let n_theta = (((normal_range_rad.1 - normal_range_rad.0) / step).round() as usize).max(1) + 1;
    let trig: Vec<(f64, f64)> = (0..n_theta)
        .map(|t| (normal_range_rad.0 + t as f64 * step).sin_cos())
        .map(|(s, c)| (c, s))
        .collect();
    let offset = w + h;
    let n_rho = (2 * offset + 1) as usize;
    let mut accum = vec![0i32; n_theta * n_rho];
    let rho_index = |t: usize, x: i32, y: i32| -> usize {
        let (c, s) = trig[t];
        let r = (x as f64 * c + y as f64 * s).round() as i32 + offset;
        t * n_rho + r.clamp(0, 2 * offset) as usize
    };
    let mut points: Vec<(i32, i32)> = Vec::new();
    for y in 0..h {
        for x in 0..w {
            if on(x, y) {
                points.push((x, y));
            }
        }
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    points.shuffle(&mut rng);
    let mut mask = vec![false; image.counts.len()];
    let mut voted = vec![false; image.counts.len()];
    for &(x, y) in &points {
        mask[(y * w + x) as usize] = true;
    }
    let max_gap_px = (options.max_gap_m / image.cell_m).round() as i32;
    let min_len_px = options.min_length_m / image.cell_m;
    let mut out = Vec::new();
    for &(x0, y0) in &points {
        let idx0 = (y0 * w + x0) as usize;
        if !mask[idx0] {
            continue;
        }
        let mut best = (0i32, 0usize);
        for t in 0..n_theta {
            let i = rho_index(t, x0, y0);
            accum[i] += 1;
            if accum[i] > best.0 {
                best = (accum[i], t);
            }
        }
        voted[idx0] = true;
        if (best.0 as u32) < options.votes_threshold {
            continue;
        }
        let (c, s) = trig[best.1];
        let dir = [-s, c];
        let dominant_x = dir[0].abs() >= dir[1].abs();
        let unit = 1.0 / dir[0].abs().max(dir[1].abs());
        let band = |px: i32, py: i32| -> Vec<(i32, i32)> {
            (-options.band_px..=options.band_px)
                .map(|k| {
                    if dominant_x {
                        (px, py + k)
                    } else {
                        (px + k, py)
                    }
                })
                .collect()
        };
        // Walk both ways from the seed pixel to find the ends.
        let mut ends = [[x0 as f64, y0 as f64]; 2];
        for (e, sign) in [1.0f64, -1.0].iter().enumerate() {
            let mut gap = 0;
            let mut k = 1.0;
            loop {
                let px = x0 as f64 + sign * k * unit * dir[0];
                let py = y0 as f64 + sign * k * unit * dir[1];
                let (ix, iy) = (px.round() as i32, py.round() as i32);
                if ix < 0 || iy < 0 || ix >= w || iy >= h {
                    break;
                }
                if band(ix, iy).iter().any(|&(bx, by)| {
                    bx >= 0 && by >= 0 && bx < w && by < h && mask[(by * w + bx) as usize]
                }) {
                    gap = 0;
                    ends[e] = [px, py];
                } else {
                    gap += 1;
                    if gap > max_gap_px {
                        break;
                    }
                }
                k += 1.0;
            }
        }
        let len_px = (ends[0][0] - ends[1][0]).hypot(ends[0][1] - ends[1][1]);
        let good = len_px >= min_len_px;
        // Walk from end to end, claiming (and, for a good line, un-voting) the band pixels.
        let steps = (len_px / unit).round() as i32;
        let mut claimed: Vec<(i32, i32)> = Vec::new();
        for k in 0..=steps {
            let px = ends[1][0] + k as f64 * unit * dir[0];
            let py = ends[1][1] + k as f64 * unit * dir[1];
            for (bx, by) in band(px.round() as i32, py.round() as i32) {
                if bx < 0 || by < 0 || bx >= w || by >= h {
                    continue;
                }
                let i = (by * w + bx) as usize;
                if !mask[i] {
                    continue;
                }
                if good {
                    mask[i] = false;
                    if voted[i] {
                        for t in 0..n_theta {
                            let j = rho_index(t, bx, by);
                            accum[j] -= 1;
                        }
                        voted[i] = false;
                    }
                    claimed.push((bx, by));
                } else if i == idx0 {
                    mask[i] = false;
                }
            }
        }
        if good {
            let pts: Vec<[f64; 2]> = claimed.iter().map(|&(x, y)| image.centre(x, y)).collect();
            let a = image.centre(0, 0);
            let to_m = |p: [f64; 2]| [a[0] + p[0] * image.cell_m, a[1] + p[1] * image.cell_m];
            if let Some(seg) = fit_segment(&pts, to_m(ends[1]), to_m(ends[0])) {
                out.push(seg);
            }
        }
    }
    out
}

/// The total-least-squares line through `points`, cut at the projections of `a` and `b`.
fn fit_segment(points: &[[f64; 2]], a: [f64; 2], b: [f64; 2]) -> Option<Segment> {
    if points.len() < 2 {
        return None;
    }
    let ([mx, my], scatter) = mean_and_scatter(points);
    let angle = major_axis_angle(scatter);
    let d = [angle.cos(), angle.sin()];
    let proj = |p: [f64; 2]| (p[0] - mx) * d[0] + (p[1] - my) * d[1];
    let mut ts: Vec<f64> = points.iter().map(|&p| proj(p)).collect();
    ts.push(proj(a));
    ts.push(proj(b));
    let (t0, t1) = (proj(a).min(proj(b)), proj(a).max(proj(b)));
    if !(t1 - t0).is_finite() || t1 - t0 <= 0.0 {
        return None;
    }
    Some(Segment::new(
        [mx + t0 * d[0], my + t0 * d[1]],
        [mx + t1 * d[0], my + t1 * d[1]],
    ))
}

/// Merges parallel near-coincident segments and collinear segments with small gaps until
/// no pair qualifies. O(n²) per merge round.
pub fn merge_segments(mut segments: Vec<Segment>, options: &SegmentOptions) -> Vec<Segment> {
    segments.retain(|s| s.length() > 0.0);
    loop {
        let mut merged_any = false;
        'outer: for i in 0..segments.len() {
            for j in (i + 1)..segments.len() {
                if let Some(m) = try_merge(&segments[i], &segments[j], options) {
                    segments[i] = m;
                    segments.swap_remove(j);
                    merged_any = true;
                    break 'outer;
                }
            }
        }
        if !merged_any {
            break;
        }
    }
    segments.sort_by(|a, b| b.length().total_cmp(&a.length()));
    segments
}

fn try_merge(s: &Segment, t: &Segment, options: &SegmentOptions) -> Option<Segment> {
    if orientation_diff(s.orientation_rad(), t.orientation_rad()) > options.merge_angle_rad {
        return None;
    }
    let (long, short) = if s.length() >= t.length() {
        (s, t)
    } else {
        (t, s)
    };
    let len = long.length();
    let d = [(long.b[0] - long.a[0]) / len, (long.b[1] - long.a[1]) / len];
    let perp = |p: [f64; 2]| ((p[0] - long.a[0]) * -d[1] + (p[1] - long.a[1]) * d[0]).abs();
    if perp(short.a).max(perp(short.b)) > options.merge_distance_m {
        return None;
    }
    let along = |p: [f64; 2]| (p[0] - long.a[0]) * d[0] + (p[1] - long.a[1]) * d[1];
    let (sa, sb) = (along(short.a), along(short.b));
    let (s0, s1) = (sa.min(sb), sa.max(sb));
    let gap = (s0 - len).max(0.0 - s1).max(0.0);
    if gap > options.merge_gap_m {
        return None;
    }
    Some(fit_two(long, short))
}

/// The total-least-squares line of two segments taken as uniform mass along their lengths
/// (the principal axis of their joint second moments), cut at the extreme projections of
/// their end points.
fn fit_two(s: &Segment, t: &Segment) -> Segment {
    let parts = [s, t].map(|g| {
        let l = g.length();
        let m = [(g.a[0] + g.b[0]) * 0.5, (g.a[1] + g.b[1]) * 0.5];
        let d = [(g.b[0] - g.a[0]) / l, (g.b[1] - g.a[1]) / l];
        (l, m, d)
    });
    let total: f64 = parts.iter().map(|p| p.0).sum();
    let mx = parts.iter().map(|p| p.0 * p.1[0]).sum::<f64>() / total;
    let my = parts.iter().map(|p| p.0 * p.1[1]).sum::<f64>() / total;
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for (l, m, d) in parts {
        let (dx, dy) = (m[0] - mx, m[1] - my);
        let spread = l * l / 12.0;
        sxx += l * (dx * dx + spread * d[0] * d[0]);
        sxy += l * (dx * dy + spread * d[0] * d[1]);
        syy += l * (dy * dy + spread * d[1] * d[1]);
    }
    let angle = major_axis_angle([sxx, sxy, syy]);
    let d = [angle.cos(), angle.sin()];
    let proj = |p: [f64; 2]| (p[0] - mx) * d[0] + (p[1] - my) * d[1];
    let ts = [s.a, s.b, t.a, t.b].map(proj);
    let t0 = ts.iter().copied().fold(f64::INFINITY, f64::min);
    let t1 = ts.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    Segment::new(
        [mx + t0 * d[0], my + t0 * d[1]],
        [mx + t1 * d[0], my + t1 * d[1]],
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;

    fn cells_on(seg: &Segment, spacing: f64, rng: &mut ChaCha8Rng, noise: f64) -> Vec<SurfaceCell> {
        let n = (seg.length() / spacing) as usize;
        let normal = crate::wrap_pi(seg.orientation_rad() + std::f64::consts::FRAC_PI_2);
        let mut out = Vec::new();
        for i in 0..=n {
            let t = i as f64 / n as f64;
            let p = [
                seg.a[0] + t * (seg.b[0] - seg.a[0]),
                seg.a[1] + t * (seg.b[1] - seg.a[1]),
            ];
            for _ in 0..3 {
                out.push(SurfaceCell {
                    xy: [
                        p[0] + rng.gen_range(-noise..=noise),
                        p[1] + rng.gen_range(-noise..=noise),
                    ],
                    z: 1.0,
                    normal_yaw_rad: normal,
                });
            }
        }
        out
    }

    fn matches(found: &[Segment], planted: &Segment, tol: f64) -> bool {
        found.iter().any(|f| {
            let ends = |x: &Segment, y: &Segment| {
                geodata::osm::geometry::point_segment_distance(x.a, y.a, y.b).max(
                    geodata::osm::geometry::point_segment_distance(x.b, y.a, y.b),
                )
            };
            ends(f, planted) < tol
                && ends(planted, f) < tol
                && (f.length() - planted.length()).abs() < 2.0 * tol
        })
    }

    #[test]
    fn hough_finds_planted_lines() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for trial in 0..20 {
            let mut planted = Vec::new();
            let mut cells = Vec::new();
            for _ in 0..4 {
                let a = [rng.gen_range(-40.0..40.0), rng.gen_range(-40.0..40.0)];
                let ang: f64 = rng.gen_range(0.0..std::f64::consts::TAU);
                let len = rng.gen_range(6.0..25.0);
                let s = Segment::new(a, [a[0] + len * ang.cos(), a[1] + len * ang.sin()]);
                cells.extend(cells_on(&s, 0.1, &mut rng, 0.05));
                planted.push(s);
            }
            // Clutter: scattered cells with random normals.
            for _ in 0..300 {
                cells.push(SurfaceCell {
                    xy: [rng.gen_range(-50.0..50.0), rng.gen_range(-50.0..50.0)],
                    z: 1.0,
                    normal_yaw_rad: rng.gen_range(0.0..std::f64::consts::PI),
                });
            }
            let found = extract_segments(&cells, &SegmentOptions::default());
            for p in &planted {
                // Crossing planted lines may split one; accept a match of the whole line.
                assert!(
                    matches(&found, p, 0.6),
                    "trial {trial}: {p:?} not in {found:?}"
                );
            }
            assert!(found.len() <= planted.len() + 3, "trial {trial}: {found:?}");
        }
    }

    #[test]
    fn merge_joins_collinear_pieces_and_keeps_parallel_distant_ones() {
        let o = SegmentOptions::default();
        let segs = vec![
            Segment::new([0.0, 0.0], [10.0, 0.0]),
            Segment::new([11.0, 0.1], [20.0, 0.1]),
            Segment::new([0.0, 5.0], [20.0, 5.0]),
        ];
        let m = merge_segments(segs, &o);
        assert_eq!(m.len(), 2, "{m:?}");
        assert!((m[0].length() - 20.0).abs() < 0.1);
    }

    #[test]
    fn no_cells_no_segments() {
        assert!(extract_segments(&[], &SegmentOptions::default()).is_empty());
    }
}
