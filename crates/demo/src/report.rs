//! The demo's report: an HTML page of sections with figures (inline SVG, embedded PNG).

use base64::Engine as _;
use std::fmt::Write as _;

/// Escapes text for HTML/SVG.
pub fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Encodes 8-bit RGB pixels (row-major, top row first) as a compressed PNG file.
pub fn encode_png_rgb(width: u32, height: u32, rgb: &[u8]) -> anyhow::Result<Vec<u8>> {
    let mut png = Vec::new();
    let mut encoder = png::Encoder::new(&mut png, width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header()?;
    writer.write_image_data(rgb)?;
    writer.finish()?;
    Ok(png)
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
            base64::engine::general_purpose::STANDARD.encode(png)
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
    fn png_round_trips() {
        let rgb: Vec<u8> = (0..2 * 3 * 3).map(|i| (i * 13) as u8).collect();
        let png = encode_png_rgb(3, 2, &rgb).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
        let mut reader = png::Decoder::new(std::io::Cursor::new(&png))
            .read_info()
            .unwrap();
        let mut back = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut back).unwrap();
        assert_eq!((info.width, info.height), (3, 2));
        assert_eq!(&back[..info.buffer_size()], &rgb[..]);
        assert!(
            encode_png_rgb(3, 3, &rgb).is_err(),
            "a short buffer is an error"
        );
    }
}
