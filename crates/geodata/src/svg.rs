//! An SVG canvas in the local metric frame (metres, y up) for pictures of maps, scans and
//! results: outlines, segments, poses, a scale bar.
//!
//! ```
//! use geodata::svg::Svg;
//! let mut svg = Svg::new(200.0, [0.0, 0.0], [50.0, 25.0]);
//! svg.polygon(&[[1.0, 1.0], [9.0, 1.0], [9.0, 9.0]], "fill:#ccc");
//! svg.scale_bar(10.0);
//! assert!(svg.finish().starts_with("<svg"));
//! ```

use std::fmt::Write as _;

/// An SVG drawing in a world frame (metres, y up) mapped onto a pixel canvas (y down).
pub struct Svg {
    width_px: f64,
    height_px: f64,
    min: [f64; 2],
    scale: f64,
    body: String,
}

impl Svg {
    /// A canvas `width_px` wide showing the world box `min..max` (aspect ratio kept).
    pub fn new(width_px: f64, min: [f64; 2], max: [f64; 2]) -> Svg {
        let span_x = (max[0] - min[0]).max(1e-9);
        let span_y = (max[1] - min[1]).max(1e-9);
        let scale = width_px / span_x;
        Svg {
            width_px,
            height_px: span_y * scale,
            min,
            scale,
            body: String::new(),
        }
    }

    /// World → pixel coordinates.
    pub fn px(&self, p: [f64; 2]) -> (f64, f64) {
        (
            (p[0] - self.min[0]) * self.scale,
            self.height_px - (p[1] - self.min[1]) * self.scale,
        )
    }

    /// Metres per pixel inverted: pixels per metre.
    pub fn pixels_per_metre(&self) -> f64 {
        self.scale
    }

    /// A closed polygon with an SVG style attribute string.
    pub fn polygon(&mut self, ring: &[[f64; 2]], style: &str) {
        let mut pts = String::new();
        for &p in ring {
            let (x, y) = self.px(p);
            let _ = write!(pts, "{x:.1},{y:.1} ");
        }
        let _ = writeln!(self.body, r#"<polygon points="{pts}" style="{style}"/>"#);
    }

    /// An open polyline.
    pub fn polyline(&mut self, pts_world: &[[f64; 2]], style: &str) {
        let mut pts = String::new();
        for &p in pts_world {
            let (x, y) = self.px(p);
            let _ = write!(pts, "{x:.1},{y:.1} ");
        }
        let _ = writeln!(
            self.body,
            r#"<polyline points="{pts}" style="fill:none;{style}"/>"#
        );
    }

    /// A circle of a radius in pixels.
    pub fn circle(&mut self, c: [f64; 2], radius_px: f64, style: &str) {
        let (x, y) = self.px(c);
        let _ = writeln!(
            self.body,
            r#"<circle cx="{x:.1}" cy="{y:.1}" r="{radius_px:.1}" style="{style}"/>"#
        );
    }

    /// A scale bar of `metres` at the lower left.
    pub fn scale_bar(&mut self, metres: f64) {
        let len = metres * self.scale;
        let y = self.height_px - 12.0;
        let _ = writeln!(
            self.body,
            r#"<line x1="10" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" style="stroke:black;stroke-width:3"/><text x="10" y="{:.1}" font-size="12" font-family="sans-serif">{metres} m</text>"#,
            10.0 + len,
            y - 6.0
        );
    }

    /// The finished SVG document.
    pub fn finish(&self) -> String {
        format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{:.0}" height="{:.0}" viewBox="0 0 {:.0} {:.0}" style="background:#f4f1ea">{}</svg>"#,
            self.width_px, self.height_px, self.width_px, self.height_px, self.body
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn world_maps_to_pixels_with_y_down() {
        let svg = Svg::new(100.0, [10.0, 20.0], [20.0, 25.0]);
        assert_eq!(svg.pixels_per_metre(), 10.0);
        assert_eq!(svg.px([10.0, 20.0]), (0.0, 50.0));
        assert_eq!(svg.px([20.0, 25.0]), (100.0, 0.0));
    }
}
