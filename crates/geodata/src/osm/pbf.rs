//! `.osm.pbf` reader: blobs are read in file order, then decoded in parallel (rayon), one
//! partial element table per blob, concatenated in blob order.

use super::{is_kept_key, OsmError, RawData, RawNode, RawRelation, RawWay};
use osmpbf::{BlobDecode, BlobReader, Element, RelMemberType};
use rayon::prelude::*;
use std::path::Path;

fn pbf_error(path: &Path, blob_index: usize, byte_offset: u64, err: &osmpbf::Error) -> OsmError {
    OsmError::Pbf {
        path: path.to_path_buf(),
        blob_index,
        byte_offset,
        message: err.to_string(),
    }
}

/// Kept tags from raw string-table indices.
fn kept_tags(raw: impl Iterator<Item = (u32, u32)>, table: &[Vec<u8>]) -> Vec<(String, String)> {
    let mut tags = Vec::new();
    for (k, v) in raw {
        let (Some(key), Some(value)) = (table.get(k as usize), table.get(v as usize)) else {
            continue;
        };
        if is_kept_key(key) {
            tags.push((
                String::from_utf8_lossy(key).into_owned(),
                String::from_utf8_lossy(value).into_owned(),
            ));
        }
    }
    tags
}

fn decode_blob(
    blob: &osmpbf::Blob,
    path: &Path,
    index: usize,
    offset: u64,
) -> Result<RawData, OsmError> {
    let mut part = RawData::default();
    match blob
        .decode()
        .map_err(|e| pbf_error(path, index, offset, &e))?
    {
        BlobDecode::OsmHeader(header) => {
            if let Some(b) = header.bbox() {
                part.bounds = Some([
                    b.left.min(b.right),
                    b.top.min(b.bottom),
                    b.left.max(b.right),
                    b.top.max(b.bottom),
                ]);
            }
        }
        BlobDecode::OsmData(block) => {
            let mut role_error = None;
            block.for_each_element(|element| match element {
                Element::DenseNode(n) => part.nodes.push(RawNode {
                    id: n.id(),
                    lat: n.lat(),
                    lon: n.lon(),
                }),
                Element::Node(n) => part.nodes.push(RawNode {
                    id: n.id(),
                    lat: n.lat(),
                    lon: n.lon(),
                }),
                Element::Way(w) => part.ways.push(RawWay {
                    id: w.id(),
                    refs: w.refs().collect(),
                    tags: kept_tags(w.raw_tags(), w.raw_stringtable()),
                }),
                Element::Relation(r) => {
                    let mut way_members = Vec::new();
                    for m in r.members() {
                        if m.member_type == RelMemberType::Way {
                            match m.role() {
                                Ok(role) => way_members.push((m.member_id, role.to_string())),
                                Err(e) => role_error = Some(e),
                            }
                        }
                    }
                    part.relations.push(RawRelation {
                        id: r.id(),
                        way_members,
                        tags: kept_tags(r.raw_tags(), r.raw_stringtable()),
                    });
                }
            });
            if let Some(e) = role_error {
                return Err(pbf_error(path, index, offset, &e));
            }
        }
        BlobDecode::Unknown(_) => {}
    }
    Ok(part)
}

/// A reader that counts the bytes handed out, so errors can name the offset of the failing blob.
struct CountingReader<R> {
    inner: R,
    consumed: std::sync::Arc<std::sync::atomic::AtomicU64>,
}

impl<R: std::io::Read> std::io::Read for CountingReader<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.consumed
            .fetch_add(n as u64, std::sync::atomic::Ordering::Relaxed);
        Ok(n)
    }
}

/// Reads a PBF file into raw element tables. Errors name the blob index and the byte offset
/// where that blob starts.
pub(crate) fn read_pbf(path: &Path) -> Result<RawData, OsmError> {
    let file = std::fs::File::open(path).map_err(|source| OsmError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let consumed = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
    let counting = CountingReader {
        inner: std::io::BufReader::with_capacity(1 << 16, file),
        consumed: consumed.clone(),
    };
    let mut reader = BlobReader::new(counting);
    let mut blobs = Vec::new();
    loop {
        let offset = consumed.load(std::sync::atomic::Ordering::Relaxed);
        let index = blobs.len();
        match reader.next() {
            None => break,
            Some(Ok(blob)) => blobs.push((index, offset, blob)),
            Some(Err(e)) => return Err(pbf_error(path, index, offset, &e)),
        }
    }
    if blobs.is_empty() {
        return Err(OsmError::Pbf {
            path: path.to_path_buf(),
            blob_index: 0,
            byte_offset: 0,
            message: "file holds no blobs".into(),
        });
    }
    let parts: Vec<RawData> = blobs
        .par_iter()
        .map(|(index, offset, blob)| decode_blob(blob, path, *index, *offset))
        .collect::<Result<_, _>>()?;
    let mut raw = RawData {
        nodes: Vec::with_capacity(parts.iter().map(|p| p.nodes.len()).sum()),
        ways: Vec::with_capacity(parts.iter().map(|p| p.ways.len()).sum()),
        ..RawData::default()
    };
    for part in parts {
        raw.bounds = raw.bounds.or(part.bounds);
        raw.nodes.extend(part.nodes);
        raw.ways.extend(part.ways);
        raw.relations.extend(part.relations);
    }
    Ok(raw)
}
