//! `iwsim chair-emulator`: a stand-in for the physical wheelchair and its acquisition board, so
//! that the RS232 bridge and everything behind it can be tested without hardware.
//!
//! It opens a pseudo-terminal (or a given serial device), speaks the protocol of
//! `docs/serial-protocol.md` (through the one `serial-protocol` crate) at a baud rate with
//! realistic byte timing, and simulates a *real* chair in a *real* room: the Intellwheels body and
//! sensors of `sim_model::chair`, one robot in its own seeded `world::World` on its own floor plan
//! with furniture the simulator's map need not have, and what a real chair shows — the right
//! motor weaker than the left, wheel slip, sonar dropouts and spikes, IR beams blind to dark
//! surfaces, range noise. It keeps the board's safety rule (motors to zero after 300 ms without
//! a valid command), and logs the chair's ground truth for tests.
//!
//! ```
//! use chair_emulator::{Board, BoardConfig, Imperfections, Outbox, Room};
//! use serial_protocol::{Decoder, Hello, MAX_ENCODED_LEN, Message, MotorPowers, SimStep, encode};
//!
//! // A stepped board: its clock moves only when the host says so, so the run is exact.
//! let room = Room::load("builtin:liacc", vec![]).expect("built in");
//! let cfg = BoardConfig { stepped: true, imperfections: Imperfections::NONE, ..BoardConfig::default() };
//! let mut board = Board::new(&cfg, &room).expect("free start");
//! let mut out = Outbox::default();
//! let mut host_seq = 0u8;
//! let mut send = |m: Message, board: &mut Board, out: &mut Outbox| {
//!     let mut wire = [0u8; MAX_ENCODED_LEN];
//!     let n = encode(&m, host_seq, &mut wire).expect("valid");
//!     host_seq = host_seq.wrapping_add(1);
//!     board.receive(&wire[..n], out);
//! };
//! send(Message::Hello(Hello { sample_period_ms: 100 }), &mut board, &mut out);
//! for _ in 0..10 {
//!     send(Message::MotorPowers(MotorPowers { left_permille: 1000, right_permille: 1000 }), &mut board, &mut out);
//!     send(Message::SimStep(SimStep { dt_ms: 100 }), &mut board, &mut out);
//! }
//! assert!(board.pose().x > 10.2, "a second at full power drives the chair forward");
//! let mut decoder = Decoder::new();
//! let frames: Vec<_> = out.wire.iter().filter_map(|&b| decoder.push(b)).collect();
//! assert!(frames.iter().all(Result::is_ok));
//! // BoardInfo; a Sample and its SimTruth every 100 ms; the periodic Status at 1 s.
//! assert_eq!(frames.len(), 1 + 2 * 10 + 1);
//! ```
//!
//! The pieces: [`Room`] (floor plan and boxes), [`Board`] (the protocol's rules, physics and
//! sensors, pure: time and bytes in, bytes and truth events out), [`Emulator`] (the port, byte
//! pacing, the clock and the truth log around a board) and [`run`] for the command line.
//!
//! The board speaks only after a Hello (a board has no way to know a host is there), and each
//! Hello discards the bytes the host has not read yet: a pseudo-terminal keeps what is written
//! to it for a host that may have gone, which a real line would not.
#![warn(missing_docs)]

mod args;
mod board;
mod driver;
mod room;
mod sys;

use std::io::Write as _;
use std::sync::atomic::AtomicBool;

pub use args::EmulatorArgs;
pub use board::{
    Board, BoardBuildError, BoardConfig, BoardCounters, DEFAULT_PERIOD_MS, Event, EventKind, FIRMWARE_VERSION,
    Imperfections, MAX_PERIOD_MS, MIN_PERIOD_MS, Outbox, PHYSICS_US, STATUS_US, WATCHDOG_US, ZeroReason, drop_reason,
};
pub use driver::{Emulator, EmulatorConfig, EmulatorError, EmulatorHandle, Outcome, PortChoice, spawn_on_pty};
pub use room::{BOX_HEIGHT_M, Room, RoomBox, RoomBuildError};
pub use sys::monotonic_ns;

/// Runs the emulator the command line describes until `stop` is set (by the caller's signal
/// handler): prints `chair-emulator: PATH` (the port a host opens) as the first line of stdout,
/// then, at the end, the [`Outcome`] as the last.
pub fn run(args: EmulatorArgs, stop: &AtomicBool) -> Result<Outcome, EmulatorError> {
    let emulator = Emulator::new(args.config()?)?.with_fault_signals()?;
    let mut stdout = std::io::stdout().lock();
    // A closed stdout must not stop the chair's emulator: the path is also in the link.
    let _ = writeln!(stdout, "chair-emulator: {}", emulator.path().display());
    let _ = stdout.flush();
    drop(stdout);
    let outcome = emulator.run(stop)?;
    // As with the first line: a reader that has gone must not turn a clean stop into a panic.
    let _ = writeln!(std::io::stdout().lock(), "{outcome}");
    Ok(outcome)
}
