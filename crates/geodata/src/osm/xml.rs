//! Streaming `.osm` XML reader (quick-xml events; the document is never held as a tree).
//!
//! Linear in the file: one pass over the events, each element's attributes scanned once
//! (quick-xml's own duplicate-attribute check compares every attribute with all earlier
//! ones, quadratic in an element's attribute count, so it is off; the attributes this reader
//! uses are checked for repeats instead), error positions are the parser's byte offset (no
//! line counting). Memory holds the kept elements only: nodes, ways with their node
//! references, relations with their way members, and the tags in [`super::KEPT_KEYS`].

use super::{is_kept_key, OsmError, RawData, RawNode, RawRelation, RawWay};
use quick_xml::events::{BytesStart, Event};
use quick_xml::Reader;
use std::io::BufRead;

/// What a latitude attribute must be.
const LATITUDE: &str = "a latitude in degrees within [-90, 90]";
/// What a longitude attribute must be.
const LONGITUDE: &str = "a longitude in degrees within [-180, 180]";

/// The element whose children are being read.
enum Current {
    None,
    Way(RawWay),
    Relation(RawRelation),
}

struct Ctx<'a> {
    source_name: &'a str,
    offset: u64,
}

impl Ctx<'_> {
    fn bad(
        &self,
        element: &[u8],
        attribute: &str,
        value: &str,
        expected: &'static str,
    ) -> OsmError {
        OsmError::BadAttribute {
            source_name: self.source_name.to_string(),
            byte_offset: self.offset,
            element: String::from_utf8_lossy(element).into_owned(),
            attribute: attribute.to_string(),
            value: value.to_string(),
            expected,
        }
    }

    fn xml(&self, message: String) -> OsmError {
        OsmError::Xml {
            source_name: self.source_name.to_string(),
            byte_offset: self.offset,
            message,
        }
    }

    /// Raw attribute values for the given keys (missing → `None`); a key given twice is an
    /// error. One pass over the element's attributes.
    fn attrs<const N: usize>(
        &self,
        e: &BytesStart<'_>,
        keys: [&[u8]; N],
    ) -> Result<[Option<String>; N], OsmError> {
        let mut out: [Option<String>; N] = std::array::from_fn(|_| None);
        for attr in e.attributes().with_checks(false) {
            let attr = attr.map_err(|err| self.xml(err.to_string()))?;
            if let Some(i) = keys.iter().position(|k| *k == attr.key.as_ref()) {
                let value = attr
                    .unescape_value()
                    .map_err(|err| self.xml(err.to_string()))?;
                if let Some(slot) = out.get_mut(i) {
                    if slot.is_some() {
                        let name = String::from_utf8_lossy(attr.key.as_ref()).into_owned();
                        return Err(self.bad(
                            e.name().as_ref(),
                            &name,
                            &value,
                            "one value, not two",
                        ));
                    }
                    *slot = Some(value.into_owned());
                }
            }
        }
        Ok(out)
    }

    fn number<T: std::str::FromStr>(
        &self,
        element: &[u8],
        name: &str,
        value: Option<&String>,
    ) -> Result<T, OsmError> {
        let text = value.map_or("", String::as_str);
        text.trim()
            .parse::<T>()
            .map_err(|_| self.bad(element, name, text, "a number"))
    }

    /// A coordinate in degrees: a finite number of magnitude at most `limit`.
    fn degrees(
        &self,
        element: &[u8],
        name: &str,
        value: Option<&String>,
        limit: f64,
        expected: &'static str,
    ) -> Result<f64, OsmError> {
        let v: f64 = self.number(element, name, value)?;
        if v.abs() <= limit {
            Ok(v)
        } else {
            Err(self.bad(element, name, value.map_or("", String::as_str), expected))
        }
    }
}

/// Reads OSM XML into raw element tables.
pub(crate) fn read_xml<R: BufRead>(input: R, source_name: &str) -> Result<RawData, OsmError> {
    let mut reader = Reader::from_reader(input);
    let mut buf = Vec::with_capacity(1024);
    let mut raw = RawData::default();
    let mut current = Current::None;
    let mut depth = 0usize;
    let mut saw_osm = false;
    loop {
        let offset = reader.buffer_position();
        let ctx = Ctx {
            source_name,
            offset,
        };
        let event = reader
            .read_event_into(&mut buf)
            .map_err(|err| OsmError::Xml {
                source_name: source_name.to_string(),
                byte_offset: reader.error_position(),
                message: err.to_string(),
            })?;
        let (e, is_empty) = match &event {
            Event::Start(e) => (e, false),
            Event::Empty(e) => (e, true),
            Event::End(e) => {
                depth = depth.saturating_sub(1);
                match (
                    e.name().as_ref(),
                    std::mem::replace(&mut current, Current::None),
                ) {
                    (b"way", Current::Way(w)) => raw.ways.push(w),
                    (b"relation", Current::Relation(r)) => raw.relations.push(r),
                    (_, other) => current = other,
                }
                buf.clear();
                continue;
            }
            Event::Eof => {
                if depth > 0 {
                    return Err(OsmError::XmlTruncated {
                        source_name: source_name.to_string(),
                        byte_offset: reader.buffer_position(),
                        open_elements: depth,
                    });
                }
                break;
            }
            _ => {
                buf.clear();
                continue;
            }
        };
        if !is_empty {
            depth += 1;
        }
        let name = e.name();
        let name = name.as_ref();
        if !saw_osm {
            if name != b"osm" {
                return Err(OsmError::NotOsm {
                    source_name: source_name.to_string(),
                });
            }
            saw_osm = true;
        }
        match name {
            b"node" => {
                let [id, lat, lon] = ctx.attrs(e, [b"id", b"lat", b"lon"])?;
                // Deleted/changes-only nodes without coordinates are not positions.
                if lat.is_some() || lon.is_some() {
                    raw.nodes.push(RawNode {
                        id: ctx.number(name, "id", id.as_ref())?,
                        lat: ctx.degrees(name, "lat", lat.as_ref(), 90.0, LATITUDE)?,
                        lon: ctx.degrees(name, "lon", lon.as_ref(), 180.0, LONGITUDE)?,
                    });
                }
            }
            b"way" => {
                let [id] = ctx.attrs(e, [b"id"])?;
                let way = RawWay {
                    id: ctx.number(name, "id", id.as_ref())?,
                    ..RawWay::default()
                };
                if is_empty {
                    raw.ways.push(way);
                } else {
                    current = Current::Way(way);
                }
            }
            b"relation" => {
                let [id] = ctx.attrs(e, [b"id"])?;
                let rel = RawRelation {
                    id: ctx.number(name, "id", id.as_ref())?,
                    ..RawRelation::default()
                };
                if is_empty {
                    raw.relations.push(rel);
                } else {
                    current = Current::Relation(rel);
                }
            }
            b"nd" => {
                if let Current::Way(w) = &mut current {
                    let [r] = ctx.attrs(e, [b"ref"])?;
                    w.refs.push(ctx.number(name, "ref", r.as_ref())?);
                }
            }
            b"member" => {
                if let Current::Relation(rel) = &mut current {
                    let [kind, r, role] = ctx.attrs(e, [b"type", b"ref", b"role"])?;
                    if kind.as_deref() == Some("way") {
                        rel.way_members.push((
                            ctx.number(name, "ref", r.as_ref())?,
                            role.unwrap_or_default(),
                        ));
                    }
                }
            }
            b"tag" => {
                let tags = match &mut current {
                    Current::Way(w) => Some(&mut w.tags),
                    Current::Relation(r) => Some(&mut r.tags),
                    Current::None => None,
                };
                if let Some(tags) = tags {
                    let [k, v] = ctx.attrs(e, [b"k", b"v"])?;
                    if let (Some(k), Some(v)) = (k, v) {
                        if is_kept_key(k.as_bytes()) {
                            tags.push((k, v));
                        }
                    }
                }
            }
            b"bounds" => {
                let [a, b, c, d] = ctx.attrs(e, [b"minlon", b"minlat", b"maxlon", b"maxlat"])?;
                raw.bounds = Some([
                    ctx.degrees(name, "minlon", a.as_ref(), 180.0, LONGITUDE)?,
                    ctx.degrees(name, "minlat", b.as_ref(), 90.0, LATITUDE)?,
                    ctx.degrees(name, "maxlon", c.as_ref(), 180.0, LONGITUDE)?,
                    ctx.degrees(name, "maxlat", d.as_ref(), 90.0, LATITUDE)?,
                ]);
            }
            _ => {}
        }
        buf.clear();
    }
    if !saw_osm {
        return Err(OsmError::NotOsm {
            source_name: source_name.to_string(),
        });
    }
    Ok(raw)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_elements_tags_and_members() {
        let xml = r#"<?xml version="1.0"?><osm version="0.6"><bounds minlat="1" minlon="2" maxlat="3" maxlon="4"/>
            <node id="1" lat="1.5" lon="2.5"><tag k="amenity" v="x"/></node>
            <way id="2"><nd ref="1"/><nd ref="1"/><tag k="highway" v="path"/><tag k="surface" v="dirt"/></way>
            <relation id="3"><member type="way" ref="2" role="outer"/><member type="node" ref="1" role=""/>
            <tag k="type" v="multipolygon"/></relation></osm>"#;
        let raw = read_xml(xml.as_bytes(), "t").unwrap();
        assert_eq!(raw.bounds, Some([2.0, 1.0, 4.0, 3.0]));
        assert_eq!(raw.nodes.len(), 1);
        assert_eq!(raw.ways[0].refs, vec![1, 1]);
        assert_eq!(
            raw.ways[0].tags,
            vec![("highway".to_string(), "path".to_string())]
        );
        assert_eq!(raw.relations[0].way_members, vec![(2, "outer".to_string())]);
    }

    #[test]
    fn bad_number_names_attribute_and_offset() {
        let err = read_xml(
            r#"<osm><node id="1" lat="abc" lon="2"/></osm>"#.as_bytes(),
            "t",
        )
        .unwrap_err();
        match err {
            OsmError::BadAttribute {
                attribute,
                value,
                byte_offset,
                ..
            } => {
                assert_eq!(attribute, "lat");
                assert_eq!(value, "abc");
                assert_eq!(byte_offset, 5);
            }
            other => panic!("unexpected {other}"),
        }
    }

    #[test]
    fn truncated_and_garbled() {
        assert!(matches!(
            read_xml(r#"<osm><node id="1" lat="1" lon="2"/>"#.as_bytes(), "t"),
            Err(OsmError::XmlTruncated { .. })
        ));
        assert!(matches!(
            read_xml(r#"<osm><way id="1"></node></osm>"#.as_bytes(), "t"),
            Err(OsmError::Xml { .. })
        ));
        assert!(matches!(
            read_xml(r#"<html></html>"#.as_bytes(), "t"),
            Err(OsmError::NotOsm { .. })
        ));
    }

    #[test]
    fn coordinates_must_be_finite_and_in_range() {
        for (node, attribute) in [
            r#"<node id="1" lat="NaN" lon="2"/>"#,
            r#"<node id="1" lat="91" lon="2"/>"#,
            r#"<node id="1" lat="1" lon="inf"/>"#,
            r#"<node id="1" lat="1" lon="-180.5"/>"#,
        ]
        .iter()
        .zip(["lat", "lat", "lon", "lon"])
        {
            let xml = format!("<osm>{node}</osm>");
            match read_xml(xml.as_bytes(), "t") {
                Err(OsmError::BadAttribute {
                    attribute: a,
                    expected,
                    ..
                }) => {
                    assert_eq!(a, attribute);
                    assert!(expected.contains("degrees"), "{expected}");
                }
                other => panic!("{node}: unexpected {other:?}"),
            }
        }
    }

    #[test]
    fn a_used_attribute_given_twice_is_an_error_and_others_are_not_checked() {
        assert!(matches!(
            read_xml(r#"<osm><node id="1" lat="1" lat="2" lon="3"/></osm>"#.as_bytes(), "t"),
            Err(OsmError::BadAttribute { attribute, .. }) if attribute == "lat"
        ));
        // Many unused attributes (and a repeated one) cost one pass, not one per pair.
        let extra: String = (0..20_000).map(|i| format!(" a{i}=\"x\"")).collect();
        let xml = format!(r#"<osm><node id="1" lat="1" lon="3"{extra} a0="y"/></osm>"#);
        assert_eq!(read_xml(xml.as_bytes(), "t").unwrap().nodes.len(), 1);
    }

    #[test]
    fn every_truncation_is_an_error_not_a_panic() {
        let xml = r#"<?xml version="1.0"?><osm version="0.6"><bounds minlat="1" minlon="2" maxlat="3" maxlon="4"/><node id="1" lat="1.5" lon="2.5"/><way id="2"><nd ref="1"/><tag k="building" v="a &amp; b"/></way><relation id="3"><member type="way" ref="2" role="outer"/></relation></osm>"#;
        assert!(read_xml(xml.as_bytes(), "t").is_ok());
        for cut in 0..xml.len() {
            let prefix = &xml.as_bytes()[..cut];
            assert!(read_xml(prefix, "t").is_err(), "prefix of {cut} bytes read");
        }
    }
}
