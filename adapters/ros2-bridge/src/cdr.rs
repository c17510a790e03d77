//! CDR as ROS 2 puts it on the wire (XCDR1, little-endian): a 4-byte encapsulation header
//! (`00 01 00 00`), then the fields in declaration order, each primitive aligned to its own
//! size counted from the first byte after the header; a string is a `u32` length that counts
//! its terminating NUL, the bytes and the NUL; a sequence is a `u32` count and its elements.

/// The encapsulation header of little-endian plain CDR (representation id `CDR_LE`, options 0).
pub const HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Writes one message.
#[derive(Debug, Clone)]
pub struct Writer {
    buf: Vec<u8>,
}

impl Default for Writer {
    fn default() -> Self {
        Self::new()
    }
}

impl Writer {
    /// A message with its header written.
    pub fn new() -> Self {
        Self::reusing(Vec::with_capacity(256))
    }

    /// A message written into `buf` (cleared), to keep one allocation across messages.
    pub fn reusing(mut buf: Vec<u8>) -> Self {
        buf.clear();
        buf.extend_from_slice(&HEADER);
        Self { buf }
    }

    fn align(&mut self, n: usize) {
        let off = self.buf.len() - HEADER.len();
        let pad = (n - off % n) % n;
        self.buf.resize(self.buf.len() + pad, 0);
    }

    /// An `uint8` (also `byte`, `char`).
    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    /// An `int8`.
    pub fn i8(&mut self, v: i8) {
        self.buf.push(v as u8);
    }

    /// A `bool`, one byte.
    pub fn bool(&mut self, v: bool) {
        self.buf.push(u8::from(v));
    }

    /// A `uint32`.
    pub fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// An `int32`.
    pub fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A `float32`.
    pub fn f32(&mut self, v: f32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A `float64`.
    pub fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A `string`.
    pub fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    /// A sequence's element count; the caller writes the elements.
    pub fn len(&mut self, n: usize) {
        self.u32(n as u32);
    }

    /// A `float32[]`.
    pub fn f32s(&mut self, v: &[f32]) {
        self.len(v.len());
        for &x in v {
            self.f32(x);
        }
    }

    /// An `int8[]`.
    pub fn i8s(&mut self, v: &[i8]) {
        self.len(v.len());
        self.buf.extend(v.iter().map(|&x| x as u8));
    }

    /// The whole message, header first.
    pub fn finish(self) -> Vec<u8> {
        self.buf
    }
}

/// What was wrong with a message that could not be read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CdrError {
    /// Not little-endian plain CDR.
    #[error("the encapsulation header is {0:02x?}, not little-endian CDR (00 01 00 00)")]
    Header([u8; 4]),
    /// The message ended inside a field.
    #[error("the message ends at byte {len} inside {what}")]
    Short {
        /// The field being read.
        what: &'static str,
        /// The message's length, header included.
        len: usize,
    },
    /// A string that is not NUL-terminated UTF-8.
    #[error("{what} at byte {at} is not a NUL-terminated UTF-8 string")]
    BadString {
        /// The field being read.
        what: &'static str,
        /// Its offset, header included.
        at: usize,
    },
}

/// Reads one message.
#[derive(Debug, Clone)]
pub struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    /// A reader past the header, which must be little-endian CDR.
    pub fn new(buf: &'a [u8]) -> Result<Self, CdrError> {
        let Some(h) = buf.get(..4) else {
            return Err(CdrError::Short { what: "the encapsulation header", len: buf.len() });
        };
        // The options bytes (2..4) carry XCDR padding hints; only the representation matters.
        if h[..2] != HEADER[..2] {
            return Err(CdrError::Header([h[0], h[1], h[2], h[3]]));
        }
        Ok(Self { buf, pos: 4 })
    }

    fn take<const N: usize>(&mut self, what: &'static str) -> Result<[u8; N], CdrError> {
        let off = self.pos - HEADER.len();
        let start = self.pos + (N - off % N) % N;
        let bytes = self.buf.get(start..start + N).ok_or(CdrError::Short { what, len: self.buf.len() })?;
        self.pos = start + N;
        Ok(bytes.try_into().unwrap_or([0; N]))
    }

    /// A `uint8`.
    pub fn u8(&mut self, what: &'static str) -> Result<u8, CdrError> {
        Ok(self.take::<1>(what)?[0])
    }

    /// A `uint32`.
    pub fn u32(&mut self, what: &'static str) -> Result<u32, CdrError> {
        Ok(u32::from_le_bytes(self.take(what)?))
    }

    /// An `int32`.
    pub fn i32(&mut self, what: &'static str) -> Result<i32, CdrError> {
        Ok(i32::from_le_bytes(self.take(what)?))
    }

    /// A `float64`.
    pub fn f64(&mut self, what: &'static str) -> Result<f64, CdrError> {
        Ok(f64::from_le_bytes(self.take(what)?))
    }

    /// A `string`.
    pub fn string(&mut self, what: &'static str) -> Result<&'a str, CdrError> {
        let n = self.u32(what)? as usize;
        let at = self.pos;
        let bytes = self.buf.get(at..at.saturating_add(n)).ok_or(CdrError::Short { what, len: self.buf.len() })?;
        let Some((0, text)) = bytes.split_last() else { return Err(CdrError::BadString { what, at }) };
        let s = std::str::from_utf8(text).map_err(|_| CdrError::BadString { what, at })?;
        self.pos = at + n;
        Ok(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn primitives_align_from_the_end_of_the_header() {
        let mut w = Writer::new();
        w.u8(7);
        w.f64(1.0);
        w.string("ab");
        w.i32(-2);
        let b = w.finish();
        assert_eq!(&b[..4], &HEADER);
        assert_eq!(b[4], 7);
        assert_eq!(&b[5..12], &[0; 7], "the f64 starts 8 bytes after the header");
        assert_eq!(&b[12..20], &1.0f64.to_le_bytes());
        assert_eq!(&b[20..27], &[3, 0, 0, 0, b'a', b'b', 0]);
        assert_eq!(&b[27..28], &[0], "padding to the i32");
        assert_eq!(&b[28..32], &(-2i32).to_le_bytes());
        let mut r = Reader::new(&b).expect("header");
        assert_eq!(r.u8("u8"), Ok(7));
        assert_eq!(r.f64("f64"), Ok(1.0));
        assert_eq!(r.string("s"), Ok("ab"));
        assert_eq!(r.i32("i32"), Ok(-2));
        assert_eq!(r.u32("past the end"), Err(CdrError::Short { what: "past the end", len: 32 }));
    }

    #[test]
    fn bad_input_says_what_is_wrong() {
        assert_eq!(Reader::new(&[0, 0, 0, 0]).map(|_| ()), Err(CdrError::Header([0, 0, 0, 0])));
        assert!(matches!(Reader::new(&[0, 1]), Err(CdrError::Short { .. })));
        // A string whose length runs past the end, and one without its NUL.
        let mut r = Reader::new(&[0, 1, 0, 0, 9, 0, 0, 0, b'a']).expect("header");
        assert!(matches!(r.string("frame_id"), Err(CdrError::Short { what: "frame_id", .. })));
        let mut r = Reader::new(&[0, 1, 0, 0, 1, 0, 0, 0, b'a']).expect("header");
        assert_eq!(r.string("frame_id"), Err(CdrError::BadString { what: "frame_id", at: 8 }));
    }
}
