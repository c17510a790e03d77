//! The protocol's test vectors (the ones docs/serial-protocol.md prints), the decoder's
//! counting of each refused chunk, and property tests over random messages and byte streams.

extern crate std;

use std::string::String;
use std::vec;
use std::vec::Vec;

use proptest::prelude::*;

use crate::*;

/// The protocol document, whose test-vector table must list exactly these frames.
const DOC: &str = include_str!("../../../docs/serial-protocol.md");

fn hex(bytes: &[u8]) -> String {
    let parts: Vec<String> = bytes.iter().map(|b| std::format!("{b:02x}")).collect();
    parts.join(" ")
}

fn unhex(s: &str) -> Vec<u8> {
    s.split_whitespace().map(|h| u8::from_str_radix(h, 16).expect("hex byte")).collect()
}

fn readings(items: &[(u8, u16)]) -> Readings {
    let r: Vec<Reading> = items.iter().map(|&(id, range_mm)| Reading { id, range_mm }).collect();
    Readings::from_slice(&r).expect("at most 8")
}

fn wire(m: &Message, seq: u8) -> Vec<u8> {
    let mut out = [0u8; MAX_ENCODED_LEN];
    let n = encode(m, seq, &mut out).expect("valid message fits MAX_ENCODED_LEN");
    out[..n].to_vec()
}

/// (message, seq, its complete encoded frame). These bytes were cross-checked with independent
/// tools: Python's `binascii.crc_hqx(data, 0xFFFF)` for the CRC and the PyPI `cobs` package for
/// the stuffing.
fn vectors() -> Vec<(Message, u8, &'static str)> {
    let sample = Sample {
        board_time_ms: 1000,
        encoder_left: 4096,
        encoder_right: -12,
        flags: StatusFlags::default(),
        last_motor_seq: 1,
        sonar: readings(&[(0, 850), (1, NO_ECHO), (2, 1200)]),
        ir: readings(&[(0, 300)]),
    };
    let full: Vec<(u8, u16)> = (0..8u8).map(|i| (i, 500 + 100 * u16::from(i))).collect();
    let full_ir: Vec<(u8, u16)> = (0..8u8).map(|i| (i, 80 + 10 * u16::from(i))).collect();
    let largest = Sample {
        board_time_ms: u32::MAX,
        encoder_left: -1,
        encoder_right: i32::MAX,
        flags: StatusFlags::WATCHDOG_STOP,
        last_motor_seq: 200,
        sonar: readings(&full),
        ir: readings(&full_ir),
    };
    vec![
        (Message::Hello(Hello { sample_period_ms: 100 }), 0, "00 03 01 01 02 64 03 07 0a 00"),
        (
            Message::MotorPowers(MotorPowers { left_permille: 500, right_permille: -250 }),
            1,
            "00 0a 01 02 01 f4 01 06 ff 64 be 00",
        ),
        (Message::Heartbeat, 2, "00 06 01 03 02 bd 8e 00"),
        (Message::EmergencyStop(EmergencyStop { reason: StopReason::HOST_SHUTDOWN }), 3, "00 07 01 04 03 02 a5 5b 00"),
        (
            Message::BoardInfo(BoardInfo {
                firmware_version: 0x0102,
                counts_per_rev: 2048,
                sonar_count: 8,
                ir_count: 8,
                sample_period_ms: 100,
            }),
            0,
            "00 03 01 81 03 02 01 02 08 01 04 08 08 64 03 33 89 00",
        ),
        (
            Message::Sample(sample),
            1,
            "00 06 01 82 01 e8 03 01 01 02 10 01 05 f4 ff ff ff 01 04 01 03 01 09 52 03 01 ff ff 02 b0 04 05 2c 01 67 53 00",
        ),
        (
            Message::Status(BoardStatus {
                uptime_ms: 123_456,
                flags: StatusFlags::WATCHDOG_STOP.with(StatusFlags::LOW_BATTERY),
            }),
            2,
            "00 07 01 83 02 40 e2 01 02 21 03 ba f0 00",
        ),
        (
            Message::StopAck(StopAck { stop_seq: 3, reason: StopReason::HOST_SHUTDOWN }),
            3,
            "00 08 01 84 03 03 02 d5 80 00",
        ),
        (Message::SimStep(SimStep { dt_ms: 20 }), 4, "00 05 01 10 04 14 03 8d b3 00"),
        (
            Message::SimTruth(SimTruth {
                board_time_ms: 1000,
                x_mm: 10_000,
                y_mm: 6_100,
                heading_mdeg: -90_000,
                contacts: 2,
            }),
            5,
            "00 06 01 90 05 e8 03 01 03 10 27 01 03 d4 17 01 06 70 a0 fe ff 02 01 01 03 fd fc 00",
        ),
        (
            Message::Sample(largest),
            255,
            "00 11 01 82 ff ff ff ff ff ff ff ff ff ff ff ff 7f 01 04 c8 08 08 18 f4 01 01 58 02 02 bc 02 03 20 03 \
             04 84 03 05 e8 03 06 4c 04 07 b0 04 02 50 03 01 5a 03 02 64 03 03 6e 03 04 78 03 05 82 03 06 8c 03 \
             07 96 03 e7 5c 00",
        ),
    ]
}

#[test]
fn every_test_vector_encodes_byte_for_byte() {
    for (m, seq, expected) in vectors() {
        assert_eq!(hex(&wire(&m, seq)), hex(&unhex(expected)), "{m:?} seq {seq}");
    }
}

#[test]
fn every_test_vector_decodes_to_its_message() {
    for (m, seq, bytes) in vectors() {
        assert_eq!(decode(&unhex(bytes)), Ok(Frame { seq, message: m }));
        let mut d = Decoder::new();
        let mut got = Vec::new();
        d.feed(&unhex(bytes), |r| got.push(r));
        assert_eq!(got, [Ok(Frame { seq, message: m })]);
    }
}

#[test]
fn the_protocol_document_prints_every_test_vector() {
    // The document wraps long frames over several lines of its code block; compare the
    // document's hex bytes as one stream.
    let doc_hex: String = DOC
        .lines()
        .filter(|l| l.trim_start().starts_with("wire:") || l.starts_with("      "))
        .flat_map(|l| l.trim().trim_start_matches("wire:").split_whitespace().map(String::from).collect::<Vec<_>>())
        .collect::<Vec<_>>()
        .join(" ");
    for (m, seq, bytes) in vectors() {
        let h = hex(&unhex(bytes));
        assert!(doc_hex.contains(&h), "docs/serial-protocol.md lacks the vector of {m:?} seq {seq}: {h}");
    }
}

#[test]
fn the_largest_frame_is_exactly_max_encoded_len() {
    let (m, seq, _) = vectors().pop().expect("vectors");
    assert_eq!(wire(&m, seq).len(), MAX_ENCODED_LEN);
    assert_eq!(MAX_ENCODED_LEN, 73);
}

#[test]
fn the_crc_is_the_ccitt_false_check_value() {
    assert_eq!(crc16_ccitt_false(b"123456789"), 0x29B1);
}

#[test]
fn type_codes_tell_the_direction() {
    for t in MessageType::ALL {
        assert_eq!(MessageType::from_code(t.code()), Some(t));
        let board = matches!(
            t,
            MessageType::BoardInfo
                | MessageType::Sample
                | MessageType::Status
                | MessageType::StopAck
                | MessageType::SimTruth
        );
        assert_eq!(t.from_board(), board, "{t:?}");
    }
    assert_eq!(MessageType::from_code(0x05), None);
}

#[test]
fn a_too_small_buffer_gets_nothing_written() {
    let mut out = [0xAAu8; 7];
    assert_eq!(
        encode(&Message::Heartbeat, 0, &mut out),
        Err(FrameEncodeError::BufferTooSmall { needed: 8, available: 7 })
    );
    assert_eq!(out, [0xAA; 7]);
}

#[test]
fn the_encoder_refuses_what_the_decoder_would_refuse() {
    let mut out = [0u8; MAX_ENCODED_LEN];
    let too_fast = Message::MotorPowers(MotorPowers { left_permille: 1001, right_permille: 0 });
    assert!(matches!(encode(&too_fast, 0, &mut out), Err(FrameEncodeError::InvalidField { .. })));
    let back = Message::MotorPowers(MotorPowers { left_permille: 0, right_permille: -1001 });
    assert!(matches!(encode(&back, 0, &mut out), Err(FrameEncodeError::InvalidField { .. })));
    let twice = Sample { sonar: readings(&[(3, 100), (3, 200)]), ..Sample::default() };
    assert_eq!(
        encode(&Message::Sample(twice), 0, &mut out),
        Err(FrameEncodeError::InvalidField { field: "sensor id repeated" })
    );
    let ninth = Sample { ir: readings(&[(8, 100)]), ..Sample::default() };
    assert_eq!(
        encode(&Message::Sample(ninth), 0, &mut out),
        Err(FrameEncodeError::InvalidField { field: "sensor id above 7" })
    );
    let many = BoardInfo { sonar_count: 9, ..BoardInfo::default() };
    assert!(matches!(encode(&Message::BoardInfo(many), 0, &mut out), Err(FrameEncodeError::InvalidField { .. })));
}

#[test]
fn a_truth_heading_outside_the_half_open_interval_is_refused_both_ways() {
    let mut out = [0u8; MAX_ENCODED_LEN];
    for heading_mdeg in [-HEADING_MDEG_MAX, HEADING_MDEG_MAX + 1, i32::MIN] {
        let t = Message::SimTruth(SimTruth { heading_mdeg, ..SimTruth::default() });
        assert!(matches!(encode(&t, 0, &mut out), Err(FrameEncodeError::InvalidField { .. })), "{heading_mdeg}");
        let mut body = vec![1, 0x90, 0];
        body.extend_from_slice(&[0; 12]);
        body.extend_from_slice(&heading_mdeg.to_le_bytes());
        body.extend_from_slice(&[0; 4]);
        assert!(matches!(
            decode(&raw_frame(&body)),
            Err(FrameDecodeError::InvalidField { message_type: MessageType::SimTruth, .. })
        ));
    }
    let edge = Message::SimTruth(SimTruth { heading_mdeg: HEADING_MDEG_MAX, ..SimTruth::default() });
    assert!(encode(&edge, 0, &mut out).is_ok(), "180000 (= 180 degrees) is in the interval");
}

#[test]
fn extension_frames_of_the_wrong_length_are_refused() {
    assert_eq!(
        decode(&raw_frame(&[1, 0x10, 0, 20])),
        Err(FrameDecodeError::BadLength { message_type: MessageType::SimStep, len: 1 })
    );
    assert_eq!(
        decode(&raw_frame(&[1, 0x90, 0, 1, 2, 3])),
        Err(FrameDecodeError::BadLength { message_type: MessageType::SimTruth, len: 3 })
    );
}

#[test]
fn readings_hold_at_most_eight() {
    let mut r = Readings::new();
    for id in 0..8 {
        assert_eq!(r.push(Reading { id, range_mm: 1 }), Ok(()));
    }
    assert_eq!(r.push(Reading { id: 0, range_mm: 2 }), Err(Reading { id: 0, range_mm: 2 }));
    assert_eq!(r.len(), 8);
    assert_eq!(r.range_mm(5), Some(1));
    assert!(Readings::from_slice(&[Reading::default(); 9]).is_none());
}

/// Wraps hand-made frame bytes (version, type, seq, payload) with a CRC and COBS, as a buggy
/// or foreign sender would, so the decoder's checks past the CRC can be reached.
fn raw_frame(body: &[u8]) -> Vec<u8> {
    let mut raw = body.to_vec();
    raw.extend_from_slice(&crc16_ccitt_false(body).to_le_bytes());
    let mut out = vec![0u8; crate::cobs::max_encoded_len(raw.len())];
    let n = crate::cobs::encode(&raw, &mut out).expect("sized");
    out.truncate(n);
    let mut w = vec![0];
    w.extend_from_slice(&out);
    w.push(0);
    w
}

fn decode_all(d: &mut Decoder, bytes: &[u8]) -> Vec<Result<Frame, FrameDecodeError>> {
    let mut got = Vec::new();
    d.feed(bytes, |r| got.push(r));
    got
}

#[test]
fn each_kind_of_bad_frame_is_refused_and_counted() {
    let mut d = Decoder::new();
    // One bit flipped in the left motor power's low byte (0xF4 -> 0xF5): a line error.
    let mut corrupt = wire(&Message::MotorPowers(MotorPowers { left_permille: 500, right_permille: -250 }), 1);
    assert_eq!(corrupt[5], 0xF4);
    corrupt[5] ^= 0x01;
    assert!(matches!(decode_all(&mut d, &corrupt)[..], [Err(FrameDecodeError::Crc { .. })]));
    assert_eq!(decode_all(&mut d, &raw_frame(&[2, 0x03, 0])), [Err(FrameDecodeError::BadVersion { version: 2 })]);
    assert_eq!(decode_all(&mut d, &raw_frame(&[1, 0x7F, 0])), [Err(FrameDecodeError::UnknownType { code: 0x7F })]);
    assert_eq!(
        decode_all(&mut d, &raw_frame(&[1, 0x02, 0, 1, 2, 3])),
        [Err(FrameDecodeError::BadLength { message_type: MessageType::MotorPowers, len: 3 })]
    );
    // 0x03E9 = 1001 per-mille: more than full power.
    assert!(matches!(
        decode_all(&mut d, &raw_frame(&[1, 0x02, 0, 0xE9, 0x03, 0, 0]))[..],
        [Err(FrameDecodeError::InvalidField { message_type: MessageType::MotorPowers, .. })]
    ));
    assert_eq!(decode_all(&mut d, &[0, 0x02, 0x01, 0]), [Err(FrameDecodeError::TooShort { len: 1 })]);
    assert_eq!(decode_all(&mut d, &[0, 0x05, 0x01, 0]), [Err(FrameDecodeError::Cobs)]);
    let long = [0x55u8; 200];
    assert_eq!(decode_all(&mut d, &long), [Err(FrameDecodeError::Oversize)], "reported once");
    assert_eq!(decode_all(&mut d, &wire(&Message::Heartbeat, 1)), [Ok(Frame { seq: 1, message: Message::Heartbeat })]);
    let s = *d.stats();
    assert_eq!(
        s,
        DecoderStats {
            frames: 1,
            oversize: 1,
            malformed: 2,
            crc_errors: 1,
            bad_version: 1,
            unknown_type: 1,
            bad_length: 1,
            invalid_field: 1,
            missed: 0,
        }
    );
    assert_eq!(s.errors(), 8);
}

#[test]
fn a_frame_cut_short_does_not_swallow_the_next_one() {
    let next = wire(&Message::Heartbeat, 9);
    let cut = wire(&Message::MotorPowers(MotorPowers { left_permille: 100, right_permille: 100 }), 8);
    let mut stream = cut[..cut.len() / 2].to_vec();
    stream.extend_from_slice(&next);
    let mut d = Decoder::new();
    let got = decode_all(&mut d, &stream);
    assert_eq!(got.len(), 2);
    assert!(got[0].is_err());
    assert_eq!(got[1], Ok(Frame { seq: 9, message: Message::Heartbeat }));
}

#[test]
fn gaps_in_sequence_numbers_count_as_missed_frames() {
    let mut d = Decoder::new();
    for seq in [254u8, 255, 2, 3] {
        decode_all(&mut d, &wire(&Message::Heartbeat, seq));
    }
    assert_eq!(d.stats().missed, 2, "0 and 1 went missing across the wrap");
    d.reset();
    decode_all(&mut d, &wire(&Message::Heartbeat, 100));
    assert_eq!(d.stats().missed, 2, "after a reset the first frame sets the count anew");
}

#[test]
fn errors_read_as_sentences() {
    let e = FrameDecodeError::Crc { received: 0x1234, computed: 0xABCD };
    assert_eq!(std::format!("{e}"), "CRC mismatch: frame says 0x1234, bytes give 0xabcd");
    let e = FrameEncodeError::BufferTooSmall { needed: 8, available: 7 };
    assert_eq!(std::format!("{e}"), "frame needs 8 bytes, buffer has 7");
}

fn arb_readings() -> impl Strategy<Value = Readings> {
    (proptest::sample::subsequence((0u8..8).collect::<Vec<_>>(), 0..=8), proptest::collection::vec(any::<u16>(), 8))
        .prop_flat_map(|(ids, ranges)| Just(ids).prop_shuffle().prop_map(move |ids| (ids, ranges.clone())))
        .prop_map(|(ids, ranges)| {
            let r: Vec<Reading> = ids.iter().zip(ranges).map(|(&id, range_mm)| Reading { id, range_mm }).collect();
            Readings::from_slice(&r).expect("at most 8")
        })
}

fn arb_message() -> impl Strategy<Value = Message> {
    let power = -FULL_POWER..=FULL_POWER;
    prop_oneof![
        any::<u16>().prop_map(|p| Message::Hello(Hello { sample_period_ms: p })),
        (power.clone(), power)
            .prop_map(|(l, r)| Message::MotorPowers(MotorPowers { left_permille: l, right_permille: r })),
        Just(Message::Heartbeat),
        any::<u8>().prop_map(|r| Message::EmergencyStop(EmergencyStop { reason: StopReason(r) })),
        (any::<u16>(), any::<u32>(), 0u8..=8, 0u8..=8, any::<u16>()).prop_map(|(f, c, s, i, p)| {
            Message::BoardInfo(BoardInfo {
                firmware_version: f,
                counts_per_rev: c,
                sonar_count: s,
                ir_count: i,
                sample_period_ms: p,
            })
        }),
        (any::<u32>(), any::<i32>(), any::<i32>(), any::<u16>(), any::<u8>(), arb_readings(), arb_readings()).prop_map(
            |(t, l, r, f, s, sonar, ir)| Message::Sample(Sample {
                board_time_ms: t,
                encoder_left: l,
                encoder_right: r,
                flags: StatusFlags(f),
                last_motor_seq: s,
                sonar,
                ir,
            })
        ),
        (any::<u32>(), any::<u16>())
            .prop_map(|(u, f)| Message::Status(BoardStatus { uptime_ms: u, flags: StatusFlags(f) })),
        (any::<u8>(), any::<u8>()).prop_map(|(s, r)| Message::StopAck(StopAck { stop_seq: s, reason: StopReason(r) })),
        any::<u16>().prop_map(|d| Message::SimStep(SimStep { dt_ms: d })),
        (any::<u32>(), any::<i32>(), any::<i32>(), -HEADING_MDEG_MAX + 1..=HEADING_MDEG_MAX, any::<u32>()).prop_map(
            |(t, x, y, h, c)| Message::SimTruth(SimTruth {
                board_time_ms: t,
                x_mm: x,
                y_mm: y,
                heading_mdeg: h,
                contacts: c
            })
        ),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn every_message_survives_encode_then_decode(m in arb_message(), seq in any::<u8>()) {
        let w = wire(&m, seq);
        prop_assert!(w.len() <= MAX_ENCODED_LEN);
        prop_assert_eq!(w.iter().filter(|&&b| b == 0).count(), 2, "only the two delimiters are zero");
        prop_assert_eq!(decode(&w), Ok(Frame { seq, message: m }));
        let mut d = Decoder::new();
        prop_assert_eq!(decode_all(&mut d, &w), vec![Ok(Frame { seq, message: m })]);
    }

    #[test]
    fn random_bytes_never_panic_and_every_chunk_is_counted(bytes in proptest::collection::vec(any::<u8>(), 0..2000)) {
        let _ = decode(&bytes);
        let mut d = Decoder::new();
        let got = decode_all(&mut d, &bytes);
        let ok = got.iter().filter(|r| r.is_ok()).count();
        prop_assert_eq!(u32::try_from(ok).ok(), Some(d.stats().frames));
        prop_assert_eq!(u32::try_from(got.len() - ok).ok(), Some(d.stats().errors()));
    }

    #[test]
    fn valid_frames_between_garbage_and_cut_frames_still_decode_in_order(
        parts in proptest::collection::vec(
            (arb_message(), any::<u8>(), proptest::collection::vec(any::<u8>(), 0..120), arb_message(), any::<proptest::sample::Index>()),
            1..12,
        ),
    ) {
        let mut stream = Vec::new();
        let mut expected = Vec::new();
        for (m, seq, garbage, cut_message, cut_at) in &parts {
            stream.extend_from_slice(garbage);
            // A frame cut off before its last data byte (a sender reset mid-frame).
            let cut = wire(cut_message, seq.wrapping_add(100));
            stream.extend_from_slice(&cut[..1 + cut_at.index(cut.len() - 2)]);
            stream.extend_from_slice(&wire(m, *seq));
            expected.push(Frame { seq: *seq, message: *m });
        }
        let mut d = Decoder::new();
        let got: Vec<Frame> = decode_all(&mut d, &stream).into_iter().filter_map(Result::ok).collect();
        prop_assert_eq!(got, expected);
    }
}

#[test]
fn raw_frames_carry_what_encode_refuses_to_and_are_refused_with_their_reason() {
    // (Every message's frame goes through encode_raw, so the test vectors check its framing.)
    // What a test bench sends to check a receiver: well framed, CRC right, yet refused.
    let mut out = [0u8; MAX_ENCODED_LEN];
    let n = encode_raw(&[VERSION, 0x7F, 1, 9, 9], &mut out).expect("fits");
    assert_eq!(decode(&out[..n]), Err(FrameDecodeError::UnknownType { code: 0x7F }));
    let n = encode_raw(&[VERSION, 0x84, 1, 1, 2, 3, 4, 5, 6], &mut out).expect("fits");
    assert!(matches!(decode(&out[..n]), Err(FrameDecodeError::BadLength { .. })), "{:?}", decode(&out[..n]));
    assert!(encode_raw(&[0u8; MAX_FRAME_LEN], &mut out).is_err(), "no room for the CRC");
    assert!(encode_raw(&[VERSION, 0x7F, 1], &mut out[..4]).is_err(), "the output buffer is checked");
}
