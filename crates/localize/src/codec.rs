//! The `.uloc` index file's body codec: scalars and byte arrays written in order and read
//! back with every read checked against the bytes left and checksummed. A leaf module: the
//! prepared map's parts ([`crate::chamfer`], [`crate::feasible`]) encode themselves with it,
//! and [`crate::index`] writes and reads the whole file.

use crate::{LocalizeError, Result};
use std::io::{Read, Write};
use std::path::Path;

/// An error in the index file `path`.
pub(crate) fn index_err(path: &Path, message: String) -> LocalizeError {
    LocalizeError::Index {
        path: path.to_path_buf(),
        message,
    }
}

/// An index body being written: scalars and byte arrays in order.
#[derive(Default)]
pub(crate) struct Enc<'a> {
    small: Vec<u8>,
    /// (position in `small` before which the array comes, the array).
    parts: Vec<(usize, &'a [u8])>,
}

impl<'a> Enc<'a> {
    pub(crate) fn u8(&mut self, v: u8) {
        self.small.push(v);
    }
    pub(crate) fn u32(&mut self, v: u32) {
        self.small.extend_from_slice(&v.to_le_bytes());
    }
    pub(crate) fn u64(&mut self, v: u64) {
        self.small.extend_from_slice(&v.to_le_bytes());
    }
    pub(crate) fn i64(&mut self, v: i64) {
        self.small.extend_from_slice(&v.to_le_bytes());
    }
    pub(crate) fn f64(&mut self, v: f64) {
        self.small.extend_from_slice(&v.to_le_bytes());
    }
    pub(crate) fn str(&mut self, s: &str) {
        self.u64(s.len() as u64);
        self.small.extend_from_slice(s.as_bytes());
    }
    /// A length-prefixed byte array (borrowed until the body is written).
    pub(crate) fn bytes(&mut self, v: &'a [u8]) {
        self.u64(v.len() as u64);
        self.parts.push((self.small.len(), v));
    }
    pub(crate) fn len(&self) -> usize {
        self.small.len() + self.parts.iter().map(|(_, p)| p.len()).sum::<usize>()
    }
    pub(crate) fn pieces(&self) -> impl Iterator<Item = &[u8]> {
        let mut at = 0;
        let mut out = Vec::new();
        for (pos, part) in &self.parts {
            out.push(&self.small[at..*pos]);
            out.push(*part);
            at = *pos;
        }
        out.push(&self.small[at..]);
        out.into_iter()
    }
    pub(crate) fn crc(&self) -> u32 {
        let mut h = crc32fast::Hasher::new();
        for p in self.pieces() {
            h.update(p);
        }
        h.finalize()
    }
    pub(crate) fn write_to(&self, w: &mut impl Write) -> std::io::Result<()> {
        for p in self.pieces() {
            w.write_all(p)?;
        }
        Ok(())
    }
}

/// An index body being read: every read checked against the bytes left, checksummed.
pub(crate) struct Dec<'p, R: Read> {
    pub(crate) r: R,
    pub(crate) path: &'p Path,
    pub(crate) pos: u64,
    pub(crate) end: u64,
    pub(crate) crc: crc32fast::Hasher,
}

impl<R: Read> Dec<'_, R> {
    pub(crate) fn bad(&self, message: String) -> LocalizeError {
        index_err(self.path, format!("byte {}: {message}", self.pos))
    }
    pub(crate) fn fill(&mut self, buf: &mut [u8], what: &str) -> Result<()> {
        if (buf.len() as u64) > self.end - self.pos {
            return Err(self.bad(format!(
                "{what}: {} bytes needed, {} left: truncated or corrupt",
                buf.len(),
                self.end - self.pos
            )));
        }
        self.r
            .read_exact(buf)
            .map_err(|e| self.bad(format!("{what}: {e}")))?;
        self.crc.update(buf);
        self.pos += buf.len() as u64;
        Ok(())
    }
    pub(crate) fn arr<const N: usize>(&mut self, what: &str) -> Result<[u8; N]> {
        let mut b = [0u8; N];
        self.fill(&mut b, what)?;
        Ok(b)
    }
    pub(crate) fn u8(&mut self, what: &str) -> Result<u8> {
        Ok(self.arr::<1>(what)?[0])
    }
    pub(crate) fn u32(&mut self, what: &str) -> Result<u32> {
        Ok(u32::from_le_bytes(self.arr(what)?))
    }
    pub(crate) fn u64(&mut self, what: &str) -> Result<u64> {
        Ok(u64::from_le_bytes(self.arr(what)?))
    }
    pub(crate) fn i64(&mut self, what: &str) -> Result<i64> {
        Ok(i64::from_le_bytes(self.arr(what)?))
    }
    /// `N` consecutive i64 values.
    pub(crate) fn i64s<const N: usize>(&mut self, what: &str) -> Result<[i64; N]> {
        let mut out = [0i64; N];
        for v in &mut out {
            *v = self.i64(what)?;
        }
        Ok(out)
    }
    /// `N` consecutive finite f64 values.
    pub(crate) fn f64s<const N: usize>(&mut self, what: &str) -> Result<[f64; N]> {
        let mut out = [0f64; N];
        for v in &mut out {
            *v = self.f64(what)?;
        }
        Ok(out)
    }
    pub(crate) fn f64(&mut self, what: &str) -> Result<f64> {
        let v = f64::from_le_bytes(self.arr(what)?);
        if !v.is_finite() {
            return Err(self.bad(format!("{what} is {v}")));
        }
        Ok(v)
    }
    /// A size that must fit in memory and in the file (at least one byte per unit).
    pub(crate) fn usize(&mut self, what: &str) -> Result<usize> {
        let v = self.u64(what)?;
        if v > self.end - self.pos + (1 << 20) {
            return Err(self.bad(format!("{what} {v} is larger than the file")));
        }
        Ok(v as usize)
    }
    /// A count of items of `unit` bytes each that must fit in the bytes left.
    pub(crate) fn count(&mut self, unit: u64, what: &str) -> Result<usize> {
        let n = self.u64(what)?;
        if n.saturating_mul(unit) > self.end - self.pos {
            return Err(self.bad(format!(
                "{n} {what} of {unit} bytes do not fit in the {} bytes left",
                self.end - self.pos
            )));
        }
        Ok(n as usize)
    }
    /// A length-prefixed byte array of exactly `expected` bytes.
    pub(crate) fn bytes(&mut self, expected: usize, what: &str) -> Result<Vec<u8>> {
        let n = self.count(1, what)?;
        if n != expected {
            return Err(self.bad(format!("{what}: {n} bytes, its geometry needs {expected}")));
        }
        let mut v = vec![0u8; n];
        self.fill(&mut v, what)?;
        Ok(v)
    }
    pub(crate) fn string(&mut self, what: &str) -> Result<String> {
        let n = self.count(1, what)?;
        let mut v = vec![0u8; n];
        self.fill(&mut v, what)?;
        String::from_utf8(v).map_err(|_| self.bad(format!("{what} is not UTF-8")))
    }
}

/// Bytes of a file header: magic (8), version (4), body length (8), body CRC-32 (4).
pub(crate) const HEADER_BYTES: u64 = 24;

/// Checks a file's 24-byte header (`magic`, `version`) and returns a decoder of its body
/// and the stored CRC.
pub(crate) fn open_body<'p, R: Read>(
    mut r: R,
    file_len: u64,
    path: &'p Path,
    magic: &[u8; 8],
    version: u32,
    what: &str,
) -> Result<(Dec<'p, R>, u32)> {
    let mut head = [0u8; HEADER_BYTES as usize];
    if file_len < HEADER_BYTES || r.read_exact(&mut head).is_err() {
        return Err(index_err(
            path,
            format!("{file_len} bytes: too short for {what} (header of {HEADER_BYTES} bytes)"),
        ));
    }
    if &head[..8] != magic {
        return Err(index_err(path, format!("not {what}")));
    }
    let v = u32::from_le_bytes(head[8..12].try_into().unwrap_or_default());
    if v != version {
        return Err(index_err(
            path,
            format!("format version {v}; this build reads version {version}: rebuild it"),
        ));
    }
    let body_len = u64::from_le_bytes(head[12..20].try_into().unwrap_or_default());
    let stored_crc = u32::from_le_bytes(head[20..24].try_into().unwrap_or_default());
    if body_len != file_len - HEADER_BYTES {
        return Err(index_err(
            path,
            format!(
                "the header announces {body_len} bytes of body, the file holds {}: truncated or not {what}",
                file_len - HEADER_BYTES
            ),
        ));
    }
    Ok((
        Dec {
            r,
            path,
            pos: HEADER_BYTES,
            end: file_len,
            crc: crc32fast::Hasher::new(),
        },
        stored_crc,
    ))
}

/// Checks that a decoder consumed its body and that the body's CRC matches.
pub(crate) fn close_body<R: Read>(d: Dec<'_, R>, stored_crc: u32) -> Result<()> {
    if d.pos != d.end {
        return Err(d.bad(format!("{} bytes after the last section", d.end - d.pos)));
    }
    let crc = d.crc.clone().finalize();
    if crc != stored_crc {
        return Err(index_err(
            d.path,
            format!("checksum mismatch (stored {stored_crc:#010x}, computed {crc:#010x}): the file is corrupt; rebuild it"),
        ));
    }
    Ok(())
}

/// Writes a file of `magic`, `version`, the body's length and CRC-32, then the body (atomically).
pub(crate) fn write_file(path: &Path, magic: &[u8; 8], version: u32, body: &Enc<'_>) -> Result<()> {
    let err = |e: std::io::Error| index_err(path, format!("writing: {e}"));
    let mut w = geodata::fsio::AtomicFile::create(path).map_err(err)?;
    w.write_all(magic).map_err(err)?;
    w.write_all(&version.to_le_bytes()).map_err(err)?;
    w.write_all(&(body.len() as u64).to_le_bytes())
        .map_err(err)?;
    w.write_all(&body.crc().to_le_bytes()).map_err(err)?;
    body.write_to(&mut w).map_err(err)?;
    w.commit().map_err(err)
}
