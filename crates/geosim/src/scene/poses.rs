//! Sensor poses in the world: seeded, on the ground, clear of walls and clutter.

use super::*;

impl Scene {
    /// `n` seeded sensor poses on sidewalks: on the ground, ≥ 1 m from walls and clutter,
    /// the sensor `height_m` above the sidewalk, heading uniform.
    pub fn sample_sidewalk_poses(&self, n: usize, seed: u64) -> Result<Vec<Pose>, SimError> {
        self.sample_poses_with_height(n, 1.8, seed)
    }

    /// Like [`Scene::sample_sidewalk_poses`] with a given sensor height above the ground.
    pub fn sample_poses_with_height(
        &self,
        n: usize,
        height_m: f64,
        seed: u64,
    ) -> Result<Vec<Pose>, SimError> {
        let candidates: Vec<usize> = (0..self.segments.len())
            .filter(|&s| {
                let t = &self.truth[s];
                t.drivable && t.on_ground && t.sidewalk_m >= 1.0 && self.segments[s].length_m >= 5.0
            })
            .collect();
        let total: f64 = candidates.iter().map(|&s| self.segments[s].length_m).sum();
        let tries = n * 200 + 100;
        if candidates.is_empty() || total <= 0.0 {
            return Err(SimError::NoPoses {
                wanted: n,
                found: 0,
                tries: 0,
            });
        }
        let mut poses = Vec::with_capacity(n);
        let mut rng = stream_rng(seed, purpose::POSES, 0);
        for _ in 0..tries {
            if poses.len() == n {
                break;
            }
            let mut pick = rng.gen_range(0.0..total);
            let mut chosen = candidates[candidates.len() - 1];
            for &s in &candidates {
                pick -= self.segments[s].length_m;
                if pick < 0.0 {
                    chosen = s;
                    break;
                }
            }
            let seg = &self.segments[chosen];
            let t = &self.truth[chosen];
            let along = rng.gen_range(0.1..0.9) * seg.length_m;
            let side = if rng.gen::<bool>() { 1.0 } else { -1.0 };
            let lateral = 0.5 * t.width_m + rng.gen_range(0.3..(t.sidewalk_m - 0.3).max(0.31));
            let yaw = rng.gen_range(-std::f64::consts::PI..std::f64::consts::PI);
            let e = [
                (seg.b[0] - seg.a[0]) / seg.length_m,
                (seg.b[1] - seg.a[1]) / seg.length_m,
            ];
            let u = t.offset_m + side * lateral;
            let p = [
                seg.a[0] + along * e[0] - u * e[1],
                seg.a[1] + along * e[1] + u * e[0],
            ];
            let cell = self.ground_at(p);
            if cell.class != Class::Sidewalk
                || self.inside_building(p)
                || !self.clear_of_shapes(p, 1.0)
            {
                continue;
            }
            poses.push(Pose {
                position: [p[0], p[1], cell.z + height_m],
                yaw_rad: yaw,
            });
        }
        if poses.len() < n {
            return Err(SimError::NoPoses {
                wanted: n,
                found: poses.len(),
                tries,
            });
        }
        Ok(poses)
    }

    /// Whether no wall or clutter footprint comes within `r` metres of `p`.
    pub fn clear_of_shapes(&self, p: [f64; 2], r: f64) -> bool {
        let shapes = self.caster.shapes();
        let mut probes = vec![p];
        for k in 0..8 {
            let a = k as f64 * std::f64::consts::FRAC_PI_4;
            probes.push([p[0] + r * a.cos(), p[1] + r * a.sin()]);
        }
        probes.iter().all(|&q| {
            self.caster
                .shapes_near(q)
                .iter()
                .all(|&i| match shapes[i as usize] {
                    Shape::Wall { a, b, .. } => point_segment_distance(p, a, b) > r,
                    other => {
                        let (lo, hi) = other.footprint();
                        p[0] < lo[0] - r || p[0] > hi[0] + r || p[1] < lo[1] - r || p[1] > hi[1] + r
                    }
                })
        })
    }
}
