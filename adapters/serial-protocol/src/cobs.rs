//! Consistent Overhead Byte Stuffing: removes every 0x00 from a frame so that 0x00 can mark
//! frame boundaries on the wire. Each block starts with a code byte `n` (1..=255): `n - 1` data
//! bytes follow, then an implied 0x00 unless `n` is 255 or the block ends the frame.

/// The most bytes COBS can add to `len` input bytes: one code byte, plus one per 254 bytes.
pub(crate) const fn max_encoded_len(len: usize) -> usize {
    len + 1 + len / 254
}

/// Encodes `input` into `out`, returning the encoded length, or `None` when `out` is too small.
pub(crate) fn encode(input: &[u8], out: &mut [u8]) -> Option<usize> {
    let mut code_at = 0;
    let mut code: u8 = 1;
    let mut o = 1;
    for &b in input {
        if b == 0 {
            *out.get_mut(code_at)? = code;
            code_at = o;
            o += 1;
            code = 1;
        } else {
            *out.get_mut(o)? = b;
            o += 1;
            code += 1;
            // A full block of 254 data bytes has no implied zero after it.
            if code == 0xFF {
                *out.get_mut(code_at)? = code;
                code_at = o;
                o += 1;
                code = 1;
            }
        }
    }
    *out.get_mut(code_at)? = code;
    Some(o)
}

/// Decodes the COBS bytes in `buf` in place (the output is never longer than the input),
/// returning the decoded length, or `None` for bytes no encoder produces: a 0x00, or a code
/// byte that points past the end.
pub(crate) fn decode_in_place(buf: &mut [u8]) -> Option<usize> {
    let n = buf.len();
    let mut i = 0;
    let mut o = 0;
    while i < n {
        let code = usize::from(buf[i]);
        if code == 0 {
            return None;
        }
        let start = i + 1;
        let end = i + code;
        if end > n {
            return None;
        }
        if buf[start..end].contains(&0) {
            return None;
        }
        buf.copy_within(start..end, o);
        o += code - 1;
        i = end;
        if code != 0xFF && i < n {
            buf[o] = 0;
            o += 1;
        }
    }
    Some(o)
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec;
    use std::vec::Vec;

    fn enc(input: &[u8]) -> Vec<u8> {
        let mut out = vec![0u8; max_encoded_len(input.len())];
        let n = encode(input, &mut out).expect("buffer sized by max_encoded_len");
        out.truncate(n);
        out
    }

    fn dec(input: &[u8]) -> Option<Vec<u8>> {
        let mut buf = input.to_vec();
        let n = decode_in_place(&mut buf)?;
        buf.truncate(n);
        Some(buf)
    }

    #[test]
    fn the_published_examples_encode_as_published() {
        // The examples of the COBS paper and its common references.
        assert_eq!(enc(&[0x00]), [0x01, 0x01]);
        assert_eq!(enc(&[0x00, 0x00]), [0x01, 0x01, 0x01]);
        assert_eq!(enc(&[0x11, 0x22, 0x00, 0x33]), [0x03, 0x11, 0x22, 0x02, 0x33]);
        assert_eq!(enc(&[0x11, 0x22, 0x33, 0x44]), [0x05, 0x11, 0x22, 0x33, 0x44]);
        assert_eq!(enc(&[0x11, 0x00, 0x00, 0x00]), [0x02, 0x11, 0x01, 0x01, 0x01]);
        assert_eq!(enc(&[]), [0x01]);
    }

    #[test]
    fn long_runs_without_zeros_split_into_blocks_of_254() {
        let data: Vec<u8> = (1..=255u8).collect();
        let e = enc(&data);
        assert_eq!(e[0], 0xFF);
        assert_eq!(e[255], 0x02);
        assert_eq!(e.len(), 257);
        assert_eq!(dec(&e).as_deref(), Some(&data[..]));
    }

    #[test]
    fn bytes_no_encoder_makes_are_refused() {
        assert_eq!(dec(&[0x05, 0x11]), None, "code points past the end");
        assert_eq!(dec(&[0x03, 0x00, 0x11]), None, "a zero inside a block");
        assert_eq!(dec(&[0x00]), None, "a zero code byte");
    }

    #[test]
    fn a_too_small_buffer_is_reported_not_overrun() {
        let mut out = [0u8; 3];
        assert_eq!(encode(&[1, 2, 3], &mut out), None);
    }

    proptest::proptest! {
        #[test]
        fn encoding_then_decoding_gives_the_input_back(data in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..600)) {
            let e = enc(&data);
            proptest::prop_assert!(!e.contains(&0));
            proptest::prop_assert!(e.len() <= max_encoded_len(data.len()));
            proptest::prop_assert_eq!(dec(&e), Some(data));
        }
    }
}
