//! The demo's report: an HTML page of sections with figures (inline SVG, embedded PNG).

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

/// Escapes text for HTML/SVG.
pub fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Encodes 8-bit RGB pixels (row-major, top row first) as a PNG file (stored deflate).
pub fn encode_png_rgb(width: u32, height: u32, rgb: &[u8]) -> Vec<u8> {
    assert_eq!(
        rgb.len(),
        width as usize * height as usize * 3,
        "RGB buffer size"
    );
    let mut raw = Vec::with_capacity(rgb.len() + height as usize);
    for row in rgb.chunks_exact(width as usize * 3) {
        raw.push(0); // filter: none
        raw.extend_from_slice(row);
    }
    // zlib stream with stored (uncompressed) deflate blocks of ≤ 65535 bytes.
    let mut z = vec![0x78, 0x01];
    let blocks: Vec<&[u8]> = raw.chunks(65_535).collect();
    for (i, block) in blocks.iter().enumerate() {
        z.push(u8::from(i + 1 == blocks.len()));
        let len = block.len() as u16;
        z.extend_from_slice(&len.to_le_bytes());
        z.extend_from_slice(&(!len).to_le_bytes());
        z.extend_from_slice(block);
    }
    z.extend_from_slice(&adler32(&raw).to_be_bytes());
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&width.to_be_bytes());
    ihdr.extend_from_slice(&height.to_be_bytes());
    ihdr.extend_from_slice(&[8, 2, 0, 0, 0]); // 8-bit, truecolour, deflate, no filter, no interlace
    chunk(&mut png, b"IHDR", &ihdr);
    chunk(&mut png, b"IDAT", &z);
    chunk(&mut png, b"IEND", &[]);
    png
}

fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend_from_slice(&(data.len() as u32).to_be_bytes());
    let start = out.len();
    out.extend_from_slice(kind);
    out.extend_from_slice(data);
    let crc = crc32(&out[start..]);
    out.extend_from_slice(&crc.to_be_bytes());
}

fn crc32(data: &[u8]) -> u32 {
    let mut crc = 0xffff_ffffu32;
    for &b in data {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xedb8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

fn adler32(data: &[u8]) -> u32 {
    let (mut a, mut b) = (1u32, 0u32);
    for chunk in data.chunks(5552) {
        for &x in chunk {
            a += u32::from(x);
            b += a;
        }
        a %= 65_521;
        b %= 65_521;
    }
    (b << 16) | a
}

/// Base64 (standard alphabet, padded), for `data:` URIs.
pub fn base64(data: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(data.len().div_ceil(3) * 4);
    for c in data.chunks(3) {
        let n = (u32::from(c[0]) << 16)
            | (u32::from(*c.get(1).unwrap_or(&0)) << 8)
            | u32::from(*c.get(2).unwrap_or(&0));
        out.push(T[(n >> 18) as usize & 63] as char);
        out.push(T[(n >> 12) as usize & 63] as char);
        out.push(if c.len() > 1 {
            T[(n >> 6) as usize & 63] as char
        } else {
            '='
        });
        out.push(if c.len() > 2 {
            T[n as usize & 63] as char
        } else {
            '='
        });
    }
    out
}

/// An HTML report assembled section by section.
#[derive(Default)]
pub struct Html {
    sections: String,
}

impl Html {
    /// Adds a section with a heading, a paragraph (HTML allowed) and figures (HTML snippets).
    pub fn section(&mut self, title: &str, text_html: &str, figures: &[String]) {
        let _ = write!(
            self.sections,
            "<section><h2>{}</h2><p>{}</p><div class=\"figs\">",
            escape(title),
            text_html
        );
        for f in figures {
            let _ = write!(self.sections, "<figure>{f}</figure>");
        }
        self.sections.push_str("</div></section>\n");
    }

    /// An `<img>` tag embedding a PNG.
    pub fn png_img(png: &[u8], alt: &str, width_px: u32) -> String {
        format!(
            r#"<img alt="{}" width="{width_px}" style="image-rendering:pixelated" src="data:image/png;base64,{}"/>"#,
            escape(alt),
            base64(png)
        )
    }

    /// A table from a header row and rows of cells.
    pub fn table(header: &[&str], rows: &[Vec<String>]) -> String {
        let mut t = String::from("<table><tr>");
        for h in header {
            let _ = write!(t, "<th>{}</th>", escape(h));
        }
        t.push_str("</tr>");
        for r in rows {
            t.push_str("<tr>");
            for c in r {
                let _ = write!(t, "<td>{}</td>", escape(c));
            }
            t.push_str("</tr>");
        }
        t.push_str("</table>");
        t
    }

    /// The whole page.
    pub fn finish(&self, title: &str) -> String {
        format!(
            "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>{t}</title><style>\
             body{{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}}\
             section{{margin-bottom:2.5em}} figure{{display:inline-block;margin:0.5em}}\
             table{{border-collapse:collapse}} td,th{{border:1px solid #bbb;padding:2px 8px;text-align:right}}\
             </style></head><body><h1>{t}</h1>{}<p style=\"color:#777\">Map data © OpenStreetMap contributors where real maps are used (ODbL).</p></body></html>",
            self.sections,
            t = escape(title)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_and_adler_match_known_values() {
        assert_eq!(crc32(b"123456789"), 0xcbf4_3926);
        assert_eq!(adler32(b"Wikipedia"), 0x11e6_0398);
    }

    #[test]
    fn base64_matches_rfc4648_vectors() {
        for (i, o) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(i.as_bytes()), o);
        }
    }

    #[test]
    fn png_has_signature_and_chunks() {
        let png = encode_png_rgb(2, 2, &[255; 12]);
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
        assert_eq!(&png[12..16], b"IHDR");
        assert_eq!(&png[png.len() - 8..png.len() - 4], b"IEND");
    }
}
