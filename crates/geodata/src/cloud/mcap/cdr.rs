//! A cursor over the CDR bytes of one ROS 2 message (OMG CDR: a 4-byte encapsulation
//! header, then each primitive aligned to its own size counted from after that header).

use crate::cloud::error::MessageProblem;

/// A cursor over CDR bytes; offsets count from the start of the message.
pub(super) struct Cdr<'a> {
    /// The bytes after the 4-byte encapsulation header.
    body: &'a [u8],
    pos: usize,
    big_endian: bool,
}

/// A decoding problem and the byte of the message where it was found.
pub(super) type CdrResult<T> = std::result::Result<T, (u64, MessageProblem)>;

impl<'a> Cdr<'a> {
    /// Reads the encapsulation header of `message`.
    pub(super) fn new(message: &'a [u8]) -> CdrResult<Self> {
        let Some((head, body)) = message.split_first_chunk::<4>() else {
            return Err((
                0,
                MessageProblem::Truncated {
                    field: "the encapsulation header",
                    need: 4,
                    left: message.len() as u64,
                },
            ));
        };
        let id = u16::from_be_bytes([head[0], head[1]]);
        let big_endian = match id {
            0 => true,
            1 => false,
            _ => return Err((0, MessageProblem::Encapsulation { id })),
        };
        Ok(Self {
            body,
            pos: 0,
            big_endian,
        })
    }

    /// Byte offset within the message of the cursor.
    pub(super) fn offset(&self) -> u64 {
        self.pos as u64 + 4
    }

    /// `n` bytes aligned to `align`, advancing past them.
    pub(super) fn take(
        &mut self,
        n: usize,
        align: usize,
        field: &'static str,
    ) -> CdrResult<&'a [u8]> {
        let start = self.pos.next_multiple_of(align);
        let left = self.body.len().saturating_sub(start);
        match self.body.get(start..).and_then(|b| b.get(..n)) {
            Some(bytes) => {
                self.pos = start + n;
                Ok(bytes)
            }
            None => Err((
                self.offset(),
                MessageProblem::Truncated {
                    field,
                    need: n as u64,
                    left: left as u64,
                },
            )),
        }
    }

    pub(super) fn u8(&mut self, field: &'static str) -> CdrResult<u8> {
        Ok(self.take(1, 1, field)?.first().copied().unwrap_or(0))
    }

    pub(super) fn u32(&mut self, field: &'static str) -> CdrResult<u32> {
        let b = self.take(4, 4, field)?;
        let a = [b[0], b[1], b[2], b[3]];
        Ok(if self.big_endian {
            u32::from_be_bytes(a)
        } else {
            u32::from_le_bytes(a)
        })
    }

    /// A CDR string: u32 length including the NUL, the bytes, the NUL.
    pub(super) fn string(&mut self, field: &'static str) -> CdrResult<String> {
        let len = self.u32(field)?;
        let at = self.offset();
        let bytes = self.take(len as usize, 1, field)?;
        let text = match bytes.split_last() {
            Some((0, text)) => std::str::from_utf8(text).ok(),
            // A zero length is not CDR, but some writers emit it for the empty string.
            None => Some(""),
            Some(_) => None,
        };
        text.map(str::to_owned)
            .ok_or((at, MessageProblem::BadString { field }))
    }

    /// A CDR float64 (8-byte aligned).
    pub(super) fn f64(&mut self, field: &'static str) -> CdrResult<f64> {
        let b = self.take(8, 8, field)?;
        let a = [b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]];
        Ok(if self.big_endian {
            f64::from_be_bytes(a)
        } else {
            f64::from_le_bytes(a)
        })
    }

    /// A `builtin_interfaces/Time` (int32 sec, uint32 nanosec) as nanoseconds.
    pub(super) fn time_ns(&mut self, field: &'static str) -> CdrResult<i64> {
        let sec = self.u32(field)? as i32;
        let nanosec = self.u32(field)?;
        Ok(i64::from(sec) * 1_000_000_000 + i64::from(nanosec))
    }
}
