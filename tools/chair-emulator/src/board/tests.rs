//! The board's rules, the chair's physics and sensors, driven without I/O on a stepped clock.

use proptest::prelude::*;
use serial_protocol::{EmergencyStop, Frame, Hello, SimStep};

use super::*;
use crate::room::RoomBox;

/// A host for a board in memory: encodes its frames with its own sequence numbers and decodes
/// what the board sends.
struct Host {
    board: Board,
    out: Outbox,
    seq: u8,
    decoder: Decoder,
    /// Every frame the board sent, in order.
    got: Vec<Frame>,
    /// Every truth event, in order.
    events: Vec<Event>,
}

impl Host {
    fn new(cfg: BoardConfig, room: &Room) -> Host {
        let board = Board::new(&cfg, room).expect("board builds");
        Host { board, out: Outbox::default(), seq: 0, decoder: Decoder::new(), got: Vec::new(), events: Vec::new() }
    }

    fn stepped(imperfections: Imperfections) -> Host {
        let room = Room::load("builtin:liacc", vec![]).expect("built in");
        Host::new(BoardConfig { stepped: true, imperfections, ..BoardConfig::default() }, &room)
    }

    /// Sends a message; returns the sequence number it went with.
    fn send(&mut self, m: Message) -> u8 {
        let mut wire = [0u8; MAX_ENCODED_LEN];
        let n = encode(&m, self.seq, &mut wire).expect("valid message");
        let seq = self.seq;
        self.seq = self.seq.wrapping_add(1);
        self.raw(&wire[..n]);
        seq
    }

    fn raw(&mut self, bytes: &[u8]) {
        self.board.receive(bytes, &mut self.out);
        self.collect();
    }

    fn collect(&mut self) {
        for &b in &self.out.wire {
            if let Some(r) = self.decoder.push(b) {
                self.got.push(r.expect("the board sends only valid frames"));
            }
        }
        self.events.extend(self.out.events.iter().copied());
        self.out.clear();
    }

    fn step(&mut self, ms: u16) {
        self.send(Message::SimStep(SimStep { dt_ms: ms }));
    }

    fn drive(&mut self, left: i16, right: i16) -> u8 {
        self.send(Message::MotorPowers(MotorPowers { left_permille: left, right_permille: right }))
    }

    fn hello(&mut self, period: u16) {
        self.send(Message::Hello(Hello { sample_period_ms: period }));
    }

    fn samples(&self) -> Vec<Sample> {
        self.got
            .iter()
            .filter_map(|f| match f.message {
                Message::Sample(s) => Some(s),
                _ => None,
            })
            .collect()
    }

    fn zero_events(&self) -> Vec<(u64, ZeroReason)> {
        self.events
            .iter()
            .filter_map(|e| match e.kind {
                EventKind::MotorsZero(r) => Some((e.board_us, r)),
                _ => None,
            })
            .collect()
    }
}

#[test]
fn the_board_is_silent_until_a_hello_and_answers_it_with_board_info() {
    let mut h = Host::stepped(Imperfections::NONE);
    h.step(500);
    assert!(h.got.is_empty(), "nothing before a Hello: {:?}", h.got);
    h.hello(0);
    let Some(Frame { message: Message::BoardInfo(info), .. }) = h.got.first().copied() else {
        panic!("first frame after a Hello: {:?}", h.got.first())
    };
    assert_eq!(
        info,
        BoardInfo {
            firmware_version: FIRMWARE_VERSION,
            counts_per_rev: chair::COUNTS_PER_REV,
            sonar_count: 5,
            ir_count: 3,
            sample_period_ms: DEFAULT_PERIOD_MS,
        }
    );
    // The watchdog tripped at 300 ms (no command since power-up): the session's first Status says so.
    assert!(
        matches!(h.got.get(1), Some(Frame { message: Message::Status(s), .. }) if s.flags.contains(StatusFlags::WATCHDOG_STOP))
    );
    for (asked, used) in [(5, MIN_PERIOD_MS), (20, 20), (250, 250), (5000, MAX_PERIOD_MS)] {
        h.got.clear();
        h.hello(asked);
        assert!(matches!(h.got[0].message, Message::BoardInfo(b) if b.sample_period_ms == used), "{asked}");
    }
}

#[test]
fn samples_come_every_period_each_followed_by_its_truth() {
    let mut h = Host::stepped(Imperfections::NONE);
    h.hello(50);
    h.got.clear();
    h.step(200);
    let kinds: Vec<MessageTypeName> = h.got.iter().map(|f| name(&f.message)).collect();
    assert_eq!(kinds, ["Sample", "SimTruth", "Sample", "SimTruth", "Sample", "SimTruth", "Sample", "SimTruth"]);
    let times: Vec<u32> = h.samples().iter().map(|s| s.board_time_ms).collect();
    assert_eq!(times, [50, 100, 150, 200]);
    let Message::SimTruth(t) = h.got[1].message else { panic!("truth") };
    assert_eq!((t.board_time_ms, t.x_mm, t.y_mm, t.heading_mdeg, t.contacts), (50, 10_000, 6_100, 0, 0));
}

type MessageTypeName = &'static str;

fn name(m: &Message) -> MessageTypeName {
    match m {
        Message::Sample(_) => "Sample",
        Message::SimTruth(_) => "SimTruth",
        Message::Status(_) => "Status",
        Message::BoardInfo(_) => "BoardInfo",
        Message::StopAck(_) => "StopAck",
        _ => "host",
    }
}

#[test]
fn motor_powers_drive_the_chair_and_the_encoders_count_forward() {
    let mut h = Host::stepped(Imperfections::NONE);
    h.hello(100);
    for _ in 0..20 {
        h.drive(500, 500);
        h.step(100);
    }
    let p = h.board.pose();
    // 2 s at half power, the filter starting from rest: a little under 0.49 m.
    assert!(p.x > 10.35 && p.x < 10.49, "{p:?}");
    assert!((p.y - 6.1).abs() < 1e-9 && p.theta.abs() < 1e-9, "no asymmetry, straight: {p:?}");
    let last = *h.samples().last().expect("samples");
    let ticks_per_m = sim_model::encoder_ticks_per_m(f64::from(chair::COUNTS_PER_REV), chair::WHEEL_RADIUS_M);
    let expected = (p.x - 10.0) * ticks_per_m;
    for counts in [last.encoder_left, last.encoder_right] {
        assert!((f64::from(counts) - expected).abs() <= 2.0, "{counts} counts for {:.3} m", p.x - 10.0);
    }
    assert_eq!(last.last_motor_seq, h.seq - 2, "the last MotorPowers applied (the SimStep came after it)");
}

#[test]
fn a_weaker_right_motor_pulls_the_chair_right_while_its_encoders_tell_the_truth() {
    let mut h = Host::stepped(Imperfections { asymmetry: 0.03, ..Imperfections::NONE });
    h.hello(100);
    for _ in 0..30 {
        h.drive(800, 800);
        h.step(100);
    }
    let p = h.board.pose();
    assert!(p.theta < -0.01, "equal powers turn the chair right (clockwise): {p:?}");
    let s = *h.samples().last().expect("samples");
    assert!(s.encoder_right < s.encoder_left, "the right wheel turned less: {s:?}");
}

#[test]
fn the_watchdog_stops_the_motors_exactly_300_ms_after_the_last_command() {
    let mut h = Host::stepped(Imperfections::NONE);
    h.hello(100);
    h.step(40);
    h.drive(400, 400);
    let t0 = h.board.now_us();
    // Heartbeats, Hellos' absence and corrupt frames do not feed it.
    for _ in 0..10 {
        h.send(Message::Heartbeat);
        h.raw(&[0, 7, 1, 2, 3, 4, 5, 6, 0]);
        h.step(20);
        assert_eq!(h.board.applied(), [0.4, 0.4], "still driving at {} µs", h.board.now_us());
    }
    h.step(100);
    assert_eq!(h.zero_events(), [(t0 + WATCHDOG_US, ZeroReason::Watchdog)]);
    assert_eq!(h.board.applied(), [0.0, 0.0]);
    assert!(h.board.flags().contains(StatusFlags::WATCHDOG_STOP));
    assert!(
        h.got.iter().any(|f| matches!(f.message, Message::Status(s) if s.flags.contains(StatusFlags::WATCHDOG_STOP))),
        "a Status at once when the flag is set"
    );
    // The next valid command clears the flag and drives again.
    h.drive(200, 200);
    assert!(!h.board.flags().contains(StatusFlags::WATCHDOG_STOP));
    assert_eq!(h.board.applied(), [0.2, 0.2]);
}

#[test]
fn an_emergency_stop_is_latched_until_the_next_hello() {
    let mut h = Host::stepped(Imperfections::NONE);
    h.hello(100);
    h.drive(600, 600);
    h.step(100);
    h.got.clear();
    let stop_seq = h.send(Message::EmergencyStop(EmergencyStop { reason: StopReason::OPERATOR }));
    assert_eq!(h.board.applied(), [0.0, 0.0]);
    assert!(matches!(
        h.got[0].message,
        Message::StopAck(StopAck { stop_seq: s, reason: StopReason::OPERATOR }) if s == stop_seq
    ));
    assert!(matches!(h.got[1].message, Message::Status(s) if s.flags.contains(StatusFlags::ESTOP_LATCHED)));
    for _ in 0..5 {
        h.drive(600, 600);
        h.step(100);
        assert_eq!(h.board.applied(), [0.0, 0.0], "latched: MotorPowers ignored");
    }
    assert_eq!(h.board.counters().ignored_latched, 5);
    h.hello(100);
    assert!(!h.board.flags().contains(StatusFlags::ESTOP_LATCHED));
    h.drive(600, 600);
    assert_eq!(h.board.applied(), [0.6, 0.6]);
    let reasons: Vec<ZeroReason> = h.zero_events().iter().map(|e| e.1).collect();
    assert_eq!(reasons, [ZeroReason::Estop]);
}

#[test]
fn corrupt_and_truncated_frames_are_counted_and_never_acted_on() {
    let mut h = Host::stepped(Imperfections::NONE);
    h.hello(100);
    let mut wire = [0u8; MAX_ENCODED_LEN];
    let n = encode(&Message::MotorPowers(MotorPowers { left_permille: 900, right_permille: 900 }), 1, &mut wire)
        .expect("valid");
    let mut flipped = wire[..n].to_vec();
    flipped[5] ^= 0x10;
    h.raw(&flipped);
    // Cut short, then the next frame's leading delimiter: the stub is judged on its own.
    h.raw(&wire[..n - 3]);
    h.raw(&[0]);
    h.raw(&[0x55; 100]);
    h.raw(&[0]);
    h.step(100);
    assert_eq!(h.board.applied(), [0.0, 0.0]);
    assert_eq!(h.board.pose().x, 10.0);
    let d = h.board.counters().decoder;
    assert_eq!((d.crc_errors + d.malformed + d.bad_length, d.oversize), (2, 1), "{d:?}");
    let dropped: Vec<&str> = h
        .events
        .iter()
        .filter_map(|e| match e.kind {
            EventKind::FrameDropped(r) => Some(r),
            _ => None,
        })
        .collect();
    assert_eq!(dropped, ["crc", "malformed", "oversize"]);
    assert!(h.got.iter().any(|f| matches!(f.message, Message::Status(s) if s.flags.contains(StatusFlags::RX_ERRORS))));
}

#[test]
fn a_real_time_board_ignores_sim_step() {
    let room = Room::load("builtin:liacc", vec![]).expect("built in");
    let mut h = Host::new(BoardConfig { stepped: false, ..BoardConfig::default() }, &room);
    h.hello(100);
    h.step(1000);
    assert_eq!(h.board.now_us(), 0);
    assert_eq!(h.board.counters().ignored_sim_steps, 1);
    h.board.advance_to(250_000, &mut h.out);
    h.collect();
    assert_eq!(h.samples().len(), 2);
}

#[test]
fn the_chair_stops_at_a_wall_and_counts_one_contact() {
    let room =
        Room::load("builtin:liacc", vec![RoomBox::parse("wall,11.2,5,11.5,7.2").expect("valid")]).expect("inside");
    let mut h =
        Host::new(BoardConfig { stepped: true, imperfections: Imperfections::NONE, ..BoardConfig::default() }, &room);
    h.hello(100);
    for _ in 0..40 {
        h.drive(1000, 1000);
        h.step(100);
    }
    let p = h.board.pose();
    assert!(p.x + chair::BODY[2] * chair::BODY[0] <= 11.2, "the front stays short of the box: {p:?}");
    assert!(p.x > 10.2, "{p:?}");
    assert_eq!(h.board.contacts(), 1);
    let Some(Message::SimTruth(t)) = h.got.iter().rev().map(|f| f.message).find(|m| matches!(m, Message::SimTruth(_)))
    else {
        panic!("truth")
    };
    assert_eq!(t.contacts, 1);
}

#[test]
fn a_start_pose_inside_a_box_or_off_the_room_is_refused() {
    let room =
        Room::load("builtin:liacc", vec![RoomBox::parse("desk,9.5,5.5,10.5,6.5").expect("valid")]).expect("inside");
    let e = Board::new(&BoardConfig::default(), &room).expect_err("blocked");
    assert_eq!(e, BoardBuildError::PoseBlocked { x: 10.0, y: 6.1, heading_deg: 0.0 });
    let e = Board::new(&BoardConfig { pose: [-5.0, 1.0, 0.0], ..BoardConfig::default() }, &room).expect_err("off");
    assert!(matches!(e, BoardBuildError::Robot { .. }), "{e}");
    let bad = Imperfections { sonar_dropout: 2.0, ..Imperfections::NONE };
    let e = Board::new(&BoardConfig { imperfections: bad, ..BoardConfig::default() }, &room).expect_err("bad");
    assert_eq!(e.to_string(), "sonar_dropout = 2 is out of range: expected in [0, 1]");
}

/// A chair at the default pose with a box to its front left, which IR beam 1 (25° left) and
/// sonar 0 (60° left) both reach.
fn with_box_front_left(dark: bool) -> Host {
    let spec = if dark { "cabinet,10.5,6.9,12.5,7.5,dark" } else { "cabinet,10.5,6.9,12.5,7.5" };
    let room = Room::load("builtin:liacc", vec![RoomBox::parse(spec).expect("valid")]).expect("inside");
    let mut h =
        Host::new(BoardConfig { stepped: true, imperfections: Imperfections::NONE, ..BoardConfig::default() }, &room);
    h.hello(100);
    h.step(200);
    h
}

fn reading(s: &[Sample], kind: chair::Kind, id: u8) -> Option<u16> {
    s.iter().rev().find_map(|s| if kind == chair::Kind::Ir { s.ir.range_mm(id) } else { s.sonar.range_mm(id) })
}

#[test]
fn ir_beams_get_no_echo_from_a_dark_box_that_sonars_see() {
    let light = with_box_front_left(false).samples();
    let dark = with_box_front_left(true).samples();
    let ir1 = reading(&light, chair::Kind::Ir, 1).expect("IR every period");
    assert!((1300..1500).contains(&ir1), "IR 1 meets the light box ~1.43 m out: {ir1}");
    assert_eq!(reading(&dark, chair::Kind::Ir, 1), Some(NO_ECHO), "the dark box sends no IR back");
    let sonar_light = reading(&light, chair::Kind::Sonar, 0).expect("sonar 0 fired");
    let sonar_dark = reading(&dark, chair::Kind::Sonar, 0).expect("sonar 0 fired");
    assert!((400..700).contains(&sonar_dark), "sonar 0 hears the dark box: {sonar_dark}");
    assert_eq!(sonar_light, sonar_dark);
    assert_eq!(reading(&light, chair::Kind::Ir, 0), reading(&dark, chair::Kind::Ir, 0), "IR 0 looks elsewhere");
}

#[test]
fn sonars_fire_in_alternate_groups_and_full_frames_carry_every_id() {
    let mut h = Host::stepped(Imperfections::NONE);
    h.hello(100);
    h.step(200);
    let s = h.samples();
    let ids = |s: &Sample| s.sonar.as_slice().iter().map(|r| r.id).collect::<Vec<_>>();
    assert_eq!((ids(&s[0]), ids(&s[1])), (vec![0, 2, 4], vec![1, 3]));
    assert!(s.iter().all(|s| s.ir.len() == 3));

    let room = Room::load("builtin:liacc", vec![]).expect("built in");
    let full = BoardConfig { stepped: true, full_frames: true, ..BoardConfig::default() };
    let mut h = Host::new(full, &room);
    h.hello(100);
    h.out.clear();
    h.board.receive(&sim_step(100), &mut h.out);
    // The Sample is the first frame of the step: the largest frame there is.
    let first_len = h.out.wire.iter().skip(1).position(|&b| b == 0).map(|i| i + 2);
    assert_eq!(first_len, Some(MAX_ENCODED_LEN));
    h.collect();
    assert!(h.samples().iter().all(|s| s.sonar.len() == 8 && s.ir.len() == 8));
}

fn sim_step(ms: u16) -> Vec<u8> {
    let mut wire = [0u8; MAX_ENCODED_LEN];
    let n = encode(&Message::SimStep(SimStep { dt_ms: ms }), 200, &mut wire).expect("valid");
    wire[..n].to_vec()
}

/// The bytes a stepped board sends for a fixed script of host frames.
fn script_run(seed: u64) -> Vec<u8> {
    let room = Room::load("builtin:liacc", vec![RoomBox::parse("A,12,5,12.5,7,dark").expect("valid")]).expect("room");
    let cfg = BoardConfig { stepped: true, seed, ..BoardConfig::default() };
    let mut h = Host::new(cfg, &room);
    h.hello(50);
    let mut all = Vec::new();
    for i in 0..60i16 {
        h.drive(700 - i * 5, 600 + i * 3);
        h.board.receive(&sim_step(50), &mut h.out);
        all.extend_from_slice(&h.out.wire);
        h.collect();
    }
    all
}

#[test]
fn one_seed_and_one_script_give_the_same_bytes_and_another_seed_does_not() {
    let a = script_run(7);
    assert!(a.len() > 3000, "60 samples and their truths: {} bytes", a.len());
    assert_eq!(a, script_run(7));
    assert_ne!(a, script_run(8), "slip and sensor noise follow the seed");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn garbage_never_moves_the_chair(bytes in proptest::collection::vec(any::<u8>(), 0..3000)) {
        let mut h = Host::stepped(Imperfections::NONE);
        h.hello(100);
        h.raw(&bytes);
        h.step(500);
        if h.board.counters().motor_commands == 0 {
            prop_assert_eq!(h.board.applied(), [0.0, 0.0]);
            prop_assert_eq!(h.board.pose().x, 10.0);
        }
    }
}
