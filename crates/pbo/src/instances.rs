//! Seeded benchmark instances: quadratic pseudo-Boolean functions with integer energies.
//!
//! Three families, as in issue 2's benchmark against Kolmogorov's QPBO and BK max-flow:
//! - [`denoising_grid`]: binary denoising of a noisy two-level image on a 4-connected grid
//!   (submodular Potts terms);
//! - [`random_sparse`]: a random sparse non-submodular function (80 % attractive, 20 %
//!   repulsive pairs on distinct random variable pairs);
//! - [`segmentation_3d`]: a 6-connected voxel grid with contrast-sensitive Potts weights
//!   (submodular).
//!
//! [`QuadraticInstance::write_raw`] stores an instance in a little-endian binary layout
//! that numpy reads directly (see its doc).
//!
//! ```
//! use pbo::instances::denoising_grid;
//! let inst = denoising_grid(8, 8, 1);
//! assert_eq!(inst.num_vars, 64);
//! assert_eq!(inst.pairs.len(), 2 * 8 * 7);
//! let mut q = inst.to_qpbo::<i64>();
//! q.solve();
//! ```

use crate::maxflow::{Capacity, Graph};
use crate::polynomial::{Literal, Polynomial};
use crate::qpbo::Qpbo;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rustc_hash::FxHashSet;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Errors writing an instance file.
#[derive(Debug, thiserror::Error)]
pub enum InstanceError {
    /// The file could not be created or written.
    #[error("cannot write instance file {path}: {source} (check that the directory is writable)")]
    Write {
        /// The file being written.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
}

/// One pairwise term: variables `i`, `j` and energies `[E00, E01, E10, E11]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PairTerm {
    /// First variable.
    pub i: u32,
    /// Second variable.
    pub j: u32,
    /// `[E00, E01, E10, E11]`.
    pub e: [i32; 4],
}

/// A quadratic pseudo-Boolean function with integer energies and no constant.
#[derive(Debug, Clone)]
pub struct QuadraticInstance {
    /// Short name (used for file names).
    pub name: String,
    /// Number of variables.
    pub num_vars: usize,
    /// `[E(0), E(1)]` per variable.
    pub unary: Vec<[i32; 2]>,
    /// Pairwise terms on distinct pairs.
    pub pairs: Vec<PairTerm>,
}

/// Magic bytes of the raw instance format.
pub const RAW_MAGIC: &[u8; 8] = b"PBOQUAD1";

impl QuadraticInstance {
    /// Builds the QPBO problem.
    pub fn to_qpbo<T: Capacity>(&self) -> Qpbo<T> {
        let mut q = Qpbo::new(self.num_vars, self.pairs.len());
        for (i, u) in self.unary.iter().enumerate() {
            q.add_unary(i, T::from_i32(u[0]), T::from_i32(u[1]));
        }
        for p in &self.pairs {
            let c = |k: usize| T::from_i32(p.e[k]);
            q.add_pairwise(p.i as usize, p.j as usize, c(0), c(1), c(2), c(3));
        }
        q
    }

    /// Whether every pairwise term has the Potts-like form `E00 = E11 = 0`, `E01, E10 ≥ 0`
    /// (then the function is exactly a cut, see [`QuadraticInstance::to_graph`]).
    pub fn is_cut_form(&self) -> bool {
        self.pairs
            .iter()
            .all(|p| p.e[0] == 0 && p.e[3] == 0 && p.e[1] >= 0 && p.e[2] >= 0)
    }

    /// The s-t graph whose cuts are the energies (node on the sink side ⇔ x = 1); `None`
    /// unless [`QuadraticInstance::is_cut_form`].
    pub fn to_graph<T: Capacity>(&self) -> Option<Graph<T>> {
        if !self.is_cut_form() {
            return None;
        }
        let mut g = Graph::new(self.num_vars, self.pairs.len());
        for (i, u) in self.unary.iter().enumerate() {
            g.add_tweights(i, T::from_i32(u[1]), T::from_i32(u[0]));
        }
        for p in &self.pairs {
            g.add_edge(
                p.i as usize,
                p.j as usize,
                T::from_i32(p.e[1]),
                T::from_i32(p.e[2]),
            );
        }
        Some(g)
    }

    /// The same function as a [`Polynomial`] in literal form, as a user writes it in an
    /// `.opb` file: `E0 x̄ᵢ + E1 xᵢ` per variable and one term `E_ab` per non-zero entry of
    /// each pair's table (a Potts pair becomes `λ xᵢ x̄ⱼ + λ x̄ᵢ xⱼ`).
    pub fn to_polynomial(&self) -> Polynomial {
        let lit = |v: u32, value: bool| Literal::new(v, value);
        let mut f = Polynomial::new(self.num_vars);
        f.reserve_terms(2 * self.num_vars + 2 * self.pairs.len());
        for (i, u) in self.unary.iter().enumerate() {
            let i = i as u32;
            f.add_term(f64::from(u[0]), &[lit(i, false)]);
            f.add_term(f64::from(u[1]), &[lit(i, true)]);
        }
        for p in &self.pairs {
            for (k, &e) in p.e.iter().enumerate() {
                f.add_term(f64::from(e), &[lit(p.i, k >= 2), lit(p.j, k % 2 == 1)]);
            }
        }
        f
    }

    /// The function as an `.opb` objective over `x1 … xN` (literal form, see
    /// [`QuadraticInstance::to_polynomial`]).
    pub fn to_opb(&self) -> crate::opb::OpbProblem {
        crate::opb::OpbProblem {
            poly: self.to_polynomial(),
            names: (1..=self.num_vars).map(|k| format!("x{k}")).collect(),
            sense: crate::opb::Sense::Minimize,
            declared: Some(self.num_vars),
        }
    }

    /// Energy of `x`, in `i64`.
    pub fn energy(&self, x: &[bool]) -> i64 {
        let mut e = 0i64;
        for (u, &xi) in self.unary.iter().zip(x) {
            e += i64::from(u[usize::from(xi)]);
        }
        for p in &self.pairs {
            let k = (usize::from(x[p.i as usize]) << 1) | usize::from(x[p.j as usize]);
            e += i64::from(p.e[k]);
        }
        e
    }

    /// Writes `dir/<name>.bin`: the 8 bytes [`RAW_MAGIC`], `u64` number of variables n,
    /// `u64` number of pairs m, then n × (`i32` E0, `i32` E1), then m × (`i32` i, `i32` j,
    /// `i32` E00, E01, E10, E11), all little-endian. Returns the path.
    pub fn write_raw(&self, dir: &Path) -> Result<PathBuf, InstanceError> {
        let path = dir.join(format!("{}.bin", self.name));
        let err = |source| InstanceError::Write {
            path: path.clone(),
            source,
        };
        std::fs::create_dir_all(dir).map_err(err)?;
        let mut bytes: Vec<u8> =
            Vec::with_capacity(24 + 8 * self.unary.len() + 24 * self.pairs.len());
        bytes.extend_from_slice(RAW_MAGIC);
        bytes.extend_from_slice(&(self.num_vars as u64).to_le_bytes());
        bytes.extend_from_slice(&(self.pairs.len() as u64).to_le_bytes());
        for u in &self.unary {
            bytes.extend_from_slice(&u[0].to_le_bytes());
            bytes.extend_from_slice(&u[1].to_le_bytes());
        }
        for p in &self.pairs {
            bytes.extend_from_slice(&(p.i as i32).to_le_bytes());
            bytes.extend_from_slice(&(p.j as i32).to_le_bytes());
            for v in p.e {
                bytes.extend_from_slice(&v.to_le_bytes());
            }
        }
        // Written beside the target and renamed into place: never a half-written file.
        let mut f = tempfile::NamedTempFile::new_in(dir).map_err(err)?;
        f.write_all(&bytes).map_err(err)?;
        f.persist(&path).map_err(|e| err(e.error))?;
        Ok(path)
    }
}

/// Data costs of a two-level image model: levels 64 and 192, E(x) = |I − level(x)|.
#[inline]
fn data_cost(intensity: i32) -> [i32; 2] {
    [(intensity - 64).abs(), (intensity - 192).abs()]
}

/// Binary denoising of a `width × height` image on a 4-connected grid: random discs and
/// boxes (level 192) on a background (64), uniform noise ±110, Potts weight 26.
pub fn denoising_grid(width: usize, height: usize, seed: u64) -> QuadraticInstance {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut clean = vec![false; width * height];
    let num_shapes = 4 + (width * height) / 8192;
    for _ in 0..num_shapes {
        let cx = rng.gen_range(0..width.max(1)) as i64;
        let cy = rng.gen_range(0..height.max(1)) as i64;
        let r = rng.gen_range(2..(width.min(height) / 6).max(3)) as i64;
        let disc = rng.gen_bool(0.5);
        for y in (cy - r).max(0)..(cy + r).min(height as i64) {
            for x in (cx - r).max(0)..(cx + r).min(width as i64) {
                let inside = !disc || (x - cx).pow(2) + (y - cy).pow(2) <= r * r;
                if inside {
                    clean[y as usize * width + x as usize] ^= true;
                }
            }
        }
    }
    let unary = clean
        .iter()
        .map(|&c| {
            let level = if c { 192 } else { 64 };
            data_cost((level + rng.gen_range(-110..=110)).clamp(0, 255))
        })
        .collect();
    let lambda = 26;
    let mut pairs = Vec::with_capacity(2 * width * height);
    for y in 0..height {
        for x in 0..width {
            let i = (y * width + x) as u32;
            if x + 1 < width {
                pairs.push(PairTerm {
                    i,
                    j: i + 1,
                    e: [0, lambda, lambda, 0],
                });
            }
            if y + 1 < height {
                pairs.push(PairTerm {
                    i,
                    j: i + width as u32,
                    e: [0, lambda, lambda, 0],
                });
            }
        }
    }
    QuadraticInstance {
        name: format!("denoise_{width}x{height}"),
        num_vars: width * height,
        unary,
        pairs,
    }
}

/// A random sparse non-submodular function on `num_vars` variables with
/// `num_vars · avg_degree / 2` distinct random pairs: unary E(1) − E(0) uniform in
/// [−40, 40]; 80 % attractive pairs `[0, w, w, 0]`, 20 % repulsive `[w, 0, 0, w]`,
/// w uniform in [1, 30].
pub fn random_sparse(num_vars: usize, avg_degree: usize, seed: u64) -> QuadraticInstance {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let unary = (0..num_vars)
        .map(|_| {
            let d = rng.gen_range(-40..=40);
            if d >= 0 {
                [0, d]
            } else {
                [-d, 0]
            }
        })
        .collect();
    let m = num_vars * avg_degree / 2;
    let mut seen: FxHashSet<(u32, u32)> = FxHashSet::default();
    seen.reserve(m);
    let mut pairs = Vec::with_capacity(m);
    if num_vars >= 2 {
        let max_pairs = num_vars * (num_vars - 1) / 2;
        while pairs.len() < m.min(max_pairs) {
            let i = rng.gen_range(0..num_vars) as u32;
            let j = rng.gen_range(0..num_vars) as u32;
            if i == j || !seen.insert((i.min(j), i.max(j))) {
                continue;
            }
            let w = rng.gen_range(1..=30);
            let e = if rng.gen_bool(0.8) {
                [0, w, w, 0]
            } else {
                [w, 0, 0, w]
            };
            pairs.push(PairTerm { i, j, e });
        }
    }
    QuadraticInstance {
        name: format!("random_{num_vars}_deg{avg_degree}"),
        num_vars,
        unary,
        pairs,
    }
}

/// A `side³` voxel segmentation on a 6-connected grid: random balls (level 192) in a
/// background (64) with uniform noise ±100, contrast-sensitive Potts weights
/// `1 + round(30 · exp(−ΔI² / (2 · 40²)))` from the noisy intensities.
pub fn segmentation_3d(side: usize, seed: u64) -> QuadraticInstance {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = side * side * side;
    let mut clean = vec![false; n];
    let num_balls = 6;
    for _ in 0..num_balls {
        let c: [i64; 3] = [0, 1, 2].map(|_| rng.gen_range(0..side.max(1)) as i64);
        let r = rng.gen_range(2..(side / 4).max(3)) as i64;
        for z in (c[2] - r).max(0)..(c[2] + r).min(side as i64) {
            for y in (c[1] - r).max(0)..(c[1] + r).min(side as i64) {
                for x in (c[0] - r).max(0)..(c[0] + r).min(side as i64) {
                    let d2 = (x - c[0]).pow(2) + (y - c[1]).pow(2) + (z - c[2]).pow(2);
                    if d2 <= r * r {
                        clean[(z as usize * side + y as usize) * side + x as usize] = true;
                    }
                }
            }
        }
    }
    let intensity: Vec<i32> = clean
        .iter()
        .map(|&c| {
            let level = if c { 192 } else { 64 };
            (level + rng.gen_range(-100..=100)).clamp(0, 255)
        })
        .collect();
    let unary = intensity.iter().map(|&v| data_cost(v)).collect();
    let weight = |a: i32, b: i32| {
        let d = f64::from(a - b);
        1 + (30.0 * (-d * d / (2.0 * 40.0 * 40.0)).exp()).round() as i32
    };
    let mut pairs = Vec::with_capacity(3 * n);
    let s = side;
    for z in 0..s {
        for y in 0..s {
            for x in 0..s {
                let i = (z * s + y) * s + x;
                let mut push = |j: usize| {
                    let w = weight(intensity[i], intensity[j]);
                    pairs.push(PairTerm {
                        i: i as u32,
                        j: j as u32,
                        e: [0, w, w, 0],
                    });
                };
                if x + 1 < s {
                    push(i + 1);
                }
                if y + 1 < s {
                    push(i + s);
                }
                if z + 1 < s {
                    push(i + s * s);
                }
            }
        }
    }
    QuadraticInstance {
        name: format!("segment3d_{side}"),
        num_vars: n,
        unary,
        pairs,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generators_are_seeded_and_sized() {
        let a = denoising_grid(16, 12, 3);
        assert_eq!(a.num_vars, 192);
        assert_eq!(a.pairs.len(), 15 * 12 + 16 * 11);
        assert_eq!(a.unary, denoising_grid(16, 12, 3).unary);
        assert!(a.is_cut_form());
        let b = random_sparse(1000, 6, 5);
        assert_eq!(b.pairs.len(), 3000);
        assert!(!b.is_cut_form());
        let distinct: FxHashSet<(u32, u32)> = b
            .pairs
            .iter()
            .map(|p| (p.i.min(p.j), p.i.max(p.j)))
            .collect();
        assert_eq!(distinct.len(), b.pairs.len());
        let c = segmentation_3d(6, 9);
        assert_eq!(c.num_vars, 216);
        assert_eq!(c.pairs.len(), 3 * 6 * 6 * 5);
    }

    #[test]
    fn cut_form_graph_flow_equals_qpbo_minimum() {
        for inst in [denoising_grid(20, 20, 1), segmentation_3d(7, 2)] {
            let mut g = inst.to_graph::<i64>().map(|mut g| g.maxflow(false));
            let mut q = inst.to_qpbo::<i64>();
            q.solve();
            q.compute_weak_persistencies();
            let x = q.labelling_or_zero();
            assert_eq!(g.take(), Some(q.energy(&x)));
            assert_eq!(inst.energy(&x), q.energy(&x));
            assert_eq!(q.twice_lower_bound(), 2 * q.energy(&x));
        }
    }

    #[test]
    fn raw_file_has_the_documented_size() {
        let inst = random_sparse(50, 4, 1);
        let dir = std::env::temp_dir().join(format!("pbo-instances-{}", std::process::id()));
        let path = inst.write_raw(&dir);
        let Ok(path) = path else {
            panic!("write failed: {path:?}");
        };
        let len = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
        assert_eq!(len, 24 + 8 * 50 + 24 * 100);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
