//! Frames: a message with its version, type, sequence number and CRC, COBS-encoded between
//! two 0x00 delimiters; and the streaming [`Decoder`] that finds them in a byte stream.

use core::fmt;

use crate::cobs;
use crate::crc::crc16_ccitt_false;
use crate::message::{MAX_PAYLOAD_LEN, Message, MessageType};

/// The protocol version this crate speaks; frames of any other version are refused.
pub const VERSION: u8 = 1;

/// Bytes before the payload: version, type, sequence number.
pub const HEADER_LEN: usize = 3;

/// Bytes of the CRC after the payload.
pub const CRC_LEN: usize = 2;

/// The longest frame before COBS: header, the largest payload, CRC.
pub const MAX_FRAME_LEN: usize = HEADER_LEN + MAX_PAYLOAD_LEN + CRC_LEN;

/// The most bytes COBS makes of the longest frame (what a receiver buffers between delimiters).
pub const MAX_COBS_LEN: usize = cobs::max_encoded_len(MAX_FRAME_LEN);

/// The most bytes [`encode`] writes: the COBS bytes and a 0x00 delimiter on each side.
pub const MAX_ENCODED_LEN: usize = MAX_COBS_LEN + 2;

/// A decoded frame: the sender's sequence number and the message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame {
    /// The sender's sequence number (one counter per direction, +1 per frame, wrapping).
    pub seq: u8,
    /// The message.
    pub message: Message,
}

/// Why [`encode`] wrote nothing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameEncodeError {
    /// The output buffer is shorter than the encoded frame; [`MAX_ENCODED_LEN`] always fits.
    BufferTooSmall {
        /// Bytes the frame needs.
        needed: usize,
        /// Bytes the buffer has.
        available: usize,
    },
    /// A field holds a value the protocol does not allow (a motor power beyond ±1000, a
    /// sensor id above 7 or repeated, more than 8 sensors of a kind); the receiver would
    /// refuse the frame, so it is not sent.
    InvalidField {
        /// Which field, in words.
        field: &'static str,
    },
}

impl fmt::Display for FrameEncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FrameEncodeError::BufferTooSmall { needed, available } => {
                write!(f, "frame needs {needed} bytes, buffer has {available}")
            }
            FrameEncodeError::InvalidField { field } => write!(f, "invalid field: {field}"),
        }
    }
}

impl core::error::Error for FrameEncodeError {}

/// Why a delimited chunk of bytes is not a frame. Each is counted in [`DecoderStats`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameDecodeError {
    /// More than [`MAX_COBS_LEN`] bytes came without a 0x00: the rest up to the next 0x00 is
    /// skipped.
    Oversize,
    /// The bytes are not valid COBS (a code byte points past the delimiter).
    Cobs,
    /// The frame is shorter than a header and a CRC.
    TooShort {
        /// Its length after COBS decoding.
        len: usize,
    },
    /// The CRC does not match the frame's bytes.
    Crc {
        /// The CRC the frame carries.
        received: u16,
        /// The CRC of the bytes received.
        computed: u16,
    },
    /// The frame is of another protocol version.
    BadVersion {
        /// The version byte.
        version: u8,
    },
    /// The type byte names no message.
    UnknownType {
        /// The type byte.
        code: u8,
    },
    /// The payload's length is wrong for its type.
    BadLength {
        /// The message type.
        message_type: MessageType,
        /// The payload's length.
        len: usize,
    },
    /// A field holds a value the protocol does not allow.
    InvalidField {
        /// The message type.
        message_type: MessageType,
        /// Which field, in words.
        field: &'static str,
    },
}

impl fmt::Display for FrameDecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FrameDecodeError::Oversize => write!(f, "more than {MAX_COBS_LEN} bytes without a delimiter"),
            FrameDecodeError::Cobs => write!(f, "malformed COBS encoding"),
            FrameDecodeError::TooShort { len } => write!(f, "frame of {len} bytes is too short"),
            FrameDecodeError::Crc { received, computed } => {
                write!(f, "CRC mismatch: frame says {received:#06x}, bytes give {computed:#06x}")
            }
            FrameDecodeError::BadVersion { version } => {
                write!(f, "protocol version {version}, expected {VERSION}")
            }
            FrameDecodeError::UnknownType { code } => write!(f, "unknown message type {code:#04x}"),
            FrameDecodeError::BadLength { message_type, len } => {
                write!(f, "{message_type:?} payload of {len} bytes has the wrong length")
            }
            FrameDecodeError::InvalidField { message_type, field } => {
                write!(f, "{message_type:?} has an invalid field: {field}")
            }
        }
    }
}

impl core::error::Error for FrameDecodeError {}

/// Encodes `message` with sequence number `seq` into `out`: `0x00`, the COBS bytes of
/// version, type, seq, payload and CRC, `0x00`. Returns the bytes written (at most
/// [`MAX_ENCODED_LEN`]); writes nothing on error.
///
/// The leading 0x00 ends whatever a receiver holds from an interrupted frame, so a frame
/// cut off mid-way never swallows the next good one.
pub fn encode(message: &Message, seq: u8, out: &mut [u8]) -> Result<usize, FrameEncodeError> {
    message.check().map_err(|field| FrameEncodeError::InvalidField { field })?;
    let mut raw = [0u8; MAX_FRAME_LEN];
    raw[0] = VERSION;
    raw[1] = message.message_type().code();
    raw[2] = seq;
    let mut payload = [0u8; MAX_PAYLOAD_LEN];
    let n = message.write_payload(&mut payload);
    raw[HEADER_LEN..HEADER_LEN + n].copy_from_slice(&payload[..n]);
    encode_raw(&raw[..HEADER_LEN + n], out)
}

/// Frames `body` — version, type, seq and payload, taken as given — as it goes on the wire:
/// `0x00`, the COBS bytes of `body` and its CRC, `0x00`. Returns the bytes written; writes
/// nothing on error. [`encode`] uses it for every message; a test bench uses it for frames a
/// receiver must refuse (an unknown type, a payload of the wrong length), which [`encode`]
/// cannot make. `body` is at most `MAX_FRAME_LEN - CRC_LEN` bytes.
pub fn encode_raw(body: &[u8], out: &mut [u8]) -> Result<usize, FrameEncodeError> {
    let mut raw = [0u8; MAX_FRAME_LEN];
    let crc_at = body.len();
    let Some(head) = raw.get_mut(..crc_at + CRC_LEN) else {
        return Err(FrameEncodeError::BufferTooSmall { needed: crc_at + CRC_LEN, available: MAX_FRAME_LEN });
    };
    head[..crc_at].copy_from_slice(body);
    let crc = crc16_ccitt_false(body);
    head[crc_at..].copy_from_slice(&crc.to_le_bytes());
    let mut stuffed = [0u8; MAX_COBS_LEN];
    let Some(m) = cobs::encode(head, &mut stuffed) else {
        // Unreachable: MAX_COBS_LEN is COBS's bound for the longest frame.
        return Err(FrameEncodeError::BufferTooSmall { needed: MAX_ENCODED_LEN, available: MAX_COBS_LEN });
    };
    let needed = m + 2;
    let Some(dst) = out.get_mut(..needed) else {
        return Err(FrameEncodeError::BufferTooSmall { needed, available: out.len() });
    };
    dst[0] = 0;
    dst[1..=m].copy_from_slice(&stuffed[..m]);
    dst[m + 1] = 0;
    Ok(needed)
}

/// Decodes one frame from its wire bytes: the COBS bytes, with or without the 0x00 delimiters
/// around them (exactly what [`encode`] wrote). For a byte stream use a [`Decoder`].
pub fn decode(wire: &[u8]) -> Result<Frame, FrameDecodeError> {
    let wire = wire.strip_prefix(&[0]).unwrap_or(wire);
    let wire = wire.strip_suffix(&[0]).unwrap_or(wire);
    let mut buf = [0u8; MAX_COBS_LEN];
    let dst = buf.get_mut(..wire.len()).ok_or(FrameDecodeError::Oversize)?;
    dst.copy_from_slice(wire);
    decode_in_place(dst)
}

/// Decodes the COBS bytes of one frame (no delimiters) in place.
fn decode_in_place(buf: &mut [u8]) -> Result<Frame, FrameDecodeError> {
    let n = cobs::decode_in_place(buf).ok_or(FrameDecodeError::Cobs)?;
    let frame = &buf[..n];
    if n < HEADER_LEN + CRC_LEN {
        return Err(FrameDecodeError::TooShort { len: n });
    }
    let (body, crc) = frame.split_at(n - CRC_LEN);
    let received = u16::from_le_bytes([crc[0], crc[1]]);
    let computed = crc16_ccitt_false(body);
    if received != computed {
        return Err(FrameDecodeError::Crc { received, computed });
    }
    // The CRC is checked first: a version or type byte means nothing in a corrupted frame.
    if body[0] != VERSION {
        return Err(FrameDecodeError::BadVersion { version: body[0] });
    }
    let message_type = MessageType::from_code(body[1]).ok_or(FrameDecodeError::UnknownType { code: body[1] })?;
    let payload = &body[HEADER_LEN..];
    let message = Message::read_payload(message_type, payload).map_err(|why| match why {
        None => FrameDecodeError::BadLength { message_type, len: payload.len() },
        Some(field) => FrameDecodeError::InvalidField { message_type, field },
    })?;
    Ok(Frame { seq: body[2], message })
}

/// What a [`Decoder`] has seen: good frames, each kind of refused chunk, and frames the
/// sequence numbers say went missing. Counters saturate rather than wrap.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DecoderStats {
    /// Frames decoded.
    pub frames: u32,
    /// Chunks longer than any frame ([`FrameDecodeError::Oversize`]).
    pub oversize: u32,
    /// Chunks that are not COBS or are too short to be a frame.
    pub malformed: u32,
    /// Frames whose CRC did not match.
    pub crc_errors: u32,
    /// Frames of another protocol version.
    pub bad_version: u32,
    /// Frames of an unknown message type.
    pub unknown_type: u32,
    /// Frames whose payload length is wrong for their type.
    pub bad_length: u32,
    /// Frames with a field value the protocol does not allow.
    pub invalid_field: u32,
    /// Frames the sender numbered but that never arrived whole (gaps in the sequence numbers
    /// between good frames; a jump of 128 or more is taken as the sender restarting).
    pub missed: u32,
}

impl DecoderStats {
    /// Every refused chunk, whatever the reason.
    pub fn errors(&self) -> u32 {
        [
            self.oversize,
            self.malformed,
            self.crc_errors,
            self.bad_version,
            self.unknown_type,
            self.bad_length,
            self.invalid_field,
        ]
        .into_iter()
        .fold(0u32, u32::saturating_add)
    }

    fn count(&mut self, e: &FrameDecodeError) {
        let c = match e {
            FrameDecodeError::Oversize => &mut self.oversize,
            FrameDecodeError::Cobs | FrameDecodeError::TooShort { .. } => &mut self.malformed,
            FrameDecodeError::Crc { .. } => &mut self.crc_errors,
            FrameDecodeError::BadVersion { .. } => &mut self.bad_version,
            FrameDecodeError::UnknownType { .. } => &mut self.unknown_type,
            FrameDecodeError::BadLength { .. } => &mut self.bad_length,
            FrameDecodeError::InvalidField { .. } => &mut self.invalid_field,
        };
        *c = c.saturating_add(1);
    }
}

/// Finds frames in a byte stream, one byte at a time, in a fixed buffer of [`MAX_COBS_LEN`]
/// bytes: no allocation, and no input makes it panic. After any garbage it is in step again
/// at the next 0x00.
///
/// ```
/// use serial_protocol::{encode, Decoder, Message, MotorPowers, MAX_ENCODED_LEN};
///
/// let mut wire = [0u8; MAX_ENCODED_LEN];
/// let m = Message::MotorPowers(MotorPowers { left_permille: 250, right_permille: -250 });
/// let n = encode(&m, 7, &mut wire).expect("fits");
/// let mut decoder = Decoder::new();
/// let mut got = None;
/// decoder.feed(&wire[..n], |frame| got = Some(frame));
/// assert_eq!(got.expect("a frame").expect("valid").message, m);
/// assert_eq!(decoder.stats().frames, 1);
/// ```
#[derive(Debug, Clone)]
pub struct Decoder {
    buf: [u8; MAX_COBS_LEN],
    len: usize,
    /// Skipping to the next 0x00 after an oversize chunk (already reported).
    skipping: bool,
    last_seq: Option<u8>,
    stats: DecoderStats,
}

impl Default for Decoder {
    fn default() -> Decoder {
        Decoder::new()
    }
}

impl Decoder {
    /// A decoder that has seen nothing.
    pub const fn new() -> Decoder {
        Decoder { buf: [0; MAX_COBS_LEN], len: 0, skipping: false, last_seq: None, stats: DecoderStats::ZERO }
    }

    /// Takes one byte; at a delimiter that ends a non-empty chunk, gives the frame or why the
    /// chunk is not one. An over-long chunk is reported once, when it outgrows the buffer.
    pub fn push(&mut self, byte: u8) -> Option<Result<Frame, FrameDecodeError>> {
        if byte != 0 {
            if self.skipping {
                return None;
            }
            let Some(slot) = self.buf.get_mut(self.len) else {
                self.skipping = true;
                self.len = 0;
                self.stats.count(&FrameDecodeError::Oversize);
                return Some(Err(FrameDecodeError::Oversize));
            };
            *slot = byte;
            self.len += 1;
            return None;
        }
        let len = core::mem::take(&mut self.len);
        if core::mem::take(&mut self.skipping) || len == 0 {
            // Back-to-back delimiters, or the end of a chunk already reported.
            return None;
        }
        let result = decode_in_place(&mut self.buf[..len]);
        match &result {
            Ok(frame) => {
                self.stats.frames = self.stats.frames.saturating_add(1);
                if let Some(last) = self.last_seq {
                    let gap = frame.seq.wrapping_sub(last).wrapping_sub(1);
                    if gap < 128 {
                        self.stats.missed = self.stats.missed.saturating_add(u32::from(gap));
                    }
                }
                self.last_seq = Some(frame.seq);
            }
            Err(e) => self.stats.count(e),
        }
        Some(result)
    }

    /// Takes a run of bytes (say, one read from the port), calling `on_frame` for each frame
    /// or refused chunk they complete, in order.
    pub fn feed(&mut self, bytes: &[u8], mut on_frame: impl FnMut(Result<Frame, FrameDecodeError>)) {
        for &b in bytes {
            if let Some(r) = self.push(b) {
                on_frame(r);
            }
        }
    }

    /// What this decoder has seen so far.
    pub fn stats(&self) -> &DecoderStats {
        &self.stats
    }

    /// Drops a partly received frame and forgets the last sequence number (for a port that was
    /// closed and opened again); the counters stay.
    pub fn reset(&mut self) {
        self.len = 0;
        self.skipping = false;
        self.last_seq = None;
    }
}

impl DecoderStats {
    const ZERO: DecoderStats = DecoderStats {
        frames: 0,
        oversize: 0,
        malformed: 0,
        crc_errors: 0,
        bad_version: 0,
        unknown_type: 0,
        bad_length: 0,
        invalid_field: 0,
        missed: 0,
    };
}
