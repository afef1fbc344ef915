//! A top-view raster of coloured 3-D points in the local frame: the highest point of each
//! pixel gives its colour (a labelled scan or map seen from above).
//!
//! ```
//! use geodata::topview::TopView;
//! let mut view = TopView::new([0.0, 0.0], 0.5, 4, [255; 3]);
//! view.plot([0.1, 0.1, 0.0], [10, 10, 10]);
//! view.plot([0.2, 0.2, 1.0], [200, 0, 0]); // higher: wins the pixel
//! assert_eq!(&view.rgb()[3 * (1 * 4 + 2)..][..3], &[200, 0, 0]);
//! ```

/// A square top-view image centred on a point, highest point per pixel.
#[derive(Debug, Clone)]
pub struct TopView {
    side: usize,
    centre: [f64; 2],
    metres_per_px: f64,
    top_z: Vec<f64>,
    rgb: Vec<u8>,
}

impl TopView {
    /// An image `side` × `side` pixels of `metres_per_px` centred on `centre`, filled with
    /// `background`.
    pub fn new(centre: [f64; 2], metres_per_px: f64, side: usize, background: [u8; 3]) -> Self {
        TopView {
            side,
            centre,
            metres_per_px,
            top_z: vec![f64::NEG_INFINITY; side * side],
            rgb: background.repeat(side * side),
        }
    }

    /// Colours the pixel under `p` with `colour` if `p` is the highest point seen there.
    pub fn plot(&mut self, p: [f64; 3], colour: [u8; 3]) {
        let half = self.side as f64 / 2.0;
        let x = ((p[0] - self.centre[0]) / self.metres_per_px + half).floor();
        let y = (half - (p[1] - self.centre[1]) / self.metres_per_px).floor();
        if !(x >= 0.0 && y >= 0.0 && x < self.side as f64 && y < self.side as f64) {
            return;
        }
        let i = y as usize * self.side + x as usize;
        if p[2] > self.top_z[i] {
            self.top_z[i] = p[2];
            self.rgb[3 * i..3 * i + 3].copy_from_slice(&colour);
        }
    }

    /// Pixels per side.
    pub fn side(&self) -> usize {
        self.side
    }

    /// The image as 8-bit RGB, row-major, top (north) row first.
    pub fn rgb(&self) -> &[u8] {
        &self.rgb
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outside_and_nan_points_are_skipped_and_north_is_up() {
        let mut v = TopView::new([10.0, 20.0], 1.0, 2, [0; 3]);
        v.plot([f64::NAN, 20.0, 0.0], [9; 3]);
        v.plot([12.5, 20.0, 0.0], [9; 3]);
        assert!(v.rgb().iter().all(|&c| c == 0));
        v.plot([9.5, 20.5, 0.0], [7; 3]); // west, north: top-left pixel
        assert_eq!(&v.rgb()[..3], &[7; 3]);
        v.plot([9.5, 20.5, -1.0], [5; 3]); // lower: does not win
        assert_eq!(&v.rgb()[..3], &[7; 3]);
    }
}
