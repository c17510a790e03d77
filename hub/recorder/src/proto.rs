//! A minimal protobuf *writer*: just the wire format the Foxglove channels need (varints,
//! doubles, strings and nested messages), appending to a reused buffer.
//!
//! Hand-written because the recorder only ever writes a handful of fixed message shapes; a
//! protobuf code generator (prost and its derive macro) would cost more build time than this
//! whole crate. The schemas themselves are Foxglove's published descriptors (see
//! [`crate::foxglove`]), so a reader decodes these bytes with generated classes of its own.

/// Wire type of varint fields (int32, uint32, int64, bool, enum).
const VARINT: u32 = 0;
/// Wire type of 64-bit fields (double).
const FIXED64: u32 = 1;
/// Wire type of length-delimited fields (string, bytes, messages).
const LEN: u32 = 2;

/// Appends protobuf fields to a buffer.
#[derive(Debug)]
pub(crate) struct Pb<'a> {
    pub(crate) buf: &'a mut Vec<u8>,
}

impl<'a> Pb<'a> {
    /// Writes into `buf`, after what it already holds.
    pub(crate) fn new(buf: &'a mut Vec<u8>) -> Self {
        Self { buf }
    }

    fn varint(&mut self, mut v: u64) {
        while v >= 0x80 {
            self.buf.push((v as u8) | 0x80);
            v >>= 7;
        }
        self.buf.push(v as u8);
    }

    fn key(&mut self, field: u32, wire: u32) {
        self.varint(u64::from((field << 3) | wire));
    }

    /// A double field. Zero is proto3's default and is left out (a reader sees the same value).
    pub(crate) fn double(&mut self, field: u32, v: f64) {
        if v.to_bits() != 0 {
            self.key(field, FIXED64);
            self.buf.extend_from_slice(&v.to_le_bytes());
        }
    }

    /// A varint-encoded unsigned field (also bool and enum); zero is left out.
    pub(crate) fn uint(&mut self, field: u32, v: u64) {
        if v != 0 {
            self.key(field, VARINT);
            self.varint(v);
        }
    }

    /// A bool field.
    pub(crate) fn bool(&mut self, field: u32, v: bool) {
        self.uint(field, u64::from(v));
    }

    /// A string field; empty is left out.
    pub(crate) fn string(&mut self, field: u32, s: &str) {
        if !s.is_empty() {
            self.key(field, LEN);
            self.varint(s.len() as u64);
            self.buf.extend_from_slice(s.as_bytes());
        }
    }

    /// A nested message field, written by `body`. Repeated message fields are this, once per
    /// item.
    pub(crate) fn message(&mut self, field: u32, body: impl FnOnce(&mut Pb)) {
        self.key(field, LEN);
        let start = self.buf.len();
        body(self);
        let len = self.buf.len() - start;
        // The length goes before the body, and its size is only known now: encode it, then
        // move the body up by that many bytes (a memmove of one small message).
        let mut tmp = [0u8; 10];
        let mut n = 0;
        let mut v = len as u64;
        loop {
            let byte = (v as u8) & 0x7f;
            v >>= 7;
            tmp[n] = if v == 0 { byte } else { byte | 0x80 };
            n += 1;
            if v == 0 {
                break;
            }
        }
        self.buf.extend_from_slice(&tmp[..n]);
        self.buf.copy_within(start..start + len, start + n);
        self.buf[start..start + n].copy_from_slice(&tmp[..n]);
    }
}

/// One field read by [`Fields`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Value<'a> {
    /// A varint.
    Varint(u64),
    /// Eight bytes (a double's bits).
    Fixed64(u64),
    /// Length-delimited bytes (string, bytes, a nested message).
    Bytes(&'a [u8]),
    /// Four bytes.
    Fixed32(u32),
}

/// Iterates over the fields of one protobuf message; `Some(Err(offset))` names where the bytes
/// stop making sense, and iteration ends there.
#[derive(Debug)]
pub(crate) struct Fields<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Fields<'a> {
    pub(crate) fn new(buf: &'a [u8]) -> Self {
        Self { buf, pos: 0 }
    }

    fn varint(&mut self) -> Option<u64> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let b = *self.buf.get(self.pos)?;
            self.pos += 1;
            v |= u64::from(b & 0x7f) << shift;
            if b & 0x80 == 0 {
                return Some(v);
            }
        }
        None
    }

    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let s = self.buf.get(self.pos..self.pos.checked_add(n)?)?;
        self.pos += n;
        Some(s)
    }

    fn field(&mut self) -> Option<(u32, Value<'a>)> {
        let key = self.varint()?;
        let field = u32::try_from(key >> 3).ok()?;
        let value = match key & 7 {
            0 => Value::Varint(self.varint()?),
            1 => Value::Fixed64(u64::from_le_bytes(self.take(8)?.try_into().ok()?)),
            2 => {
                let n = usize::try_from(self.varint()?).ok()?;
                Value::Bytes(self.take(n)?)
            }
            5 => Value::Fixed32(u32::from_le_bytes(self.take(4)?.try_into().ok()?)),
            _ => return None,
        };
        Some((field, value))
    }
}

impl<'a> Iterator for Fields<'a> {
    type Item = Result<(u32, Value<'a>), usize>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.pos >= self.buf.len() {
            return None;
        }
        let start = self.pos;
        match self.field() {
            Some(f) => Some(Ok(f)),
            None => {
                self.pos = self.buf.len();
                Some(Err(start))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nested_messages_carry_their_length_before_their_body() {
        let mut buf = Vec::new();
        let mut pb = Pb::new(&mut buf);
        pb.message(2, |m| {
            m.string(3, "ab");
            m.double(1, 0.0);
        });
        // key(2, LEN) = 0x12, length 4, key(3, LEN) = 0x1a, length 2, "ab".
        assert_eq!(buf, [0x12, 4, 0x1a, 2, b'a', b'b']);
    }

    #[test]
    fn fields_read_back_what_the_writer_wrote() {
        let mut buf = Vec::new();
        let mut pb = Pb::new(&mut buf);
        pb.double(1, -2.5);
        pb.message(4, |m| m.string(2, "chair"));
        pb.uint(7, 300);
        let fields: Vec<_> = Fields::new(&buf).collect();
        assert_eq!(fields[0], Ok((1, Value::Fixed64((-2.5f64).to_bits()))));
        let Ok((4, Value::Bytes(inner))) = fields[1] else { panic!("{:?}", fields[1]) };
        assert_eq!(Fields::new(inner).collect::<Vec<_>>(), [Ok((2, Value::Bytes(b"chair")))]);
        assert_eq!(fields[2], Ok((7, Value::Varint(300))));
        assert_eq!(Fields::new(&[0x0a, 5, 1]).collect::<Vec<_>>(), [Err(0)]);
    }

    #[test]
    fn long_bodies_get_multi_byte_lengths() {
        let mut buf = Vec::new();
        let text = "x".repeat(200);
        Pb::new(&mut buf).message(1, |m| m.string(1, &text));
        // Body = key + varint(200) (2 bytes) + 200 = 203 = 0xcb 0x01.
        assert_eq!(&buf[..3], &[0x0a, 0xcb, 0x01]);
        assert_eq!(buf.len(), 3 + 203);
        assert_eq!(&buf[3..6], &[0x0a, 0xc8, 0x01]);
    }
}
