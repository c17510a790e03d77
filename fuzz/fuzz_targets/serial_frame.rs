//! Any bytes on the chair's serial line, fed to the streaming decoder in arbitrary pieces,
//! give frames or counted errors, never a panic, and the decoder's counters add up. Every
//! frame that decodes encodes back to bytes that decode to the same frame.
//!
//! Random bytes almost never carry a valid CRC, so half of the inputs are wrapped first: the
//! bytes become a raw frame (version, type, seq, payload) with a correct CRC and COBS around
//! it. That reaches the payload parsers, and a frame that decodes from such bytes must encode
//! back to exactly those bytes (the wire form is canonical).
#![no_main]
use serial_protocol::{Decoder, FrameDecodeError, MAX_ENCODED_LEN, crc16_ccitt_false, decode, encode};

/// COBS as docs/serial-protocol.md describes it, written here apart from the crate's own so
/// the fuzz target checks the crate against the document rather than against itself.
fn cobs_wrap(raw: &[u8]) -> Vec<u8> {
    let mut out = vec![0u8];
    for block in raw.split(|&b| b == 0) {
        // Blocks longer than 254 data bytes never occur: wrapped inputs are cut to 80 bytes.
        out.push(block.len() as u8 + 1);
        out.extend_from_slice(block);
    }
    out.push(0);
    out
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let Some((&control, rest)) = data.split_first() else { return };
    let wrapped = control & 0x80 != 0;
    let stream = if wrapped {
        let mut raw = rest[..rest.len().min(80)].to_vec();
        let crc = crc16_ccitt_false(&raw);
        raw.extend_from_slice(&crc.to_le_bytes());
        cobs_wrap(&raw)
    } else {
        rest.to_vec()
    };
    // The low bits pick how the stream is cut into reads, as a serial port hands them over.
    let step = usize::from(control & 0x0F) + 1;
    let mut decoder = Decoder::new();
    let (mut ok, mut bad) = (0u32, 0u32);
    for piece in stream.chunks(step) {
        decoder.feed(piece, |result| match result {
            Ok(frame) => {
                ok += 1;
                let mut wire = [0u8; MAX_ENCODED_LEN];
                let n = encode(&frame.message, frame.seq, &mut wire).expect("a decoded frame encodes");
                assert_eq!(decode(&wire[..n]), Ok(frame), "a re-encoded frame decodes the same");
                if wrapped {
                    assert_eq!(&wire[..n], &stream[..], "the wire form is canonical");
                }
            }
            Err(e) => {
                bad += 1;
                if wrapped {
                    assert!(!matches!(e, FrameDecodeError::Crc { .. } | FrameDecodeError::Cobs), "{e}");
                }
            }
        });
    }
    assert_eq!(decoder.stats().frames, ok);
    assert_eq!(decoder.stats().errors(), bad);
    let _ = decode(&stream);
});
