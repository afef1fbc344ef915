//! Map edges and the directional distance-transform tensor of Fast Directional Chamfer
//! Matching (Liu, Tuzel, Veeraraghavan, Chellappa, "Fast directional chamfer matching",
//! CVPR 2010, doi:10.1109/CVPR.2010.5539837), with a lower-bound pyramid for the search.
//!
//! The tensor has one channel per quantized edge orientation (default 12 over [0, π), channel
//! width w). Channel c at cell x holds `min_e |x − e| + λ·w·Δc(c, c_e)`, truncated at τ, over
//! the map edges e with orientation channel c_e (Δc the cyclic channel distance): the exact
//! point-to-segment distance from the cell centre to each edge within τ is written into its
//! own channel, then FDCM's recursion along the orientation axis adds the penalty. Values are
//! stored as u8 in units of τ/255, all channels of a cell adjacent. Building costs
//! O(Σ_e (|e| + 2τ)·2τ / grid² + cells · channels), in parallel over stripes of rows.
//!
//! [`IntegralDt`] holds FDCM's integral distance transforms along each channel's direction,
//! so the sum of a channel over a digital line is two look-ups.
//!
//! [`BoundPyramid`] level h ≥ 2 (box side s = 2^h) holds, per channel, the minimum of the
//! tensor over the window of (2^k + 1)·u cells per axis starting at each multiple of
//! u = 2^(h−k) (k = [`stride_shift`]): the s × s window of a sample whose cell lies in
//! [b·u, (b + 1)·u) lies inside window b, which gives the lower bounds of the branch-and-bound
//! search (samples grouped per u-block). Level 1 holds the exact minimum over the 2 × 2 cells
//! starting at every cell. With k = 1 a window spans 1.5 s instead of the 2s of aligned
//! windows at stride s.

use crate::{LocalizeError, Result, Segment};
use geodata::osm::OsmMap;
use rayon::prelude::*;

/// Options of the distance-transform tensor.
#[derive(Debug, Clone, PartialEq)]
pub struct ChamferOptions {
    /// Grid cell size, metres.
    pub grid_m: f64,
    /// Number of orientation channels over [0, π).
    pub channels: usize,
    /// Orientation penalty λ, metres per radian.
    pub lambda_m_per_rad: f64,
    /// Truncation τ of the distance, metres.
    pub truncation_m: f64,
    /// Largest number of grid cells (per channel).
    pub max_cells: usize,
}

impl Default for ChamferOptions {
    fn default() -> Self {
        ChamferOptions {
            grid_m: 0.5,
            channels: 12,
            lambda_m_per_rad: 2.0,
            truncation_m: 3.0,
            max_cells: 64_000_000,
        }
    }
}

/// The building outline edges (outer and inner rings) of a map, in its local frame.
pub fn map_edges(map: &OsmMap) -> Vec<Segment> {
    let mut edges = Vec::new();
    for b in &map.buildings {
        for ring in std::iter::once(&b.outer).chain(b.inners.iter()) {
            for (i, &a) in ring.iter().enumerate() {
                let Some(&b) = ring.get((i + 1) % ring.len()) else {
                    continue;
                };
                let s = Segment::new(a, b);
                if s.length() > 1e-6 && a.iter().chain(b.iter()).all(|v| v.is_finite()) {
                    edges.push(s);
                }
            }
        }
    }
    edges
}

/// Bounding box `(min, max)` of segments, `None` when empty.
pub fn bounding_box(segments: &[Segment]) -> Option<([f64; 2], [f64; 2])> {
    let mut it = segments.iter().flat_map(|s| [s.a, s.b]);
    let first = it.next()?;
    Some(it.fold((first, first), |(lo, hi), p| {
        (
            [lo[0].min(p[0]), lo[1].min(p[1])],
            [hi[0].max(p[0]), hi[1].max(p[1])],
        )
    }))
}

/// The directional distance-transform tensor (u8, units of τ/255).
#[derive(Debug, Clone, PartialEq)]
pub struct DtTensor {
    /// Lower-left corner of lattice cell (0, 0), metres in the map frame.
    pub origin: [f64; 2],
    /// The lattice cell of the tensor's cell (0, 0) (zero but for a window of a larger
    /// lattice, such as a map tile's, whose cells then equal the larger tensor's bit for bit).
    pub offset: [i64; 2],
    /// Cell size, metres.
    pub grid_m: f64,
    /// Cells along x.
    pub width: usize,
    /// Cells along y.
    pub height: usize,
    /// Orientation channels.
    pub channels: usize,
    /// Stored units per metre (255 / τ).
    pub units_per_m: f64,
    /// λ, metres per radian.
    pub lambda_m_per_rad: f64,
    data: Vec<u8>,
}

impl DtTensor {
    /// Builds the tensor over the edges' bounding box plus τ (cells outside hold τ).
    pub fn build(edges: &[Segment], options: &ChamferOptions) -> Result<DtTensor> {
        Self::check_options(options)?;
        let tau = options.truncation_m;
        let (min, max) = bounding_box(edges).unwrap_or(([0.0, 0.0], [0.0, 0.0]));
        let origin = [min[0] - tau - options.grid_m, min[1] - tau - options.grid_m];
        let width = ((max[0] + tau - origin[0]) / options.grid_m).ceil() as usize + 2;
        let height = ((max[1] + tau - origin[1]) / options.grid_m).ceil() as usize + 2;
        if width.saturating_mul(height) > options.max_cells {
            return Err(LocalizeError::MapTooLarge {
                width_m: max[0] - min[0],
                height_m: max[1] - min[1],
                grid_m: options.grid_m,
                max_cells: options.max_cells,
            });
        }
        Ok(Self::rasterize(
            edges,
            options,
            origin,
            [0, 0],
            width,
            height,
        ))
    }

    /// Builds the cells `[offset, offset + (width, height))` of the lattice anchored at
    /// `origin` (the window of a map tile): every cell holds what the tensor of all `edges`
    /// on that lattice holds there, bit for bit, given the edges within τ of the window.
    pub fn build_window(
        edges: &[Segment],
        options: &ChamferOptions,
        origin: [f64; 2],
        offset: [i64; 2],
        size: [usize; 2],
    ) -> Result<DtTensor> {
        Self::check_options(options)?;
        let [width, height] = size;
        if width.saturating_mul(height) > options.max_cells || width == 0 || height == 0 {
            return Err(LocalizeError::MapTooLarge {
                width_m: width as f64 * options.grid_m,
                height_m: height as f64 * options.grid_m,
                grid_m: options.grid_m,
                max_cells: options.max_cells,
            });
        }
        Ok(Self::rasterize(
            edges, options, origin, offset, width, height,
        ))
    }

    fn check_options(options: &ChamferOptions) -> Result<()> {
        let checks = [
            ("grid_m", options.grid_m, options.grid_m > 0.0),
            (
                "truncation_m",
                options.truncation_m,
                options.truncation_m > 0.0,
            ),
            (
                "lambda_m_per_rad",
                options.lambda_m_per_rad,
                options.lambda_m_per_rad >= 0.0,
            ),
            (
                "channels",
                options.channels as f64,
                (1..=255).contains(&options.channels),
            ),
        ];
        for (name, value, ok) in checks {
            if !ok || !value.is_finite() {
                return Err(LocalizeError::InvalidOption {
                    name,
                    value,
                    expected: "a positive finite number (channels 1..=255, λ ≥ 0)",
                });
            }
        }
        Ok(())
    }

    /// The tensor's cells, `width × height` from lattice cell `offset`.
    fn rasterize(
        edges: &[Segment],
        options: &ChamferOptions,
        origin: [f64; 2],
        offset: [i64; 2],
        width: usize,
        height: usize,
    ) -> DtTensor {
        let tau = options.truncation_m;
        let channels = options.channels;
        let bin = std::f64::consts::PI / channels as f64;
        let units_per_m = 255.0 / tau;
        let g = options.grid_m;
        // One orientation-channel step costs λ·w (FDCM's quantized orientation penalty).
        let step = (options.lambda_m_per_rad * bin * units_per_m)
            .round()
            .min(255.0) as u8;
        let classes: Vec<usize> = edges
            .iter()
            .map(|e| ((crate::wrap_pi(e.orientation_rad()) / bin).round() as usize) % channels)
            .collect();
        // The tensor cell (lattice cell minus offset) of a coordinate, rounded by `round`.
        let lattice = |v: f64, axis: usize, round: fn(f64) -> f64| -> i64 {
            round((v - origin[axis]) / g) as i64 - offset[axis]
        };
        // Edges bucketed by the stripes of rows their τ-neighbourhood meets.
        const STRIPE: usize = 64;
        let stripes = height.div_ceil(STRIPE);
        let mut by_stripe: Vec<Vec<usize>> = vec![Vec::new(); stripes];
        for (k, e) in edges.iter().enumerate() {
            let y0 = lattice(e.a[1].min(e.b[1]) - tau, 1, f64::floor);
            let y1 = lattice(e.a[1].max(e.b[1]) + tau, 1, f64::ceil);
            if y1 < 0 || y0 >= height as i64 {
                continue;
            }
            let (y0, y1) = (y0.max(0) as usize, (y1 as usize).min(height - 1));
            for list in by_stripe.iter_mut().take(y1 / STRIPE + 1).skip(y0 / STRIPE) {
                list.push(k);
            }
        }
        let mut data = vec![255u8; width * height * channels];
        data.par_chunks_mut(width * channels * STRIPE)
            .enumerate()
            .for_each(|(si, block)| {
                let row0 = si * STRIPE;
                let rows = block.len() / (width * channels);
                // Exact Euclidean distance of each cell centre to the edges of each class.
                for &k in by_stripe.get(si).map(Vec::as_slice).unwrap_or(&[]) {
                    let (e, c) = (&edges[k], classes[k]);
                    let lo = [e.a[0].min(e.b[0]) - tau, e.a[1].min(e.b[1]) - tau];
                    let hi = [e.a[0].max(e.b[0]) + tau, e.a[1].max(e.b[1]) + tau];
                    let x0 = lattice(lo[0], 0, f64::floor).max(0) as usize;
                    let x1 = lattice(hi[0], 0, f64::ceil);
                    if x1 < 0 || x0 >= width {
                        continue;
                    }
                    let x1 = (x1 as usize).min(width - 1);
                    let y0 = (lattice(lo[1], 1, f64::floor).max(0) as usize).max(row0);
                    let y1 = lattice(hi[1], 1, f64::ceil).max(0) as usize;
                    let y1 = y1.min(row0 + rows - 1);
                    for y in y0..=y1 {
                        let cy = origin[1] + ((offset[1] + y as i64) as f64 + 0.5) * g;
                        let row = (y - row0) * width * channels;
                        for x in x0..=x1 {
                            let cx = origin[0] + ((offset[0] + x as i64) as f64 + 0.5) * g;
                            let d = e.distance_to([cx, cy]);
                            if d < tau {
                                let v = (d * units_per_m).round() as u8;
                                let cell = &mut block[row + x * channels + c];
                                if v < *cell {
                                    *cell = v;
                                }
                            }
                        }
                    }
                }
                // Orientation recursion around the channel cycle (two rounds each way).
                for cell in block.chunks_mut(channels) {
                    for k in 1..2 * channels {
                        let (prev, cur) = ((k - 1) % channels, k % channels);
                        let v = cell[prev].saturating_add(step);
                        if v < cell[cur] {
                            cell[cur] = v;
                        }
                    }
                    for k in (0..2 * channels - 1).rev() {
                        let (next, cur) = ((k + 1) % channels, k % channels);
                        let v = cell[next].saturating_add(step);
                        if v < cell[cur] {
                            cell[cur] = v;
                        }
                    }
                }
            });
        DtTensor {
            origin,
            offset,
            grid_m: g,
            width,
            height,
            channels,
            units_per_m,
            lambda_m_per_rad: options.lambda_m_per_rad,
            data,
        }
    }

    /// The geometry of a lattice without cells (every value τ): converts between cells and
    /// metres and makes templates for tensors on that lattice.
    pub fn lattice(
        origin: [f64; 2],
        grid_m: f64,
        channels: usize,
        units_per_m: f64,
        lambda_m_per_rad: f64,
    ) -> DtTensor {
        DtTensor {
            origin,
            offset: [0, 0],
            grid_m,
            width: 0,
            height: 0,
            channels,
            units_per_m,
            lambda_m_per_rad,
            data: Vec::new(),
        }
    }

    /// The channel of a line orientation (radians, any value; period π).
    pub fn channel_of(&self, orientation_rad: f64) -> usize {
        let bin = std::f64::consts::PI / self.channels as f64;
        let k = (crate::wrap_pi(orientation_rad) / bin).round() as usize;
        k % self.channels
    }

    /// The cell containing a map point (may be outside the grid).
    pub fn cell_of(&self, p: [f64; 2]) -> (i64, i64) {
        (
            ((p[0] - self.origin[0]) / self.grid_m).floor() as i64 - self.offset[0],
            ((p[1] - self.origin[1]) / self.grid_m).floor() as i64 - self.offset[1],
        )
    }

    /// The lower-left corner of a cell, metres in the map frame.
    pub fn corner_of(&self, x: i64, y: i64) -> [f64; 2] {
        [
            self.origin[0] + (self.offset[0] + x) as f64 * self.grid_m,
            self.origin[1] + (self.offset[1] + y) as f64 * self.grid_m,
        ]
    }

    /// The stored value (units of τ/255) of a channel at a cell; τ (255) outside the grid.
    #[inline]
    pub fn get(&self, c: usize, x: i64, y: i64) -> u8 {
        if x < 0 || y < 0 || x as usize >= self.width || y as usize >= self.height {
            return 255;
        }
        self.data
            .get((y as usize * self.width + x as usize) * self.channels + c)
            .copied()
            .unwrap_or(255)
    }

    /// Value in metres of a channel at a map point.
    pub fn value_m(&self, c: usize, p: [f64; 2]) -> f64 {
        let (x, y) = self.cell_of(p);
        self.get(c, x, y) as f64 / self.units_per_m
    }

    /// Memory held, bytes.
    pub fn bytes(&self) -> usize {
        self.data.len()
    }

    /// The tensor as a flat cell-major grid.
    pub fn view(&self) -> GridView<'_> {
        GridView {
            data: &self.data,
            w: self.width as i64,
            h: self.height as i64,
            channels: self.channels as i64,
            offset: 0,
        }
    }
}

/// A cell-major u8 grid (all channels of a cell adjacent) as one flat slice, so that a sum
/// over fixed cell offsets is one index addition per term.
#[derive(Debug, Clone, Copy)]
pub struct GridView<'a> {
    /// Values, index `((y + offset) · w + x + offset) · channels + c`.
    pub data: &'a [u8],
    /// Stored cells along x.
    pub w: i64,
    /// Stored cells along y.
    pub h: i64,
    /// Channels per cell.
    pub channels: i64,
    /// Stored position of coordinate 0 (coordinates from −offset are stored).
    pub offset: i64,
}

/// Integral distance transforms of FDCM: per channel, the running sum of the channel along
/// digital lines in the channel's direction.
#[derive(Debug, Clone)]
pub struct IntegralDt {
    width: usize,
    height: usize,
    /// Per channel, the running sums.
    sums: Vec<Vec<u32>>,
    /// Per channel, each pixel's predecessor on its digital line (`u32::MAX`: none).
    prev: Vec<Vec<u32>>,
}

impl IntegralDt {
    /// Builds the integral DTs of every channel (O(cells · channels)).
    pub fn build(dt: &DtTensor) -> IntegralDt {
        let (w, h) = (dt.width, dt.height);
        let bin = std::f64::consts::PI / dt.channels as f64;
        let per_channel: Vec<(Vec<u32>, Vec<u32>)> = (0..dt.channels)
            .into_par_iter()
            .map(|c| {
                let phi = c as f64 * bin;
                let (dx, dy) = (phi.cos(), phi.sin());
                let mut sums = vec![0u32; w * h];
                let mut prev = vec![u32::MAX; w * h];
                // Each pixel's predecessor is one step back along the direction, rounded.
                let x_major = dx.abs() >= dy.abs();
                let order: Vec<usize> = if x_major {
                    (0..w)
                        .flat_map(|x| (0..h).map(move |y| y * w + x))
                        .collect()
                } else {
                    (0..h)
                        .flat_map(|y| (0..w).map(move |x| y * w + x))
                        .collect()
                };
                for idx in order {
                    let (x, y) = ((idx % w) as i64, (idx / w) as i64);
                    let (px, py) = if x_major {
                        (x - 1, y - step_offset(x, dy / dx))
                    } else {
                        (x - step_offset(y, dx / dy), y - 1)
                    };
                    let v = dt.get(c, x, y) as u32;
                    if px >= 0 && py >= 0 && (px as usize) < w && (py as usize) < h {
                        let p = py as usize * w + px as usize;
                        sums[idx] = sums[p] + v;
                        prev[idx] = p as u32;
                    } else {
                        sums[idx] = v;
                    }
                }
                (sums, prev)
            })
            .collect();
        let (sums, prev) = per_channel.into_iter().unzip();
        IntegralDt {
            width: w,
            height: h,
            sums,
            prev,
        }
    }

    /// Sum of channel `c` over the digital line of `steps` + 1 pixels ending at (x, y),
    /// walking back along the channel direction: O(steps) only to find the start, O(1) sums.
    pub fn line_sum(&self, c: usize, x: usize, y: usize, steps: usize) -> Option<u32> {
        let (sums, prev) = (self.sums.get(c)?, self.prev.get(c)?);
        let end = y.checked_mul(self.width)?.checked_add(x)?;
        if x >= self.width || y >= self.height {
            return None;
        }
        let mut start = end;
        for _ in 0..steps {
            let p = *prev.get(start)?;
            if p == u32::MAX {
                return None;
            }
            start = p as usize;
        }
        let before = match *prev.get(start)? {
            u32::MAX => 0,
            p => *sums.get(p as usize)?,
        };
        Some(sums.get(end)? - before)
    }

    /// The pixels of the digital line of `steps` + 1 pixels ending at (x, y), last first.
    pub fn line_pixels(&self, c: usize, x: usize, y: usize, steps: usize) -> Vec<(usize, usize)> {
        let mut out = Vec::new();
        let Some(prev) = self.prev.get(c) else {
            return out;
        };
        let mut idx = y * self.width + x;
        out.push((x, y));
        for _ in 0..steps {
            match prev.get(idx) {
                Some(&p) if p != u32::MAX => {
                    idx = p as usize;
                    out.push((idx % self.width, idx / self.width));
                }
                _ => break,
            }
        }
        out
    }
}

/// The minor-axis step taken when the major coordinate moves from `m - 1` to `m` on the
/// digital line of slope `slope` through the origin.
fn step_offset(m: i64, slope: f64) -> i64 {
    (m as f64 * slope).round() as i64 - ((m - 1) as f64 * slope).round() as i64
}

/// Multi-resolution lower bounds of a [`DtTensor`] (see the module doc).
#[derive(Debug, Clone, PartialEq)]
pub struct BoundPyramid {
    /// Levels h = 2 ..= top: with k = [`stride_shift`]`(h)` and u = 2^(h−k), the minimum over
    /// the (2^k + 1)·u cells (per axis) starting at each multiple of u.
    levels: Vec<BoundLevel>,
    /// Exact minimum over the 2 × 2 cells starting at each cell (cell −1 stored at 0).
    fine: BoundLevel,
}

/// Minima over aligned u × u blocks (block b covers cells [b·u, (b + 1)·u)), from the blocks
/// of half the size (`get_half`, 255 beyond the grid).
fn aligned_blocks(
    w: usize,
    h: usize,
    ch: usize,
    get_half: impl Fn(usize, i64, i64) -> u8 + Sync,
) -> BoundLevel {
    let mut data = vec![255u8; w * h * ch];
    data.par_chunks_mut(w * ch)
        .enumerate()
        .for_each(|(j, row)| {
            let j = j as i64;
            for i in 0..w {
                let ii = i as i64;
                for c in 0..ch {
                    row[i * ch + c] = get_half(c, 2 * ii, 2 * j)
                        .min(get_half(c, 2 * ii + 1, 2 * j))
                        .min(get_half(c, 2 * ii, 2 * j + 1))
                        .min(get_half(c, 2 * ii + 1, 2 * j + 1));
                }
            }
        });
    BoundLevel {
        offset: 0,
        w,
        h,
        channels: ch,
        data,
    }
}

/// Minima over m × m aligned blocks starting at every block from −m.
fn block_windows(blocks: &BoundLevel, m: usize) -> BoundLevel {
    let ch = blocks.channels;
    let (w, h) = (blocks.w + m, blocks.h + m);
    let mi = m as i64;
    let mut data = vec![255u8; w * h * ch];
    data.par_chunks_mut(w * ch)
        .enumerate()
        .for_each(|(sj, row)| {
            let j = sj as i64 - mi;
            for si in 0..w {
                let i = si as i64 - mi;
                let out = &mut row[si * ch..(si + 1) * ch];
                for dy in 0..mi {
                    for dx in 0..mi {
                        if let Some(src) = blocks.cell(i + dx, j + dy) {
                            for (o, v) in out.iter_mut().zip(src) {
                                *o = (*o).min(*v);
                            }
                        }
                    }
                }
            }
        });
    BoundLevel {
        offset: mi,
        w,
        h,
        channels: ch,
        data,
    }
}

/// log2 of (box side / window stride) at level h ≥ 2: level h's windows start every
/// u = 2^(h − shift) cells and span (2^shift + 1)·u cells, so a box's samples are grouped as
/// the template's level h − shift. Blocks are at least 2 cells. k = 1 measured best on MCD
/// scans among Monaco distractors (k = 2: 30 % fewer boxes, no faster; k = 3: slower; the
/// aligned 2s windows at stride s: 75 % more boxes, 1.5–2.5× slower).
#[inline]
pub fn stride_shift(h: u32) -> u32 {
    STRIDE_SHIFT.min(h.saturating_sub(1))
}

const STRIDE_SHIFT: u32 = 1;

#[derive(Debug, Clone, PartialEq)]
struct BoundLevel {
    /// Stored position of block 0 (blocks from −offset are stored).
    offset: i64,
    /// Stored blocks along x (block index −offset ..= n − 1 − offset stored at 0 ..= n − 1).
    w: usize,
    h: usize,
    channels: usize,
    /// Cell-major: all channels of a block are adjacent.
    data: Vec<u8>,
}

impl BoundPyramid {
    /// Builds levels 1 ..= `top` (level 0 is the tensor itself).
    pub fn build(dt: &DtTensor, top: u32) -> BoundPyramid {
        let ch = dt.channels;
        // Fine: exact 2 × 2 minima at every cell (cell −1 stored at 0).
        let (fw, fh) = (dt.width + 1, dt.height + 1);
        let mut fine = vec![255u8; fw * fh * ch];
        fine.par_chunks_mut(fw * ch)
            .enumerate()
            .for_each(|(bj, row)| {
                let j = bj as i64 - 1;
                for bi in 0..fw {
                    let i = bi as i64 - 1;
                    for c in 0..ch {
                        row[bi * ch + c] = dt
                            .get(c, i, j)
                            .min(dt.get(c, i + 1, j))
                            .min(dt.get(c, i, j + 1))
                            .min(dt.get(c, i + 1, j + 1));
                    }
                }
            });
        let fine = BoundLevel {
            offset: 1,
            w: fw,
            h: fh,
            channels: ch,
            data: fine,
        };
        // Aligned u-blocks for u = 2, 4, …, and level h's windows of m × m of them.
        let mut levels = Vec::new();
        let mut blocks: Option<(usize, BoundLevel)> = None;
        for h in 2..=top {
            let u = 1usize << (h - stride_shift(h));
            while blocks.as_ref().is_none_or(|(bu, _)| *bu < u) {
                let bu = blocks.as_ref().map_or(2, |(bu, _)| 2 * bu);
                let (bw, bh) = (dt.width.div_ceil(bu), dt.height.div_ceil(bu));
                let next = match &blocks {
                    None => aligned_blocks(bw, bh, ch, |c, x, y| dt.get(c, x, y)),
                    Some((_, prev)) => aligned_blocks(bw, bh, ch, |c, x, y| prev.get(ch, c, x, y)),
                };
                blocks = Some((bu, next));
            }
            if let Some((_, b)) = &blocks {
                levels.push(block_windows(b, (1 << stride_shift(h)) + 1));
            }
        }
        BoundPyramid { levels, fine }
    }

    /// Minimum of channel `c` over the 2 × 2 cells starting at cell (x, y); 255 beyond the grid.
    #[inline]
    pub fn get_fine(&self, channels: usize, c: usize, x: i64, y: i64) -> u8 {
        self.fine.get(channels, c, x, y)
    }

    /// Level h ≥ 1 as a flat grid (the fine level for h = 1), `None` beyond the top.
    pub fn level_view(&self, level: u32) -> Option<GridView<'_>> {
        match level {
            1 => Some(self.fine.view()),
            _ => self
                .levels
                .get((level as usize).checked_sub(2)?)
                .map(BoundLevel::view),
        }
    }

    /// Highest level.
    pub fn top(&self) -> u32 {
        self.levels.len() as u32 + 1
    }

    /// Lower bound of channel `c` over every window of 2^level cells (per axis) starting in
    /// cells [b·u, (b + 1)·u), u = 2^(level − [`stride_shift`]`(level)`), for level ≥ 2: the
    /// minimum over the window's (2^k + 1)·u cells; 255 beyond the grid, 0 beyond the top.
    #[inline]
    pub fn get(&self, level: u32, c: usize, bi: i64, bj: i64) -> u8 {
        match (level as usize)
            .checked_sub(2)
            .and_then(|i| self.levels.get(i))
        {
            Some(l) => l.get(l.channels, c, bi, bj),
            None => 0,
        }
    }

    /// Memory held, bytes.
    pub fn bytes(&self) -> usize {
        self.levels.iter().map(|l| l.data.len()).sum::<usize>() + self.fine.data.len()
    }
}

impl BoundLevel {
    fn view(&self) -> GridView<'_> {
        GridView {
            data: &self.data,
            w: self.w as i64,
            h: self.h as i64,
            channels: self.channels as i64,
            offset: self.offset,
        }
    }

    #[inline]
    fn get(&self, _channels: usize, c: usize, bi: i64, bj: i64) -> u8 {
        self.cell(bi, bj)
            .and_then(|v| v.get(c))
            .copied()
            .unwrap_or(255)
    }

    /// All channels of block (bi, bj), `None` beyond the stored range.
    #[inline]
    fn cell(&self, bi: i64, bj: i64) -> Option<&[u8]> {
        let (x, y) = (bi + self.offset, bj + self.offset);
        if x < 0 || y < 0 || x as usize >= self.w || y as usize >= self.h {
            return None;
        }
        let start = (y as usize * self.w + x as usize) * self.channels;
        self.data.get(start..start + self.channels)
    }
}

/// Index file codec of the prepared map (see [`crate::index`]).
impl DtTensor {
    pub(crate) fn encode<'a>(&'a self, e: &mut crate::codec::Enc<'a>) {
        e.f64(self.origin[0]);
        e.f64(self.origin[1]);
        e.i64(self.offset[0]);
        e.i64(self.offset[1]);
        e.f64(self.grid_m);
        e.u64(self.width as u64);
        e.u64(self.height as u64);
        e.u64(self.channels as u64);
        e.f64(self.units_per_m);
        e.f64(self.lambda_m_per_rad);
        e.bytes(&self.data);
    }

    pub(crate) fn decode<R: std::io::Read>(d: &mut crate::codec::Dec<'_, R>) -> Result<DtTensor> {
        let origin: [f64; 2] = d.f64s("tensor origin")?;
        let offset: [i64; 2] = d.i64s("tensor offset")?;
        if offset.iter().any(|v| v.unsigned_abs() > 1 << 40) {
            return Err(d.bad(format!("tensor offset {offset:?} out of range")));
        }
        let grid_m = d.f64("tensor grid")?;
        let (width, height, channels) = (
            d.usize("tensor width")?,
            d.usize("tensor height")?,
            d.usize("tensor channels")?,
        );
        let units_per_m = d.f64("tensor units")?;
        let lambda_m_per_rad = d.f64("tensor lambda")?;
        let cells = width
            .checked_mul(height)
            .and_then(|c| c.checked_mul(channels))
            .ok_or_else(|| d.bad(format!("tensor {width} × {height} × {channels} overflows")))?;
        if grid_m <= 0.0 || units_per_m <= 0.0 || channels == 0 {
            return Err(d.bad(format!(
                "tensor grid {grid_m} m, {units_per_m} units/m, {channels} channels"
            )));
        }
        let data = d.bytes(cells, "tensor data")?;
        Ok(DtTensor {
            origin,
            offset,
            grid_m,
            width,
            height,
            channels,
            units_per_m,
            lambda_m_per_rad,
            data,
        })
    }
}

impl BoundLevel {
    fn encode<'a>(&'a self, e: &mut crate::codec::Enc<'a>) {
        e.i64(self.offset);
        e.u64(self.w as u64);
        e.u64(self.h as u64);
        e.u64(self.channels as u64);
        e.bytes(&self.data);
    }

    fn decode<R: std::io::Read>(d: &mut crate::codec::Dec<'_, R>) -> Result<BoundLevel> {
        let offset = d.i64("pyramid offset")?;
        let (w, h, channels) = (
            d.usize("pyramid width")?,
            d.usize("pyramid height")?,
            d.usize("pyramid channels")?,
        );
        if offset.unsigned_abs() > 1 << 32 {
            return Err(d.bad(format!("pyramid offset {offset}")));
        }
        let n = w
            .checked_mul(h)
            .and_then(|c| c.checked_mul(channels))
            .ok_or_else(|| d.bad(format!("pyramid level {w} × {h} × {channels} overflows")))?;
        let data = d.bytes(n, "pyramid data")?;
        Ok(BoundLevel {
            offset,
            w,
            h,
            channels,
            data,
        })
    }
}

impl BoundPyramid {
    pub(crate) fn encode<'a>(&'a self, e: &mut crate::codec::Enc<'a>) {
        e.u64(self.levels.len() as u64);
        for l in &self.levels {
            l.encode(e);
        }
        self.fine.encode(e);
    }

    pub(crate) fn decode<R: std::io::Read>(
        d: &mut crate::codec::Dec<'_, R>,
    ) -> Result<BoundPyramid> {
        let n = d.count(32, "pyramid levels")?;
        let levels = (0..n)
            .map(|_| BoundLevel::decode(d))
            .collect::<Result<Vec<_>>>()?;
        let fine = BoundLevel::decode(d)?;
        Ok(BoundPyramid { levels, fine })
    }
}

/// A translation search domain in cells: `[i0, i1) × [j0, j1)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Domain {
    /// First cell x.
    pub i0: i64,
    /// First cell y.
    pub j0: i64,
    /// One past the last cell x.
    pub i1: i64,
    /// One past the last cell y.
    pub j1: i64,
}

/// Index file codec of a domain (see [`crate::index`]).
impl Domain {
    pub(crate) fn encode(&self, e: &mut crate::codec::Enc<'_>) {
        for v in [self.i0, self.j0, self.i1, self.j1] {
            e.i64(v);
        }
    }

    pub(crate) fn decode<R: std::io::Read>(d: &mut crate::codec::Dec<'_, R>) -> Result<Domain> {
        let v: [i64; 4] = d.i64s("domain")?;
        if v.iter().any(|x| x.unsigned_abs() > 1 << 40) || v[2] < v[0] || v[3] < v[1] {
            return Err(d.bad(format!("domain {v:?} is not a cell box")));
        }
        Ok(Domain {
            i0: v[0],
            j0: v[1],
            i1: v[2],
            j1: v[3],
        })
    }
}

impl Domain {
    /// The cells whose corner lies in `min..max` (metres).
    pub fn from_box(dt: &DtTensor, min: [f64; 2], max: [f64; 2]) -> Domain {
        let (i0, j0) = dt.cell_of(min);
        let (i1, j1) = dt.cell_of(max);
        Domain {
            i0,
            j0,
            i1: i1 + 1,
            j1: j1 + 1,
        }
    }

    /// Number of cells.
    pub fn cells(&self) -> u64 {
        ((self.i1 - self.i0).max(0) * (self.j1 - self.j0).max(0)) as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_edges(rng: &mut ChaCha8Rng, n: usize, span: f64) -> Vec<Segment> {
        (0..n)
            .map(|_| {
                let a = [rng.gen_range(0.0..span), rng.gen_range(0.0..span)];
                let ang: f64 = rng.gen_range(0.0..std::f64::consts::TAU);
                let l = rng.gen_range(2.0..15.0);
                Segment::new(a, [a[0] + l * ang.cos(), a[1] + l * ang.sin()])
            })
            .collect()
    }

    #[test]
    fn tensor_matches_the_direct_directional_distance() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let edges = random_edges(&mut rng, 15, 40.0);
        let o = ChamferOptions::default();
        let dt = DtTensor::build(&edges, &o).unwrap();
        let bin = std::f64::consts::PI / o.channels as f64;
        for _ in 0..2000 {
            let x = rng.gen_range(0..dt.width as i64);
            let y = rng.gen_range(0..dt.height as i64);
            let c = rng.gen_range(0..o.channels);
            let centre = [
                dt.origin[0] + (x as f64 + 0.5) * o.grid_m,
                dt.origin[1] + (y as f64 + 0.5) * o.grid_m,
            ];
            let direct = edges
                .iter()
                .map(|e| {
                    let class = dt.channel_of(e.orientation_rad());
                    let steps = (c as i64 - class as i64).rem_euclid(o.channels as i64);
                    let steps = steps.min(o.channels as i64 - steps) as f64;
                    e.distance_to(centre) + o.lambda_m_per_rad * bin * steps
                })
                .fold(o.truncation_m, f64::min);
            let stored = dt.get(c, x, y) as f64 / dt.units_per_m;
            // u8 rounding: half a unit for the distance and per orientation step.
            assert!(
                (stored - direct).abs() <= 4.0 / dt.units_per_m + 1e-6,
                "{stored} vs {direct}"
            );
        }
    }

    #[test]
    fn pyramid_bounds_every_window() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let edges = random_edges(&mut rng, 10, 30.0);
        let dt = DtTensor::build(&edges, &ChamferOptions::default()).unwrap();
        let pyr = BoundPyramid::build(&dt, 4);
        for _ in 0..3000 {
            let level = rng.gen_range(1..=4u32);
            let s = 1i64 << level;
            let x = rng.gen_range(-20..dt.width as i64 + 20);
            let y = rng.gen_range(-20..dt.height as i64 + 20);
            let c = rng.gen_range(0..dt.channels);
            let mut true_min = 255u8;
            for yy in y..y + s {
                for xx in x..x + s {
                    true_min = true_min.min(dt.get(c, xx, yy));
                }
            }
            if level == 1 {
                assert_eq!(pyr.get_fine(dt.channels, c, x, y), true_min);
                continue;
            }
            let k = stride_shift(level);
            let u = level - k;
            let lb = pyr.get(level, c, x >> u, y >> u);
            assert!(
                lb <= true_min,
                "level {level} at ({x},{y}): {lb} > {true_min}"
            );
            // Exactly the minimum over the (2^k + 1)·2^u window.
            let (x0, y0) = ((x >> u) << u, (y >> u) << u);
            let side = ((1 << k) + 1) << u;
            let mut window_min = 255u8;
            for yy in y0..y0 + side {
                for xx in x0..x0 + side {
                    window_min = window_min.min(dt.get(c, xx, yy));
                }
            }
            assert_eq!(lb, window_min, "level {level} at ({x},{y})");
        }
    }

    #[test]
    fn integral_line_sums_equal_direct_sums() {
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let edges = random_edges(&mut rng, 10, 30.0);
        let dt = DtTensor::build(&edges, &ChamferOptions::default()).unwrap();
        let idt = IntegralDt::build(&dt);
        for _ in 0..500 {
            let c = rng.gen_range(0..dt.channels);
            let x = rng.gen_range(0..dt.width);
            let y = rng.gen_range(0..dt.height);
            let steps = rng.gen_range(0..20);
            let pixels = idt.line_pixels(c, x, y, steps);
            if pixels.len() != steps + 1 {
                assert_eq!(idt.line_sum(c, x, y, steps), None);
                continue;
            }
            let direct: u32 = pixels
                .iter()
                .map(|&(px, py)| dt.get(c, px as i64, py as i64) as u32)
                .sum();
            assert_eq!(idt.line_sum(c, x, y, steps), Some(direct));
            // Consecutive pixels are neighbours along the channel direction.
            for w in pixels.windows(2) {
                let (dx, dy) = (w[0].0 as i64 - w[1].0 as i64, w[0].1 as i64 - w[1].1 as i64);
                assert!(dx.abs() <= 1 && dy.abs() <= 1 && (dx, dy) != (0, 0));
            }
        }
    }

    #[test]
    fn empty_edge_set_gives_a_constant_tensor() {
        let dt = DtTensor::build(&[], &ChamferOptions::default()).unwrap();
        assert!((0..dt.width as i64).all(|x| dt.get(0, x, 0) == 255));
    }
}
