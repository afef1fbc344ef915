//! Ray casting against the scene's solid shapes through a uniform 2-D grid.
//!
//! Urban scenes are 2.5-D (walls, boxes and columns standing on the ground), so a grid over
//! the ground plane whose cells list the shapes whose footprint touches them is as good a
//! partition as a BVH and simpler to traverse: a ray visits the cells its ground projection
//! crosses in order (Amanatides & Woo 1987, "A fast voxel traversal algorithm"), and stops
//! as soon as the nearest hit so far lies before the current cell's exit. Cost per ray:
//! O(cells crossed + shapes in them). The ground itself is analytic and handled by
//! [`super::scene::Scene::cast`].

use geodata::osm::geometry::segment_intersects_box;

/// Smallest ray parameter accepted as a hit (metres), to leave the surface a ray starts on.
const T_MIN: f64 = 1e-9;

/// A solid shape of the scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    /// A vertical wall: the quad above the segment `a`–`b` between two heights.
    Wall {
        /// Start of the wall's ground line, metres.
        a: [f64; 2],
        /// End of the wall's ground line, metres.
        b: [f64; 2],
        /// Bottom height, metres.
        z_min: f64,
        /// Top height, metres.
        z_max: f64,
    },
    /// A box rotated about the vertical axis.
    OrientedBox {
        /// Centre, metres.
        centre: [f64; 3],
        /// Half extents along the box's own x (yaw direction), y and z, metres.
        half: [f64; 3],
        /// Rotation of the box's x axis from east, counter-clockwise, radians.
        yaw_rad: f64,
    },
    /// A vertical cylinder with a top cap.
    Cylinder {
        /// Axis position, metres.
        centre: [f64; 2],
        /// Radius, metres.
        radius: f64,
        /// Bottom height, metres.
        z_min: f64,
        /// Top height, metres.
        z_max: f64,
    },
    /// An ellipsoid of revolution about the vertical axis (a tree crown).
    Spheroid {
        /// Centre, metres.
        centre: [f64; 3],
        /// Horizontal radius, metres.
        radius_xy: f64,
        /// Vertical radius, metres.
        radius_z: f64,
    },
}

/// Where a ray met a shape.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShapeHit {
    /// Distance along the (unit) ray direction, metres.
    pub t: f64,
    /// Unit surface normal facing the ray.
    pub normal: [f64; 3],
}

fn cross2(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

fn facing(mut n: [f64; 3], d: [f64; 3]) -> [f64; 3] {
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if len > 0.0 {
        n = [n[0] / len, n[1] / len, n[2] / len];
    }
    if n[0] * d[0] + n[1] * d[1] + n[2] * d[2] > 0.0 {
        [-n[0], -n[1], -n[2]]
    } else {
        n
    }
}

impl Shape {
    /// Axis-aligned ground footprint `(min, max)` of the shape, metres.
    pub fn footprint(&self) -> ([f64; 2], [f64; 2]) {
        match *self {
            Shape::Wall { a, b, .. } => (
                [a[0].min(b[0]), a[1].min(b[1])],
                [a[0].max(b[0]), a[1].max(b[1])],
            ),
            Shape::OrientedBox {
                centre,
                half,
                yaw_rad,
            } => {
                let (s, c) = yaw_rad.sin_cos();
                let ex = half[0] * c.abs() + half[1] * s.abs();
                let ey = half[0] * s.abs() + half[1] * c.abs();
                (
                    [centre[0] - ex, centre[1] - ey],
                    [centre[0] + ex, centre[1] + ey],
                )
            }
            Shape::Cylinder { centre, radius, .. } => (
                [centre[0] - radius, centre[1] - radius],
                [centre[0] + radius, centre[1] + radius],
            ),
            Shape::Spheroid {
                centre, radius_xy, ..
            } => (
                [centre[0] - radius_xy, centre[1] - radius_xy],
                [centre[0] + radius_xy, centre[1] + radius_xy],
            ),
        }
    }

    /// The first hit of the ray `o + t·d` (d unit) with `T_MIN < t < t_max`, if any.
    pub fn intersect(&self, o: [f64; 3], d: [f64; 3], t_max: f64) -> Option<ShapeHit> {
        match *self {
            Shape::Wall { a, b, z_min, z_max } => {
                let e = [b[0] - a[0], b[1] - a[1]];
                let dxy = [d[0], d[1]];
                let denom = cross2(dxy, e);
                if denom.abs() < 1e-15 {
                    return None;
                }
                let w = [a[0] - o[0], a[1] - o[1]];
                let t = cross2(w, e) / denom;
                let s = cross2(w, dxy) / denom;
                if !(T_MIN..t_max).contains(&t) || !(0.0..=1.0).contains(&s) {
                    return None;
                }
                let z = o[2] + t * d[2];
                if z < z_min || z > z_max {
                    return None;
                }
                Some(ShapeHit {
                    t,
                    normal: facing([e[1], -e[0], 0.0], d),
                })
            }
            Shape::OrientedBox {
                centre,
                half,
                yaw_rad,
            } => {
                let (s, c) = yaw_rad.sin_cos();
                let q = [o[0] - centre[0], o[1] - centre[1], o[2] - centre[2]];
                let lo = [c * q[0] + s * q[1], -s * q[0] + c * q[1], q[2]];
                let ld = [c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]];
                let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
                let mut axis = 0;
                for k in 0..3 {
                    if ld[k].abs() < 1e-15 {
                        if lo[k].abs() > half[k] {
                            return None;
                        }
                        continue;
                    }
                    let inv = 1.0 / ld[k];
                    let (mut ta, mut tb) = ((-half[k] - lo[k]) * inv, (half[k] - lo[k]) * inv);
                    if ta > tb {
                        std::mem::swap(&mut ta, &mut tb);
                    }
                    if ta > t0 {
                        t0 = ta;
                        axis = k;
                    }
                    t1 = t1.min(tb);
                }
                if t0 > t1 || !(T_MIN..t_max).contains(&t0) {
                    return None;
                }
                let normal = match axis {
                    0 => [c, s, 0.0],
                    1 => [-s, c, 0.0],
                    _ => [0.0, 0.0, 1.0],
                };
                Some(ShapeHit {
                    t: t0,
                    normal: facing(normal, d),
                })
            }
            Shape::Cylinder {
                centre,
                radius,
                z_min,
                z_max,
            } => {
                let mut best: Option<ShapeHit> = None;
                let f = [o[0] - centre[0], o[1] - centre[1]];
                let a = d[0] * d[0] + d[1] * d[1];
                if a > 1e-18 {
                    let b = 2.0 * (f[0] * d[0] + f[1] * d[1]);
                    let cc = f[0] * f[0] + f[1] * f[1] - radius * radius;
                    let disc = b * b - 4.0 * a * cc;
                    if disc >= 0.0 {
                        let t = (-b - disc.sqrt()) / (2.0 * a);
                        if (T_MIN..t_max).contains(&t) {
                            let z = o[2] + t * d[2];
                            if (z_min..=z_max).contains(&z) {
                                let p = [f[0] + t * d[0], f[1] + t * d[1]];
                                best = Some(ShapeHit {
                                    t,
                                    normal: facing([p[0], p[1], 0.0], d),
                                });
                            }
                        }
                    }
                }
                if d[2] < 0.0 && o[2] > z_max {
                    let t = (z_max - o[2]) / d[2];
                    let p = [f[0] + t * d[0], f[1] + t * d[1]];
                    if (T_MIN..t_max).contains(&t)
                        && p[0] * p[0] + p[1] * p[1] <= radius * radius
                        && best.is_none_or(|h| t < h.t)
                    {
                        best = Some(ShapeHit {
                            t,
                            normal: [0.0, 0.0, 1.0],
                        });
                    }
                }
                best
            }
            Shape::Spheroid {
                centre,
                radius_xy,
                radius_z,
            } => {
                let s = radius_xy / radius_z;
                let q = [o[0] - centre[0], o[1] - centre[1], (o[2] - centre[2]) * s];
                let dd = [d[0], d[1], d[2] * s];
                let a = dd[0] * dd[0] + dd[1] * dd[1] + dd[2] * dd[2];
                let b = 2.0 * (q[0] * dd[0] + q[1] * dd[1] + q[2] * dd[2]);
                let c = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] - radius_xy * radius_xy;
                let disc = b * b - 4.0 * a * c;
                if disc < 0.0 {
                    return None;
                }
                let t = (-b - disc.sqrt()) / (2.0 * a);
                if !(T_MIN..t_max).contains(&t) {
                    return None;
                }
                let p = [q[0] + t * dd[0], q[1] + t * dd[1], q[2] + t * dd[2]];
                Some(ShapeHit {
                    t,
                    normal: facing([p[0], p[1], p[2] * s], d),
                })
            }
        }
    }
}

/// The nearest shape a ray hits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CastHit {
    /// Index of the shape in the caster's list.
    pub shape: usize,
    /// Distance along the ray, metres.
    pub t: f64,
    /// Unit normal facing the ray.
    pub normal: [f64; 3],
}

/// A set of shapes with a uniform 2-D grid over their footprints.
#[derive(Debug, Clone)]
pub struct Caster {
    shapes: Vec<Shape>,
    min: [f64; 2],
    cell_m: f64,
    nx: usize,
    ny: usize,
    /// CSR: shapes of cell `c` are `items[cell_start[c]..cell_start[c + 1]]`.
    cell_start: Vec<u32>,
    items: Vec<u32>,
}

impl Caster {
    /// Builds the grid (cell side `cell_m` metres) over the shapes' footprints plus `margin_m`.
    ///
    /// O(Σ cells touched per shape); a wall is registered only in the cells its line crosses.
    pub fn new(shapes: Vec<Shape>, cell_m: f64, bounds: ([f64; 2], [f64; 2])) -> Caster {
        let cell_m = if cell_m.is_finite() && cell_m > 0.0 {
            cell_m
        } else {
            4.0
        };
        let (mut min, mut max) = bounds;
        for s in &shapes {
            let (lo, hi) = s.footprint();
            for k in 0..2 {
                min[k] = min[k].min(lo[k]);
                max[k] = max[k].max(hi[k]);
            }
        }
        if !(min[0].is_finite() && max[0].is_finite() && min[1].is_finite() && max[1].is_finite()) {
            min = [0.0, 0.0];
            max = [cell_m, cell_m];
        }
        let nx = (((max[0] - min[0]) / cell_m).ceil() as usize).max(1);
        let ny = (((max[1] - min[1]) / cell_m).ceil() as usize).max(1);
        let cells_of = |s: &Shape, f: &mut dyn FnMut(usize)| {
            let (lo, hi) = s.footprint();
            let ix0 = (((lo[0] - min[0]) / cell_m).floor().max(0.0) as usize).min(nx - 1);
            let iy0 = (((lo[1] - min[1]) / cell_m).floor().max(0.0) as usize).min(ny - 1);
            let ix1 = (((hi[0] - min[0]) / cell_m).floor().max(0.0) as usize).min(nx - 1);
            let iy1 = (((hi[1] - min[1]) / cell_m).floor().max(0.0) as usize).min(ny - 1);
            for iy in iy0..=iy1 {
                for ix in ix0..=ix1 {
                    if let Shape::Wall { a, b, .. } = s {
                        let eps = 1e-9;
                        let cmin = [
                            min[0] + ix as f64 * cell_m - eps,
                            min[1] + iy as f64 * cell_m - eps,
                        ];
                        let cmax = [cmin[0] + cell_m + 2.0 * eps, cmin[1] + cell_m + 2.0 * eps];
                        if !segment_intersects_box(*a, *b, cmin, cmax) {
                            continue;
                        }
                    }
                    f(iy * nx + ix);
                }
            }
        };
        let mut counts = vec![0u32; nx * ny + 1];
        for s in &shapes {
            cells_of(s, &mut |c| counts[c + 1] += 1);
        }
        for c in 0..nx * ny {
            counts[c + 1] += counts[c];
        }
        let mut fill = counts.clone();
        let mut items = vec![0u32; counts[nx * ny] as usize];
        for (i, s) in shapes.iter().enumerate() {
            cells_of(s, &mut |c| {
                items[fill[c] as usize] = i as u32;
                fill[c] += 1;
            });
        }
        Caster {
            shapes,
            min,
            cell_m,
            nx,
            ny,
            cell_start: counts,
            items,
        }
    }

    /// The shapes, in the order given to [`Caster::new`].
    pub fn shapes(&self) -> &[Shape] {
        &self.shapes
    }

    /// Indices of the shapes registered in the grid cell containing `p` (empty outside the grid).
    pub fn shapes_near(&self, p: [f64; 2]) -> &[u32] {
        let fx = (p[0] - self.min[0]) / self.cell_m;
        let fy = (p[1] - self.min[1]) / self.cell_m;
        if !(fx >= 0.0 && fy >= 0.0) {
            return &[];
        }
        let (ix, iy) = (fx as usize, fy as usize);
        if ix >= self.nx || iy >= self.ny {
            return &[];
        }
        let c = iy * self.nx + ix;
        &self.items[self.cell_start[c] as usize..self.cell_start[c + 1] as usize]
    }

    /// The nearest shape hit by `o + t·d` (d unit) with t < `t_max`, by grid traversal.
    pub fn cast(&self, o: [f64; 3], d: [f64; 3], t_max: f64) -> Option<CastHit> {
        let max = [
            self.min[0] + self.nx as f64 * self.cell_m,
            self.min[1] + self.ny as f64 * self.cell_m,
        ];
        // Clip the ray's ground projection to the grid.
        let (mut t0, mut t1) = (0.0_f64, t_max);
        for k in 0..2 {
            if d[k].abs() < 1e-15 {
                if o[k] < self.min[k] || o[k] > max[k] {
                    return None;
                }
                continue;
            }
            let inv = 1.0 / d[k];
            let (mut ta, mut tb) = ((self.min[k] - o[k]) * inv, (max[k] - o[k]) * inv);
            if ta > tb {
                std::mem::swap(&mut ta, &mut tb);
            }
            t0 = t0.max(ta);
            t1 = t1.min(tb);
        }
        if t0 > t1 {
            return None;
        }
        let start = [o[0] + t0 * d[0], o[1] + t0 * d[1]];
        let cell = |v: f64, k: usize, n: usize| -> usize {
            (((v - self.min[k]) / self.cell_m).floor().max(0.0) as usize).min(n - 1)
        };
        let mut ix = cell(start[0], 0, self.nx);
        let mut iy = cell(start[1], 1, self.ny);
        let next_boundary = |i: usize, k: usize| -> (f64, f64) {
            if d[k] > 1e-15 {
                let b = self.min[k] + (i + 1) as f64 * self.cell_m;
                ((b - o[k]) / d[k], self.cell_m / d[k])
            } else if d[k] < -1e-15 {
                let b = self.min[k] + i as f64 * self.cell_m;
                ((b - o[k]) / d[k], -self.cell_m / d[k])
            } else {
                (f64::INFINITY, f64::INFINITY)
            }
        };
        let (mut tx, dtx) = next_boundary(ix, 0);
        let (mut ty, dty) = next_boundary(iy, 1);
        let mut best: Option<CastHit> = None;
        let mut best_t = t_max;
        loop {
            let c = iy * self.nx + ix;
            for &i in &self.items[self.cell_start[c] as usize..self.cell_start[c + 1] as usize] {
                let shape = &self.shapes[i as usize];
                if let Some(h) = shape.intersect(o, d, best_t) {
                    best_t = h.t;
                    best = Some(CastHit {
                        shape: i as usize,
                        t: h.t,
                        normal: h.normal,
                    });
                }
            }
            let t_exit = tx.min(ty);
            if best_t <= t_exit || t_exit > t1 {
                break;
            }
            if tx < ty {
                if d[0] > 0.0 {
                    ix += 1;
                    if ix >= self.nx {
                        break;
                    }
                } else {
                    if ix == 0 {
                        break;
                    }
                    ix -= 1;
                }
                tx += dtx;
            } else {
                if d[1] > 0.0 {
                    iy += 1;
                    if iy >= self.ny {
                        break;
                    }
                } else {
                    if iy == 0 {
                        break;
                    }
                    iy -= 1;
                }
                ty += dty;
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn unit(d: [f64; 3]) -> [f64; 3] {
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        [d[0] / l, d[1] / l, d[2] / l]
    }

    #[test]
    fn wall_box_cylinder_spheroid_by_hand() {
        let o = [0.0, 0.0, 1.0];
        let d = [1.0, 0.0, 0.0];
        let wall = Shape::Wall {
            a: [5.0, -1.0],
            b: [5.0, 1.0],
            z_min: 0.0,
            z_max: 10.0,
        };
        let h = wall.intersect(o, d, 100.0).unwrap();
        assert!((h.t - 5.0).abs() < 1e-12);
        assert_eq!(h.normal, [-1.0, 0.0, 0.0]);
        assert!(wall.intersect([0.0, 0.0, 11.0], d, 100.0).is_none());
        assert!(wall.intersect(o, d, 4.0).is_none());

        let boxed = Shape::OrientedBox {
            centre: [5.0, 0.0, 1.0],
            half: [1.0, 0.5, 0.5],
            yaw_rad: std::f64::consts::FRAC_PI_2,
        };
        // Rotated by 90°: the box's half extent along east is 0.5.
        let h = boxed.intersect(o, d, 100.0).unwrap();
        assert!((h.t - 4.5).abs() < 1e-12, "{h:?}");

        let cyl = Shape::Cylinder {
            centre: [3.0, 0.0],
            radius: 0.5,
            z_min: 0.0,
            z_max: 2.0,
        };
        assert!((cyl.intersect(o, d, 100.0).unwrap().t - 2.5).abs() < 1e-12);
        // Straight down onto the cap.
        let h = cyl
            .intersect([3.0, 0.1, 5.0], [0.0, 0.0, -1.0], 100.0)
            .unwrap();
        assert!((h.t - 3.0).abs() < 1e-12);

        let crown = Shape::Spheroid {
            centre: [10.0, 0.0, 1.0],
            radius_xy: 2.0,
            radius_z: 1.0,
        };
        assert!((crown.intersect(o, d, 100.0).unwrap().t - 8.0).abs() < 1e-12);
        let up = crown
            .intersect([10.0, 0.0, -5.0], [0.0, 0.0, 1.0], 100.0)
            .unwrap();
        assert!((up.t - 5.0).abs() < 1e-12);
    }

    fn random_shapes(seed: u64, n: usize) -> Vec<Shape> {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|i| {
                let c = [rng.gen_range(-40.0..40.0), rng.gen_range(-40.0..40.0)];
                match i % 4 {
                    0 => Shape::Wall {
                        a: c,
                        b: [
                            c[0] + rng.gen_range(-20.0..20.0),
                            c[1] + rng.gen_range(-20.0..20.0),
                        ],
                        z_min: 0.0,
                        z_max: rng.gen_range(1.0..20.0),
                    },
                    1 => Shape::OrientedBox {
                        centre: [c[0], c[1], rng.gen_range(0.5..2.0)],
                        half: [
                            rng.gen_range(0.2..3.0),
                            rng.gen_range(0.2..2.0),
                            rng.gen_range(0.2..1.5),
                        ],
                        yaw_rad: rng.gen_range(-3.0..3.0),
                    },
                    2 => Shape::Cylinder {
                        centre: c,
                        radius: rng.gen_range(0.05..1.0),
                        z_min: 0.0,
                        z_max: rng.gen_range(1.0..8.0),
                    },
                    _ => Shape::Spheroid {
                        centre: [c[0], c[1], rng.gen_range(3.0..7.0)],
                        radius_xy: rng.gen_range(0.5..3.0),
                        radius_z: rng.gen_range(0.5..3.0),
                    },
                }
            })
            .collect()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// Grid traversal returns the same nearest hit as testing every shape.
        #[test]
        fn grid_cast_equals_brute_force(
            seed in 0u64..1000,
            ox in -50.0f64..50.0, oy in -50.0f64..50.0, oz in 0.5f64..3.0,
            az in -3.2f64..3.2, el in -1.2f64..1.2, cell in 1.0f64..9.0,
        ) {
            let shapes = random_shapes(seed, 60);
            let caster = Caster::new(shapes.clone(), cell, ([-60.0, -60.0], [60.0, 60.0]));
            let d = unit([el.cos() * az.cos(), el.cos() * az.sin(), el.sin()]);
            let o = [ox, oy, oz];
            let got = caster.cast(o, d, 150.0);
            let mut want: Option<(usize, f64)> = None;
            for (i, s) in shapes.iter().enumerate() {
                if let Some(h) = s.intersect(o, d, want.map_or(150.0, |w| w.1)) {
                    want = Some((i, h.t));
                }
            }
            match (got, want) {
                (None, None) => {}
                (Some(g), Some(w)) => prop_assert!((g.t - w.1).abs() < 1e-9, "{g:?} vs {w:?}"),
                (g, w) => prop_assert!(false, "grid {g:?} vs brute force {w:?}"),
            }
        }
    }
}
