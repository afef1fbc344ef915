//! Small planar geometry helpers on `[x, y]` points: ring area, point in ring/polygon,
//! segment–segment and segment–box intersection, point–segment distance, the principal axis
//! of a point set (2-D PCA).

/// Mean and scatter `[sxx, sxy, syy]` (sums of products of the centred coordinates) of
/// planar points; the mean of no points is the origin.
pub fn mean_and_scatter(points: &[[f64; 2]]) -> ([f64; 2], [f64; 3]) {
    let n = points.len().max(1) as f64;
    let mx = points.iter().map(|p| p[0]).sum::<f64>() / n;
    let my = points.iter().map(|p| p[1]).sum::<f64>() / n;
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for p in points {
        let (dx, dy) = (p[0] - mx, p[1] - my);
        sxx += dx * dx;
        sxy += dx * dy;
        syy += dy * dy;
    }
    ([mx, my], [sxx, sxy, syy])
}

/// Direction of the major axis of a planar scatter or covariance `[sxx, sxy, syy]`, radians
/// in [−π/2, π/2] (its larger eigenvector, in closed form).
pub fn major_axis_angle(s: [f64; 3]) -> f64 {
    0.5 * (2.0 * s[1]).atan2(s[0] - s[2])
}

/// Signed area of a ring (last vertex not repeated): positive when counter-clockwise.
pub fn signed_area(ring: &[[f64; 2]]) -> f64 {
    let n = ring.len();
    let mut twice = 0.0;
    for i in 0..n {
        let p = ring[i];
        let q = ring[(i + 1) % n];
        twice += p[0] * q[1] - q[0] * p[1];
    }
    0.5 * twice
}

/// Whether `p` lies inside the ring (even–odd rule; points on the boundary may go either way).
pub fn point_in_ring(p: [f64; 2], ring: &[[f64; 2]]) -> bool {
    let n = ring.len();
    let mut inside = false;
    let mut j = n.wrapping_sub(1);
    for i in 0..n {
        let a = ring[i];
        let b = ring[j];
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1]);
            if p[0] < x {
                inside = !inside;
            }
        }
        j = i;
    }
    inside
}

/// Whether `p` is inside the outer ring and outside every hole.
pub fn point_in_polygon(p: [f64; 2], outer: &[[f64; 2]], inners: &[Vec<[f64; 2]>]) -> bool {
    point_in_ring(p, outer) && !inners.iter().any(|h| point_in_ring(p, h))
}

fn orient(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

fn on_segment(a: [f64; 2], b: [f64; 2], p: [f64; 2]) -> bool {
    p[0] >= a[0].min(b[0])
        && p[0] <= a[0].max(b[0])
        && p[1] >= a[1].min(b[1])
        && p[1] <= a[1].max(b[1])
}

/// Whether the closed segments `a–b` and `c–d` share a point.
pub fn segments_intersect(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let d1 = orient(c, d, a);
    let d2 = orient(c, d, b);
    let d3 = orient(a, b, c);
    let d4 = orient(a, b, d);
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    (d1 == 0.0 && on_segment(c, d, a))
        || (d2 == 0.0 && on_segment(c, d, b))
        || (d3 == 0.0 && on_segment(a, b, c))
        || (d4 == 0.0 && on_segment(a, b, d))
}

/// Whether the closed segment `a–b` meets the axis-aligned box `[min, max]`.
pub fn segment_intersects_box(a: [f64; 2], b: [f64; 2], min: [f64; 2], max: [f64; 2]) -> bool {
    // Liang–Barsky clipping of the parametric segment a + t (b − a), t ∈ [0, 1].
    let d = [b[0] - a[0], b[1] - a[1]];
    let mut t0 = 0.0_f64;
    let mut t1 = 1.0_f64;
    for axis in 0..2 {
        if d[axis] == 0.0 {
            if a[axis] < min[axis] || a[axis] > max[axis] {
                return false;
            }
        } else {
            let mut ta = (min[axis] - a[axis]) / d[axis];
            let mut tb = (max[axis] - a[axis]) / d[axis];
            if ta > tb {
                std::mem::swap(&mut ta, &mut tb);
            }
            t0 = t0.max(ta);
            t1 = t1.min(tb);
            if t0 > t1 {
                return false;
            }
        }
    }
    true
}

/// Euclidean distance from `p` to the closed segment `a–b`.
pub fn point_segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let d = [b[0] - a[0], b[1] - a[1]];
    let len2 = d[0] * d[0] + d[1] * d[1];
    let t = if len2 > 0.0 {
        (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p[0] - a[0] - t * d[0]).hypot(p[1] - a[1] - t * d[1])
}

/// Distance from `p` to a ring's area: 0 inside, else to the nearest edge.
pub fn point_ring_distance(p: [f64; 2], ring: &[[f64; 2]]) -> f64 {
    if point_in_ring(p, ring) {
        return 0.0;
    }
    (0..ring.len())
        .map(|k| point_segment_distance(p, ring[k], ring[(k + 1) % ring.len()]))
        .fold(f64::INFINITY, f64::min)
}

/// Axis-aligned bounds (min, max) of points ((+∞, −∞) for none).
pub fn ring_bounds(ring: &[[f64; 2]]) -> ([f64; 2], [f64; 2]) {
    ring.iter().fold(
        ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
        |(lo, hi), p| {
            (
                [lo[0].min(p[0]), lo[1].min(p[1])],
                [hi[0].max(p[0]), hi[1].max(p[1])],
            )
        },
    )
}

/// A rectangle in the plane: centre, half side lengths along its yaw axis and across it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RingBox {
    /// Centre, metres.
    pub centre: [f64; 2],
    /// Half extents along the yaw axis and across it, metres.
    pub half: [f64; 2],
    /// Yaw of the first axis, counter-clockwise from the x axis, radians.
    pub yaw_rad: f64,
}

/// The bounding rectangle of a ring aligned with its longest edge (how a building's box is
/// drawn from its outline); `None` for fewer than two distinct vertices.
pub fn longest_edge_box(ring: &[[f64; 2]]) -> Option<RingBox> {
    let n = ring.len();
    let (mut best, mut yaw) = (0.0, 0.0);
    for i in 0..n {
        let (p, q) = (ring[i], ring[(i + 1) % n]);
        let len = (q[0] - p[0]).hypot(q[1] - p[1]);
        if len > best {
            best = len;
            yaw = (q[1] - p[1]).atan2(q[0] - p[0]);
        }
    }
    if best <= 0.0 {
        return None;
    }
    Some(bounding_box_at(ring, yaw))
}

/// The bounding rectangle of points with its first axis at `yaw_rad`.
pub fn bounding_box_at(points: &[[f64; 2]], yaw_rad: f64) -> RingBox {
    let (s, c) = f64::sin_cos(yaw_rad);
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in points {
        let q = [c * p[0] + s * p[1], -s * p[0] + c * p[1]];
        for k in 0..2 {
            lo[k] = lo[k].min(q[k]);
            hi[k] = hi[k].max(q[k]);
        }
    }
    let m = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
    RingBox {
        centre: [c * m[0] - s * m[1], s * m[0] + c * m[1]],
        half: [0.5 * (hi[0] - lo[0]), 0.5 * (hi[1] - lo[1])],
        yaw_rad,
    }
}

/// Whether a polygon (outer ring with holes) and an axis-aligned box share a point.
pub fn polygon_intersects_box(
    outer: &[[f64; 2]],
    inners: &[Vec<[f64; 2]>],
    min: [f64; 2],
    max: [f64; 2],
) -> bool {
    let rings = std::iter::once(outer).chain(inners.iter().map(Vec::as_slice));
    for ring in rings {
        let n = ring.len();
        for i in 0..n {
            if segment_intersects_box(ring[i], ring[(i + 1) % n], min, max) {
                return true;
            }
        }
    }
    // No boundary crosses the box: either the box lies inside the polygon or they are apart.
    point_in_polygon(min, outer, inners)
}

/// Whether two simple rings overlap (boundaries cross or one contains the other).
pub fn rings_overlap(r1: &[[f64; 2]], r2: &[[f64; 2]]) -> bool {
    let (n1, n2) = (r1.len(), r2.len());
    for i in 0..n1 {
        for j in 0..n2 {
            if segments_intersect(r1[i], r1[(i + 1) % n1], r2[j], r2[(j + 1) % n2]) {
                return true;
            }
        }
    }
    r1.first().is_some_and(|&p| point_in_ring(p, r2))
        || r2.first().is_some_and(|&p| point_in_ring(p, r1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn principal_axis_of_a_rotated_cloud() {
        // An elongated cross of points rotated by 30°, centred at (5, -2).
        let (s, c) = 30f64.to_radians().sin_cos();
        let pts: Vec<[f64; 2]> = (-10..=10)
            .flat_map(|i| [[i as f64, 0.3], [i as f64, -0.3]])
            .map(|[x, y]| [5.0 + c * x - s * y, -2.0 + s * x + c * y])
            .collect();
        let (mean, scatter) = mean_and_scatter(&pts);
        assert!((mean[0] - 5.0).abs() < 1e-12 && (mean[1] + 2.0).abs() < 1e-12);
        assert!((major_axis_angle(scatter) - 30f64.to_radians()).abs() < 1e-12);
        // The same angle from the eigenvector of the 2 × 2 matrix, computed another way.
        let m = nalgebra::Matrix2::new(scatter[0], scatter[1], scatter[1], scatter[2]);
        let eig = m.symmetric_eigen();
        let k = if eig.eigenvalues[0] > eig.eigenvalues[1] {
            0
        } else {
            1
        };
        let v = eig.eigenvectors.column(k);
        let angle = v[1].atan2(v[0]);
        let diff = (angle - major_axis_angle(scatter)).rem_euclid(std::f64::consts::PI);
        assert!(diff < 1e-9 || std::f64::consts::PI - diff < 1e-9, "{angle}");
        assert_eq!(mean_and_scatter(&[]), ([0.0, 0.0], [0.0, 0.0, 0.0]));
    }

    #[test]
    fn longest_edge_box_of_a_rotated_l_shape() {
        // An L: 10 m long base along 30°, 4 m wide, with a 3 × 3 m arm on one end.
        let (s, c) = (30f64.to_radians()).sin_cos();
        let local = [
            [0.0, 0.0],
            [10.0, 0.0],
            [10.0, 4.0],
            [3.0, 4.0],
            [3.0, 7.0],
            [0.0, 7.0],
        ];
        let ring: Vec<[f64; 2]> = local
            .iter()
            .map(|p| [5.0 + c * p[0] - s * p[1], -2.0 + s * p[0] + c * p[1]])
            .collect();
        let b = longest_edge_box(&ring).expect("a box");
        assert!((b.yaw_rad - 30f64.to_radians()).abs() < 1e-12);
        assert!((b.half[0] - 5.0).abs() < 1e-9 && (b.half[1] - 3.5).abs() < 1e-9);
        let want = [5.0 + c * 5.0 - s * 3.5, -2.0 + s * 5.0 + c * 3.5];
        assert!((b.centre[0] - want[0]).abs() < 1e-9 && (b.centre[1] - want[1]).abs() < 1e-9);
        assert_eq!(longest_edge_box(&[[1.0, 1.0], [1.0, 1.0]]), None);
    }

    const SQUARE: [[f64; 2]; 4] = [[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]];

    #[test]
    fn square_area_and_containment() {
        assert_eq!(signed_area(&SQUARE), 4.0);
        let mut cw = SQUARE.to_vec();
        cw.reverse();
        assert_eq!(signed_area(&cw), -4.0);
        assert!(point_in_ring([1.0, 1.0], &SQUARE));
        assert!(!point_in_ring([3.0, 1.0], &SQUARE));
        let hole = vec![[0.5, 0.5], [0.5, 1.5], [1.5, 1.5], [1.5, 0.5]];
        assert!(!point_in_polygon(
            [1.0, 1.0],
            &SQUARE,
            std::slice::from_ref(&hole)
        ));
        assert!(point_in_polygon([0.2, 1.0], &SQUARE, &[hole]));
    }

    #[test]
    fn segment_tests_by_hand() {
        assert!(segments_intersect(
            [0.0, 0.0],
            [2.0, 2.0],
            [0.0, 2.0],
            [2.0, 0.0]
        ));
        assert!(!segments_intersect(
            [0.0, 0.0],
            [1.0, 0.0],
            [0.0, 1.0],
            [1.0, 1.0]
        ));
        assert!(segments_intersect(
            [0.0, 0.0],
            [1.0, 0.0],
            [1.0, 0.0],
            [1.0, 1.0]
        ));
        assert!(segment_intersects_box(
            [-1.0, 1.0],
            [3.0, 1.0],
            [0.0, 0.0],
            [2.0, 2.0]
        ));
        assert!(!segment_intersects_box(
            [-1.0, 3.0],
            [3.0, 3.0],
            [0.0, 0.0],
            [2.0, 2.0]
        ));
        assert!(!segment_intersects_box(
            [-1.0, 0.5],
            [0.4, -1.0],
            [0.0, 0.0],
            [2.0, 2.0]
        ));
        assert!((point_segment_distance([1.0, 1.0], [0.0, 0.0], [2.0, 0.0]) - 1.0).abs() < 1e-12);
        assert!((point_segment_distance([3.0, 0.0], [0.0, 0.0], [2.0, 0.0]) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn polygon_box_and_ring_overlap() {
        assert!(polygon_intersects_box(&SQUARE, &[], [0.5, 0.5], [0.6, 0.6]));
        assert!(polygon_intersects_box(
            &SQUARE,
            &[],
            [-1.0, -1.0],
            [5.0, 5.0]
        ));
        assert!(!polygon_intersects_box(
            &SQUARE,
            &[],
            [3.0, 3.0],
            [4.0, 4.0]
        ));
        let shifted: Vec<[f64; 2]> = SQUARE.iter().map(|p| [p[0] + 1.0, p[1] + 1.0]).collect();
        assert!(rings_overlap(&SQUARE, &shifted));
        let far: Vec<[f64; 2]> = SQUARE.iter().map(|p| [p[0] + 5.0, p[1]]).collect();
        assert!(!rings_overlap(&SQUARE, &far));
    }
}
