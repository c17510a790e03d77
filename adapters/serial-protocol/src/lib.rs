//! The serial protocol between iwsim and a wheelchair's acquisition board (RS232), as
//! `docs/serial-protocol.md` defines it: messages (motor powers, heartbeats, emergency stop;
//! encoder counts, sonar/IR readings, status, stop acknowledgement; and two test-bench
//! extensions, SimStep and SimTruth, between iwsim and its chair emulator), each framed with a
//! version, a type, a sequence number and a CRC-16/CCITT-FALSE, COBS-encoded between 0x00
//! delimiters.
//!
//! This crate is the protocol's one implementation: the `iwsim serial` bridge and the chair
//! emulator both use it, and a board's firmware can too. It is `no_std`, allocates nothing and
//! has no dependencies; [`encode`] writes into the caller's buffer and the streaming
//! [`Decoder`] keeps one fixed buffer, counts what it refuses and never panics on any input.
//!
//! ```
//! use serial_protocol::{encode, Decoder, Message, Reading, Readings, Sample, MAX_ENCODED_LEN};
//!
//! // The board sends one sample per tick...
//! let mut sample = Sample { encoder_left: 1200, encoder_right: 1187, ..Sample::default() };
//! sample.sonar = Readings::from_slice(&[Reading { id: 0, range_mm: 850 }]).expect("at most 8");
//! let mut wire = [0u8; MAX_ENCODED_LEN];
//! let n = encode(&Message::Sample(sample), 42, &mut wire).expect("fits");
//!
//! // ...and the host finds it in the byte stream, however the bytes arrive.
//! let mut decoder = Decoder::new();
//! let frames: Vec<_> = wire[..n].iter().filter_map(|&b| decoder.push(b)).collect();
//! let frame = frames[0].expect("valid");
//! assert_eq!((frame.seq, frame.message), (42, Message::Sample(sample)));
//! ```
#![no_std]
#![warn(missing_docs)]

mod cobs;
mod crc;
mod frame;
mod message;

pub use crc::crc16_ccitt_false;
pub use frame::{
    CRC_LEN, Decoder, DecoderStats, Frame, FrameDecodeError, FrameEncodeError, HEADER_LEN, MAX_COBS_LEN,
    MAX_ENCODED_LEN, MAX_FRAME_LEN, VERSION, decode, encode, encode_raw,
};
pub use message::{
    BoardInfo, BoardStatus, EmergencyStop, FULL_POWER, HEADING_MDEG_MAX, Hello, MAX_PAYLOAD_LEN, MAX_SENSORS, Message,
    MessageType, MotorPowers, NO_ECHO, Reading, Readings, Sample, SimStep, SimTruth, StatusFlags, StopAck, StopReason,
};

#[cfg(test)]
mod tests;
