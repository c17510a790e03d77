//! The host's safety rule of `docs/serial-protocol.md` as a pure state machine: it is fed the
//! time and what happened (a hub tick, a frame from the board, the port opening or going away,
//! a shutdown) and answers with the frames to send and the state changes to report. It reads
//! no clock and touches no port, so its tests drive it through every case with made-up times.
//!
//! The rule: the chair is told to stop — a MotorPowers {0, 0} at once, then an EmergencyStop
//! with the reason, both repeated every 100 ms until a StopAck or for 1 s — as soon as any
//! source goes quiet for 200 ms (the hub, the controlling agent, the board), the controlling
//! agent lets go, the board reports a motor fault, the port goes away or the adapter shuts
//! down. A stop is sent only while the chair may be moving by our command (we sent motor
//! powers since the last Hello or stop), except at shutdown, which always sends one: before
//! any motor command the board holds its motors at zero on its own (a Hello zeroes them, its
//! watchdog needs MotorPowers to let them turn).
//!
//! A stop latches: when every cause has cleared and the controller answers again, the chair
//! stays stopped until the operator resumes it (`iwsim resume`, teleop's `r` key: the hub's
//! `ResumeChair` count in the chair's block), as wheelchair safety practice has it — a chair
//! that drives off on its own when a stalled program recovers surprises its occupant. Then a
//! Hello clears the board's latched stop and driving resumes. `--auto-resume` (emulated chairs,
//! tests) resumes as soon as every cause has cleared. A resume asked while a cause holds is
//! refused, not kept for later: it never takes effect at a moment nobody chose.

use std::fmt;
use std::time::Duration;

use ipc_types::{DRIVE_CONTROLLED, DRIVE_FRESH};
use serial_protocol::{EmergencyStop, FULL_POWER, Hello, Message, MotorPowers, StatusFlags, StopReason};

/// A source silent this long is taken as gone (the protocol's host quiet threshold).
pub const QUIET: Duration = Duration::from_millis(200);
/// How late the news of a controller's answer may be before it counts as quiet, at the hub's
/// default 100 ms cycle: the block saying "answered" comes a cycle after the answer, the next
/// one a cycle later, plus 50 ms for a late tick. A controller frozen right after answering is
/// stopped 250–270 ms later. [`Safety::with_cycle`] scales it for other cycles.
pub const CONTROLLER_QUIET: Duration = Duration::from_millis(250);
/// What a late tick may add to a cycle before the hub or the controller counts as quiet.
const TICK_SLACK: Duration = Duration::from_millis(50);
/// How often an unanswered Hello is repeated.
pub const HELLO_EVERY: Duration = Duration::from_millis(500);
/// How often an unacknowledged stop is repeated.
pub const STOP_REPEAT_EVERY: Duration = Duration::from_millis(100);
/// How long an unacknowledged stop is repeated before the adapter gives up on a StopAck.
pub const STOP_REPEAT_FOR: Duration = Duration::from_secs(1);

/// Why the adapter stopped the chair.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum StopCause {
    /// The adapter is shutting down: a termination signal, a stop request, the run's end.
    Shutdown,
    /// The hub's process is gone, or it removed the chair.
    HubGone,
    /// The hub published no tick for 200 ms (stopped, paused, or hung).
    HubQuiet,
    /// No live agent controls the chair any more (it died or detached).
    ControllerLost,
    /// The controlling agent has not answered for 200 ms.
    ControllerQuiet,
    /// No valid frame from the board for 200 ms (in stepped mode: a step went unanswered).
    BoardQuiet,
    /// The serial port went away (read or write error, hang-up).
    PortGone,
    /// The board reports a motor fault; motion stays off until the adapter is restarted.
    MotorFault,
}

impl StopCause {
    /// The reason code sent in the EmergencyStop.
    pub fn reason(self) -> StopReason {
        match self {
            StopCause::Shutdown => StopReason::HOST_SHUTDOWN,
            StopCause::HubGone | StopCause::HubQuiet => StopReason::HUB_LOST,
            StopCause::ControllerLost | StopCause::ControllerQuiet => StopReason::CONTROLLER_LOST,
            StopCause::BoardQuiet | StopCause::PortGone => StopReason::LINK_LOST,
            StopCause::MotorFault => StopReason::UNSPECIFIED,
        }
    }
}

impl fmt::Display for StopCause {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            StopCause::Shutdown => "the adapter is shutting down",
            StopCause::HubGone => "the hub is gone",
            StopCause::HubQuiet => "the hub stopped ticking",
            StopCause::ControllerLost => "no agent controls the chair",
            StopCause::ControllerQuiet => "the controlling agent stopped answering",
            StopCause::BoardQuiet => "the board went silent",
            StopCause::PortGone => "the serial port went away",
            StopCause::MotorFault => "the board reports a motor fault",
        })
    }
}

/// What the state machine asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Output {
    /// Send this message to the board.
    Send(Message),
    /// A stop began (its frames follow as `Send`s when the port is open).
    Stop(StopCause),
    /// The board acknowledged the stop.
    StopAcked(StopCause),
    /// No StopAck came within 1 s; the board's own watchdog is the remaining guard.
    StopUnacknowledged(StopCause),
    /// The chair was resumed after this stop (by the operator, or `--auto-resume`): a Hello
    /// clears the board's latch if it holds one, then driving resumes.
    Resume(StopCause),
    /// Every cause of this stop has cleared; the chair stays stopped until the operator
    /// resumes it. Said once per stop.
    AwaitingResume(StopCause),
    /// The operator asked to resume while this cause still holds: refused (ask again once it
    /// has cleared).
    ResumeRefused(StopCause),
    /// The board answered the Hello: the link is up.
    BoardReady,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Stopping {
    cause: StopCause,
    started: Duration,
    last_sent: Duration,
}

/// The adapter's safety state. Times are durations since any fixed origin, never going back.
#[derive(Debug, Clone)]
pub struct Safety {
    stepped: bool,
    hello: Hello,
    board_quiet_after: Duration,
    port_open: bool,
    /// A BoardInfo arrived since the port opened.
    board_known: bool,
    /// Waiting for a BoardInfo; when to repeat the Hello.
    hello_due: Option<Duration>,
    last_frame: Duration,
    /// Stepped mode: a step went unanswered, and no frame came since.
    step_unanswered: bool,
    /// The last tick received, or answered.
    hub_at: Duration,
    /// The hub's cycle (see [`Safety::with_cycle`]).
    cycle: Duration,
    /// No tick for longer than this: the hub is quiet.
    hub_quiet_after: Duration,
    /// No news of a controller's answer for longer than this: it is quiet.
    controller_quiet_after: Duration,
    /// Stepped mode: a tick is held while its step's sample is awaited (the hub waits for us,
    /// and so does the controller: neither can be late meanwhile).
    holding: bool,
    /// The held tick's powers were fresh.
    held_fresh: bool,
    controlled: bool,
    fresh_at: Duration,
    /// We sent motor powers since the last Hello or stop: the chair may be moving by our word.
    engaged: bool,
    stopping: Option<Stopping>,
    /// The stop the board holds latched (until a Hello's BoardInfo).
    latched: Option<StopCause>,
    /// The stop the host holds until a resume, whatever became of the board's latch (a new
    /// port's Hello clears that one, and must not drive the chair on by itself).
    held: Option<StopCause>,
    /// Resume as soon as every cause has cleared, without the operator's word.
    auto_resume: bool,
    /// The hub's count of resume requests at the last tick (`None` before the first).
    resumes_seen: Option<u16>,
    /// A resume request not yet honoured or refused.
    resume_asked: bool,
    /// `AwaitingResume` was said for the stop held.
    awaiting_said: bool,
    motor_fault: bool,
    /// The board sent a SimTruth: it is the chair emulator.
    emulated: bool,
    shutdown: Option<StopCause>,
    out: Vec<Output>,
}

impl Safety {
    /// A state machine at time `now`, the port closed. `stepped`: the board is a stepped
    /// emulator (its silence is judged per step, not by the clock); `hello` is what each Hello
    /// asks for.
    pub fn new(now: Duration, stepped: bool, hello: Hello) -> Safety {
        Safety {
            stepped,
            hello,
            board_quiet_after: QUIET,
            port_open: false,
            board_known: false,
            hello_due: None,
            last_frame: now,
            step_unanswered: false,
            hub_at: now,
            cycle: Duration::from_millis(100),
            hub_quiet_after: QUIET,
            controller_quiet_after: CONTROLLER_QUIET,
            holding: false,
            held_fresh: false,
            controlled: false,
            fresh_at: now,
            engaged: false,
            stopping: None,
            latched: None,
            held: None,
            auto_resume: false,
            resumes_seen: None,
            resume_asked: false,
            awaiting_said: false,
            motor_fault: false,
            emulated: false,
            shutdown: None,
            out: Vec::new(),
        }
    }

    /// Fits the quiet thresholds to a hub ticking every `cycle`: at least [`QUIET`] for the
    /// hub, [`CONTROLLER_QUIET`] for the controller, longer for slow cycles (a tick may come a
    /// cycle plus 50 ms after the last; news of an answer two cycles plus 50 ms) so that a
    /// healthy run is never stopped. The 300 ms stop of the protocol holds for cycles up to
    /// 100 ms, the hub's default.
    pub fn with_cycle(mut self, cycle: Duration) -> Safety {
        self.cycle = cycle;
        self.hub_quiet_after = QUIET.max(cycle + TICK_SLACK);
        self.controller_quiet_after = CONTROLLER_QUIET.max(2 * cycle + TICK_SLACK);
        self
    }

    /// Resumes after a stop as soon as every cause has cleared, without the operator's word:
    /// for emulated chairs and tests, never for a chair with someone in it.
    pub fn with_auto_resume(mut self, auto_resume: bool) -> Safety {
        self.auto_resume = auto_resume;
        self
    }

    /// What the machine asked for since the last call, in order.
    pub fn drain(&mut self) -> std::vec::Drain<'_, Output> {
        self.out.drain(..)
    }

    /// The port opened: say Hello (repeated every 500 ms until a BoardInfo).
    pub fn port_opened(&mut self, now: Duration) {
        self.port_open = true;
        self.board_known = false;
        self.last_frame = now;
        self.step_unanswered = false;
        // The Hello zeroes the motors and clears any latch left by an earlier session.
        self.engaged = false;
        self.latched = None;
        self.stopping = None;
        self.say_hello(now);
    }

    /// The port went away. Nothing can be sent; if the chair was driven, the stop is recorded
    /// and the board's own 300 ms watchdog stops it.
    pub fn port_lost(&mut self, now: Duration) {
        self.port_open = false;
        self.board_known = false;
        self.hello_due = None;
        self.stopping = None;
        self.latched = None;
        if self.engaged {
            self.start_stop(now, StopCause::PortGone);
        }
    }

    /// A valid frame arrived from the board.
    pub fn frame(&mut self, now: Duration, message: &Message) {
        self.last_frame = now;
        self.step_unanswered = false;
        let flags = match message {
            Message::BoardInfo(info) => {
                self.board_known = true;
                // A board that samples slower than every 100 ms is quiet between samples.
                self.board_quiet_after = QUIET.max(Duration::from_millis(2 * u64::from(info.sample_period_ms)));
                if self.hello_due.take().is_some() {
                    // The answer to our Hello: the board's latch is clear, its motors at zero.
                    self.latched = None;
                    self.out.push(Output::BoardReady);
                }
                None
            }
            Message::StopAck(_) => {
                if let Some(s) = self.stopping.take() {
                    self.out.push(Output::StopAcked(s.cause));
                }
                None
            }
            Message::Sample(s) => Some(s.flags),
            Message::SimTruth(_) => {
                self.emulated = true;
                None
            }
            Message::Status(s) => Some(s.flags),
            _ => None,
        };
        if flags.is_some_and(|f| f.contains(StatusFlags::MOTOR_FAULT)) && !self.motor_fault {
            self.motor_fault = true;
            self.check(now);
        }
    }

    /// Stepped mode: the sample a step should have produced did not come in time.
    pub fn step_unanswered(&mut self, now: Duration) {
        self.step_unanswered = true;
        self.check(now);
    }

    /// A hub tick with the chair's `drive` powers and `DRIVE_*` flags: sends the motor powers
    /// when driving is safe, a Hello when a stop was resumed and the board holds its latch,
    /// else a Heartbeat.
    pub fn tick(&mut self, now: Duration, drive: [f32; 2], drive_flags: u32) {
        self.tick_aged(now, Duration::ZERO, drive, drive_flags);
    }

    /// [`Safety::tick`] for a tick the hub published `age` before `now` (its header's time):
    /// the hub's and the controller's signs of life are dated from when they were given, not
    /// from when this adapter read them. An adapter the machine's load kept off the CPU for a
    /// while then finds them as fresh as they are, not quiet (issue 27, fault 9), and a hub
    /// that really stopped is still found quiet, since its last tick stays old.
    pub fn tick_aged(&mut self, now: Duration, age: Duration, drive: [f32; 2], drive_flags: u32) {
        let published = now.saturating_sub(age).max(self.hub_at);
        let resumes = ipc_types::drive_resumes(drive_flags);
        // A count that moved since the last tick is a request; the first tick sets the count
        // (requests made before this adapter ran were not for the stop it holds).
        if self.resumes_seen.is_some_and(|seen| seen != resumes) {
            self.resume_asked = true;
        }
        self.resumes_seen = Some(resumes);
        // DRIVE_FRESH in this tick's block says the controller answered the *previous* tick,
        // so its last sign of life is dated from when that tick came, not this one: a
        // controller that stops right after answering is then stopped 200 ms later, not
        // 300 ms (a whole cycle of news lag added).
        // With ticks skipped while this adapter was held up, the previous tick it read is older
        // than the hub's previous tick, which came about a cycle before this one.
        let previous_tick = std::mem::replace(&mut self.hub_at, published).max(published.saturating_sub(self.cycle));
        self.controlled = drive_flags & DRIVE_CONTROLLED != 0;
        let fresh = self.controlled && drive_flags & DRIVE_FRESH != 0;
        self.holding = self.stepped;
        self.held_fresh = fresh;
        if fresh {
            self.fresh_at = self.fresh_at.max(previous_tick);
        }
        self.check(now);
        if !self.port_open || self.shutdown.is_some() {
            return;
        }
        let fault = self.fault(now);
        if self.resume_asked {
            match (self.held, fault) {
                // Nothing to resume.
                (None, _) => self.resume_asked = false,
                (Some(_), Some(f)) => {
                    self.resume_asked = false;
                    self.out.push(Output::ResumeRefused(f));
                }
                // Kept while only the stop's repeats or the controller's next answer are
                // awaited: each ends within a second, as a resume or a fault.
                (Some(_), None) => {}
            }
        }
        let clear = fresh && fault.is_none() && self.stopping.is_none();
        if clear && let Some(cause) = self.held {
            if self.auto_resume || self.resume_asked {
                self.held = None;
                self.resume_asked = false;
                self.out.push(Output::Resume(cause));
            } else if !self.awaiting_said {
                self.awaiting_said = true;
                self.out.push(Output::AwaitingResume(cause));
            }
        }
        let clear = clear && self.held.is_none();
        if clear && self.board_known && self.hello_due.is_none() && self.latched.is_none() {
            let [left_permille, right_permille] = drive.map(permille);
            self.send(Message::MotorPowers(MotorPowers { left_permille, right_permille }));
            self.engaged = true;
        } else if clear && self.hello_due.is_none() && self.latched.is_some() {
            self.say_hello(now);
        } else {
            self.send(Message::Heartbeat);
        }
    }

    /// The tick in hand was answered (stepped mode holds it while it waits for the board).
    pub fn answered(&mut self, now: Duration) {
        if std::mem::take(&mut self.holding) && self.held_fresh {
            // The time spent holding the tick was ours, not the controller's.
            self.fresh_at = now;
        }
        self.hub_at = now;
    }

    /// Checks the timers: stops for sources gone quiet, repeats Hellos and stops.
    pub fn poll(&mut self, now: Duration) {
        self.check(now);
        if self.port_open
            && let Some(due) = self.hello_due
            && now >= due
        {
            self.say_hello(now);
        }
        if let Some(s) = self.stopping {
            if now.saturating_sub(s.started) >= STOP_REPEAT_FOR {
                self.stopping = None;
                self.out.push(Output::StopUnacknowledged(s.cause));
            } else if now.saturating_sub(s.last_sent) >= STOP_REPEAT_EVERY {
                self.send_stop(s.cause);
                self.stopping = Some(Stopping { last_sent: now, ..s });
            }
        }
    }

    /// Stops the chair for good (whether or not it was driven): the stop is sent at once and
    /// repeated until acknowledged or for 1 s; [`Safety::shutdown_done`] says when it is over.
    pub fn shutdown(&mut self, now: Duration, cause: StopCause) {
        if self.shutdown.is_some() {
            return;
        }
        self.shutdown = Some(cause);
        self.hello_due = None;
        self.start_stop(now, cause);
    }

    /// Whether a shutdown's stop is over: acknowledged, given up on after 1 s, or impossible
    /// (the port is closed).
    pub fn shutdown_done(&self) -> bool {
        self.shutdown.is_some() && (self.stopping.is_none() || !self.port_open)
    }

    /// Whether the board is known and talking: the port is open, a BoardInfo came, and it
    /// has not gone quiet.
    pub fn link_up(&self, now: Duration) -> bool {
        self.port_open && self.board_known && !self.board_quiet(now)
    }

    /// Whether a BoardInfo arrived since the port opened.
    pub fn board_known(&self) -> bool {
        self.board_known
    }

    /// Whether a stepped step went unanswered and nothing came since.
    pub fn stepped_silent(&self) -> bool {
        self.step_unanswered
    }

    /// Whether the chair may be moving by our last command.
    pub fn engaged(&self) -> bool {
        self.engaged
    }

    /// Why the chair must not be driven now, the most fundamental cause first.
    pub fn fault(&self, now: Duration) -> Option<StopCause> {
        let quiet = |since: Duration, after: Duration| now.saturating_sub(since) > after;
        if let Some(cause) = self.shutdown {
            Some(cause)
        } else if self.motor_fault {
            Some(StopCause::MotorFault)
        } else if !self.port_open {
            Some(StopCause::PortGone)
        } else if self.board_quiet(now) {
            Some(StopCause::BoardQuiet)
        } else if !self.holding && !self.held_still() && quiet(self.hub_at, self.hub_quiet_after) {
            Some(StopCause::HubQuiet)
        } else if !self.controlled {
            Some(StopCause::ControllerLost)
        } else if !self.holding && !self.held_still() && quiet(self.fresh_at, self.controller_quiet_after) {
            Some(StopCause::ControllerQuiet)
        } else {
            None
        }
    }

    /// Whether the board proved to be the chair emulator (it sent a SimTruth).
    pub fn emulated(&self) -> bool {
        self.emulated
    }

    /// Whether the chair cannot move while we do not step it: a stepped board that proved to
    /// be an emulator (only an emulator sends SimTruth). Its clock moves only on our steps,
    /// once per tick, so a hub or controller that is slow in lock-step (a long plan) moves
    /// nothing and is no reason to stop. A real board never sends SimTruth, so with a real
    /// chair these rules always hold, `--stepped` or not.
    fn held_still(&self) -> bool {
        self.stepped && self.emulated
    }

    fn board_quiet(&self, now: Duration) -> bool {
        if self.stepped {
            // A stepped board speaks only when stepped: between ticks its silence is normal.
            self.step_unanswered
        } else {
            now.saturating_sub(self.last_frame) > self.board_quiet_after
        }
    }

    fn check(&mut self, now: Duration) {
        if self.engaged
            && let Some(cause) = self.fault(now)
        {
            self.start_stop(now, cause);
        }
    }

    fn start_stop(&mut self, now: Duration, cause: StopCause) {
        self.engaged = false;
        self.held = Some(cause);
        self.awaiting_said = false;
        self.out.push(Output::Stop(cause));
        if self.port_open {
            self.send_stop(cause);
            self.stopping = Some(Stopping { cause, started: now, last_sent: now });
            self.latched = Some(cause);
        }
    }

    fn send_stop(&mut self, cause: StopCause) {
        // Zero powers first: a board that drops the EmergencyStop (a corrupted byte) still
        // gets a command that stops it.
        self.send(Message::MotorPowers(MotorPowers::default()));
        self.send(Message::EmergencyStop(EmergencyStop { reason: cause.reason() }));
    }

    fn say_hello(&mut self, now: Duration) {
        self.send(Message::Hello(self.hello));
        self.hello_due = Some(now + HELLO_EVERY);
    }

    fn send(&mut self, m: Message) {
        self.out.push(Output::Send(m));
    }
}

/// A hub motor power in [−1, 1] as per-mille of full power; NaN is no power.
pub fn permille(power: f32) -> i16 {
    if power.is_nan() {
        return 0;
    }
    // In range after the clamp, so the cast cannot saturate.
    (power.clamp(-1.0, 1.0) * f32::from(FULL_POWER)).round() as i16
}

#[cfg(test)]
mod tests {
    use super::*;
    use serial_protocol::{BoardInfo, BoardStatus, Sample, SimTruth, StopAck};

    const CF: u32 = DRIVE_CONTROLLED | DRIVE_FRESH;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    fn info() -> Message {
        Message::BoardInfo(BoardInfo { counts_per_rev: 2048, sample_period_ms: 100, ..BoardInfo::default() })
    }

    fn sends(s: &mut Safety) -> Vec<Message> {
        s.drain()
            .filter_map(|o| match o {
                Output::Send(m) => Some(m),
                _ => None,
            })
            .collect()
    }

    fn powers(l: i16, r: i16) -> Message {
        Message::MotorPowers(MotorPowers { left_permille: l, right_permille: r })
    }

    fn estop(reason: StopReason) -> Message {
        Message::EmergencyStop(EmergencyStop { reason })
    }

    /// A real-time machine, connected and driving at 50 % since t = 0; the board sends a
    /// sample every 100 ms, the hub ticks every 100 ms, the last tick at `until`.
    fn driving(until: u64) -> Safety {
        let mut s = Safety::new(ms(0), false, Hello::default());
        s.port_opened(ms(0));
        s.frame(ms(0), &info());
        for t in (0..=until).step_by(100) {
            s.frame(ms(t), &Message::Sample(Sample::default()));
            s.tick(ms(t), [0.5, 0.5], CF);
            s.poll(ms(t));
        }
        s.drain().for_each(drop);
        s
    }

    /// Polls every 10 ms from `from` to `to`, the board sending a Status each time, and returns
    /// the first stop, when it came and what was sent with it.
    fn first_stop(s: &mut Safety, from: u64, to: u64) -> Option<(u64, StopCause, Vec<Message>)> {
        for t in (from..=to).step_by(10) {
            s.frame(ms(t), &Message::Status(BoardStatus::default()));
            s.poll(ms(t));
            let out: Vec<Output> = s.drain().collect();
            if let Some(cause) = out.iter().find_map(|o| if let Output::Stop(c) = o { Some(*c) } else { None }) {
                let sent = out.into_iter().filter_map(|o| if let Output::Send(m) = o { Some(m) } else { None });
                return Some((t, cause, sent.collect()));
            }
        }
        None
    }

    #[test]
    fn the_port_opening_says_hello_and_repeats_it_every_500_ms_until_a_board_info() {
        let mut s = Safety::new(ms(0), false, Hello { sample_period_ms: 100 });
        s.port_opened(ms(0));
        assert_eq!(sends(&mut s), vec![Message::Hello(Hello { sample_period_ms: 100 })]);
        s.poll(ms(499));
        assert_eq!(sends(&mut s), vec![]);
        s.poll(ms(500));
        assert_eq!(sends(&mut s), vec![Message::Hello(Hello { sample_period_ms: 100 })]);
        s.frame(ms(600), &info());
        assert_eq!(s.drain().collect::<Vec<_>>(), vec![Output::BoardReady]);
        s.poll(ms(1500));
        assert_eq!(sends(&mut s), vec![], "answered: no more Hellos");
        assert!(s.link_up(ms(600)));
    }

    #[test]
    fn fresh_control_is_forwarded_as_motor_powers_and_anything_else_as_a_heartbeat() {
        let mut s = Safety::new(ms(0), false, Hello::default());
        s.port_opened(ms(0));
        s.tick(ms(0), [0.5, 0.5], CF);
        assert_eq!(sends(&mut s), vec![Message::Hello(Hello::default()), Message::Heartbeat], "no BoardInfo yet");
        s.frame(ms(10), &info());
        s.frame(ms(100), &Message::Sample(Sample::default()));
        s.tick(ms(100), [0.5, -0.25], CF);
        assert_eq!(sends(&mut s), vec![powers(500, -250)]);
        s.frame(ms(200), &Message::Sample(Sample::default()));
        s.tick(ms(200), [0.5, -0.25], DRIVE_CONTROLLED);
        assert_eq!(sends(&mut s), vec![Message::Heartbeat], "stale powers are not forwarded");
        s.tick(ms(250), [f32::NAN, 7.0], CF);
        assert_eq!(sends(&mut s), vec![powers(0, 1000)], "NaN is no power, beyond ±1 is clamped");
        assert!(s.engaged());
    }

    #[test]
    fn without_a_controller_nothing_is_driven_and_nothing_needs_stopping() {
        let mut s = Safety::new(ms(0), false, Hello::default());
        s.port_opened(ms(0));
        s.frame(ms(10), &info());
        for t in (0..1000).step_by(100) {
            s.frame(ms(t), &Message::Sample(Sample::default()));
            s.tick(ms(t), [1.0, 1.0], 0);
            assert_eq!(sends(&mut s).last(), Some(&Message::Heartbeat));
        }
        assert_eq!(first_stop(&mut s, 1000, 3000), None, "the hub went quiet, but we never drove");
    }

    #[test]
    fn an_adapter_held_off_the_cpu_dates_ticks_from_their_publication_and_stops_nothing() {
        // Driving until 1000 ms; then this adapter is kept off the CPU for 600 ms while the hub,
        // the controller and the board go on. Waking at 1600 ms it reads the board's queued
        // frames and the newest tick, published 40 ms before: nothing went quiet.
        let mut s = driving(1000);
        for t in (1100..=1600).step_by(100) {
            s.frame(ms(t), &Message::Sample(Sample::default()));
        }
        s.tick_aged(ms(1600), ms(40), [0.5, 0.5], CF);
        s.poll(ms(1600));
        let out: Vec<Output> = s.drain().collect();
        assert!(!out.iter().any(|o| matches!(o, Output::Stop(_))), "a spurious stop: {out:?}");
        assert_eq!(out.last(), Some(&Output::Send(powers(500, 500))), "{out:?}");
        // A hub that really stopped at 1000 ms still stops the chair within 300 ms (its last
        // news of the controller goes stale first).
        let mut h = driving(1000);
        let (at, cause, _) = first_stop(&mut h, 1010, 1600).expect("a stop");
        assert!(at <= 1300 && matches!(cause, StopCause::HubQuiet | StopCause::ControllerQuiet), "{at} {cause:?}");
    }

    #[test]
    fn a_silent_board_is_stopped_with_zero_powers_then_an_emergency_stop_within_300_ms() {
        let mut s = driving(1000);
        // The board's last frame came at 1000 ms; the hub keeps ticking.
        let mut stopped = None;
        for t in (1010..=1400).step_by(10) {
            if t % 100 == 0 {
                s.tick(ms(t), [0.5, 0.5], CF);
            }
            s.poll(ms(t));
            let out: Vec<Output> = s.drain().collect();
            if let Some(i) = out.iter().position(|o| *o == Output::Stop(StopCause::BoardQuiet)) {
                stopped = Some((t, out[i + 1..].to_vec()));
                break;
            }
            assert!(!out.iter().any(|o| matches!(o, Output::Stop(_))), "{out:?}");
        }
        let (t, out) = stopped.expect("a stop");
        assert!((1200..=1220).contains(&t), "stopped at {t} ms");
        assert_eq!(
            out,
            vec![Output::Send(powers(0, 0)), Output::Send(estop(StopReason::LINK_LOST))],
            "zero powers, then the stop"
        );
        // No powers forwarded while the board is quiet.
        s.tick(ms(1300), [0.5, 0.5], CF);
        assert_eq!(sends(&mut s), vec![Message::Heartbeat]);
    }

    #[test]
    fn an_unacknowledged_stop_is_repeated_every_100_ms_for_1_s_then_given_up() {
        let mut s = driving(0);
        let (t0, cause, _) = first_stop(&mut s, 10, 500).expect("the hub went quiet");
        assert_eq!(cause, StopCause::HubQuiet);
        assert!((200..=220).contains(&t0), "{t0}");
        let mut repeats = Vec::new();
        let mut gave_up = None;
        for t in (t0 + 10..t0 + 1500).step_by(10) {
            // The board still talks (its samples keep the link up), but never acknowledges.
            s.frame(ms(t), &Message::Status(BoardStatus::default()));
            s.poll(ms(t));
            for o in s.drain() {
                match o {
                    Output::Send(Message::EmergencyStop(e)) => repeats.push((t, e.reason)),
                    Output::StopUnacknowledged(c) => gave_up = Some((t, c)),
                    _ => {}
                }
            }
        }
        let times: Vec<u64> = repeats.iter().map(|r| r.0 - t0).collect();
        assert_eq!(times, (1..10).map(|k| k * 100).collect::<Vec<_>>());
        assert!(repeats.iter().all(|r| r.1 == StopReason::HUB_LOST));
        assert_eq!(gave_up, Some((t0 + 1000, StopCause::HubQuiet)));
    }

    #[test]
    fn a_stop_ack_ends_the_repeats() {
        let mut s = driving(0);
        first_stop(&mut s, 10, 500).expect("stop");
        s.frame(ms(250), &Message::StopAck(StopAck { stop_seq: 3, reason: StopReason::HUB_LOST }));
        assert_eq!(s.drain().collect::<Vec<_>>(), vec![Output::StopAcked(StopCause::HubQuiet)]);
        for t in (260..2000).step_by(10) {
            s.poll(ms(t));
        }
        assert_eq!(sends(&mut s), vec![], "no repeats after the ack");
    }

    #[test]
    fn a_controller_that_detaches_is_a_stop_at_the_next_tick() {
        let mut s = driving(500);
        s.frame(ms(600), &Message::Sample(Sample::default()));
        s.tick(ms(600), [0.0, 0.0], 0);
        let out: Vec<Output> = s.drain().collect();
        assert_eq!(
            out,
            vec![
                Output::Stop(StopCause::ControllerLost),
                Output::Send(powers(0, 0)),
                Output::Send(estop(StopReason::CONTROLLER_LOST)),
                Output::Send(Message::Heartbeat),
            ]
        );
    }

    #[test]
    fn a_controller_that_stops_answering_is_stopped_250_ms_after_news_of_its_last_answer() {
        let mut s = driving(500);
        let mut stop = None;
        for t in (510..=900).step_by(10) {
            if t % 100 == 0 {
                s.frame(ms(t), &Message::Sample(Sample::default()));
                s.tick(ms(t), [0.5, 0.5], DRIVE_CONTROLLED);
            }
            s.poll(ms(t));
            if let Some(c) = s.drain().find_map(|o| if let Output::Stop(c) = o { Some(c) } else { None }) {
                stop = Some((t, c));
                break;
            }
        }
        // The block at 500 says the tick of 400 was answered; nothing after: stopped as soon
        // as that news is 250 ms old (the next 10 ms poll after 650).
        let (t, cause) = stop.expect("a stop");
        assert_eq!(cause, StopCause::ControllerQuiet);
        assert!((650..=670).contains(&t), "{t}");
    }

    #[test]
    fn a_healthy_controller_is_never_stopped_whatever_the_cycle_and_its_jitter() {
        for cycle in [20u64, 100, 200] {
            let mut s = Safety::new(ms(0), false, Hello::default()).with_cycle(ms(cycle));
            s.port_opened(ms(0));
            s.frame(ms(0), &info());
            // Ticks on the hub's grid, each late by up to 40 ms, each block saying the
            // previous tick was answered.
            let late = |k: u64| (k * 7 % 5) * 10;
            let mut k = 0;
            while k * cycle < 5000 {
                let t = k * cycle + late(k);
                s.tick(ms(t), [0.5, 0.5], CF);
                for p in (t..(k + 1) * cycle + late(k + 1)).step_by(5) {
                    // The board samples every 100 ms on its own clock.
                    if p % 100 == 0 {
                        s.frame(ms(p), &Message::Sample(Sample::default()));
                    }
                    s.poll(ms(p));
                }
                k += 1;
            }
            let stops: Vec<Output> = s.drain().filter(|o| matches!(o, Output::Stop(_))).collect();
            assert!(stops.is_empty(), "cycle {cycle} ms: {stops:?}");
        }
    }

    #[test]
    fn with_auto_resume_a_stop_whose_cause_cleared_is_followed_by_a_hello_and_driving() {
        let mut s = driving(500).with_auto_resume(true);
        s.frame(ms(600), &Message::Sample(Sample::default()));
        s.tick(ms(600), [0.5, 0.5], DRIVE_CONTROLLED);
        s.poll(ms(710));
        assert!(s.drain().any(|o| o == Output::Stop(StopCause::ControllerQuiet)));
        s.frame(ms(720), &Message::StopAck(StopAck::default()));
        s.drain().for_each(drop);
        // The controller answers again: Hello, not motor powers, while the board is latched.
        s.frame(ms(800), &Message::Sample(Sample::default()));
        s.tick(ms(800), [0.5, 0.5], CF);
        let out: Vec<Output> = s.drain().collect();
        assert_eq!(
            out,
            vec![Output::Resume(StopCause::ControllerQuiet), Output::Send(Message::Hello(Hello::default()))]
        );
        s.tick(ms(900), [0.5, 0.5], CF);
        assert_eq!(sends(&mut s), vec![Message::Heartbeat], "still waiting for the BoardInfo");
        s.frame(ms(910), &info());
        assert_eq!(s.drain().collect::<Vec<_>>(), vec![Output::BoardReady]);
        s.frame(ms(1000), &Message::Sample(Sample::default()));
        s.tick(ms(1000), [0.5, 0.5], CF);
        assert_eq!(sends(&mut s), vec![powers(500, 500)]);
    }

    #[test]
    fn a_motor_fault_stops_the_chair_and_keeps_it_stopped() {
        let mut s = driving(300);
        let faulty = Sample { flags: StatusFlags::MOTOR_FAULT, ..Sample::default() };
        s.frame(ms(350), &Message::Sample(faulty));
        assert_eq!(s.drain().next(), Some(Output::Stop(StopCause::MotorFault)));
        s.frame(ms(360), &Message::StopAck(StopAck::default()));
        for t in (400..2000).step_by(100) {
            s.frame(ms(t), &Message::Sample(Sample::default()));
            s.tick(ms(t), [0.5, 0.5], CF);
        }
        assert!(!sends(&mut s).iter().any(|m| matches!(m, Message::MotorPowers(_) | Message::Hello(_))));
    }

    #[test]
    fn a_lost_port_records_the_stop_and_a_new_port_starts_with_a_hello() {
        let mut s = driving(300);
        s.port_lost(ms(350));
        assert_eq!(s.drain().collect::<Vec<_>>(), vec![Output::Stop(StopCause::PortGone)], "nothing can be sent");
        s.tick(ms(400), [0.5, 0.5], CF);
        assert_eq!(sends(&mut s), vec![], "no port, nothing sent");
        s.port_opened(ms(450));
        assert_eq!(sends(&mut s), vec![Message::Hello(Hello::default())]);
        s.frame(ms(460), &info());
        // The new board's latch is clear, but the stop is the host's to lift.
        s.tick(ms(500), [0.5, 0.5], CF);
        assert_eq!(
            s.drain().collect::<Vec<_>>(),
            vec![Output::BoardReady, Output::AwaitingResume(StopCause::PortGone), Output::Send(Message::Heartbeat)]
        );
        s.tick(ms(600), [0.5, 0.5], CF | RESUME);
        assert_eq!(
            s.drain().collect::<Vec<_>>(),
            vec![Output::Resume(StopCause::PortGone), Output::Send(powers(500, 500))],
            "resumed: the board was said Hello when the port opened, so it drives at once"
        );
    }

    /// A block saying the operator asked for one resume (the hub's count moved from 0 to 1).
    const RESUME: u32 = 1 << ipc_types::DRIVE_RESUMES_SHIFT;

    #[test]
    fn a_stop_whose_causes_cleared_holds_the_chair_until_the_operator_resumes_it() {
        // A controller that stopped answering is stopped (acknowledged at 720 ms), and answers
        // again from 800 ms.
        let mut s = driving(500);
        s.frame(ms(600), &Message::Sample(Sample::default()));
        s.tick(ms(600), [0.5, 0.5], DRIVE_CONTROLLED);
        s.poll(ms(710));
        assert!(s.drain().any(|o| o == Output::Stop(StopCause::ControllerQuiet)));
        s.frame(ms(720), &Message::StopAck(StopAck::default()));
        s.drain().for_each(drop);
        // Every cause has cleared, for as long as you like: the chair is not driven, and the
        // wait is said once.
        let mut out = Vec::new();
        for t in (800..3000).step_by(100) {
            s.frame(ms(t), &Message::Sample(Sample::default()));
            s.tick(ms(t), [0.5, 0.5], CF);
            s.poll(ms(t + 50));
            out.extend(s.drain());
        }
        assert_eq!(out.iter().filter(|o| **o == Output::AwaitingResume(StopCause::ControllerQuiet)).count(), 1);
        assert!(
            out.iter().all(|o| matches!(o, Output::AwaitingResume(_) | Output::Send(Message::Heartbeat))),
            "nothing but heartbeats while held: {out:?}"
        );
        // The operator's word: Hello clears the board's latch, then the powers flow.
        s.frame(ms(3000), &Message::Sample(Sample::default()));
        s.tick(ms(3000), [0.5, 0.5], CF | RESUME);
        assert_eq!(
            s.drain().collect::<Vec<_>>(),
            vec![Output::Resume(StopCause::ControllerQuiet), Output::Send(Message::Hello(Hello::default()))]
        );
        s.frame(ms(3010), &info());
        s.frame(ms(3100), &Message::Sample(Sample::default()));
        s.tick(ms(3100), [0.5, 0.5], CF | RESUME);
        assert_eq!(sends(&mut s), vec![powers(500, 500)]);
    }

    #[test]
    fn a_resume_asked_while_a_cause_holds_is_refused_and_not_kept_for_later() {
        let mut s = driving(500);
        s.frame(ms(600), &Message::Sample(Sample::default()));
        s.tick(ms(600), [0.0, 0.0], 0);
        assert!(s.drain().any(|o| o == Output::Stop(StopCause::ControllerLost)));
        s.frame(ms(610), &Message::StopAck(StopAck::default()));
        // Asked while no agent controls the chair: refused.
        s.frame(ms(700), &Message::Sample(Sample::default()));
        s.tick(ms(700), [0.0, 0.0], RESUME);
        let out: Vec<Output> = s.drain().collect();
        assert!(out.contains(&Output::ResumeRefused(StopCause::ControllerLost)), "{out:?}");
        // A controller attaches (the count stays where it was): still held.
        for t in (800..1500).step_by(100) {
            s.frame(ms(t), &Message::Sample(Sample::default()));
            s.tick(ms(t), [0.5, 0.5], CF | RESUME);
        }
        let out: Vec<Output> = s.drain().collect();
        assert!(
            !out.iter()
                .any(|o| matches!(o, Output::Resume(_) | Output::Send(Message::MotorPowers(_) | Message::Hello(_)))),
            "a refused resume came back by itself: {out:?}"
        );
        assert!(out.contains(&Output::AwaitingResume(StopCause::ControllerLost)), "{out:?}");
        // Asked again, now that it has cleared.
        s.tick(ms(1500), [0.5, 0.5], CF | (2 * RESUME));
        assert!(s.drain().any(|o| o == Output::Resume(StopCause::ControllerLost)));
    }

    #[test]
    fn requests_made_before_the_adapter_started_are_not_a_resume() {
        let mut s = Safety::new(ms(0), false, Hello::default());
        s.port_opened(ms(0));
        s.frame(ms(0), &info());
        // The hub's count is already 5 at the first tick: nothing to compare it with.
        for t in (0..=500).step_by(100) {
            s.frame(ms(t), &Message::Sample(Sample::default()));
            s.tick(ms(t), [0.5, 0.5], CF | (5 * RESUME));
        }
        s.frame(ms(600), &Message::Sample(Sample::default()));
        s.tick(ms(600), [0.5, 0.5], DRIVE_CONTROLLED | (5 * RESUME));
        s.poll(ms(710));
        s.frame(ms(720), &Message::StopAck(StopAck::default()));
        s.drain().for_each(drop);
        s.frame(ms(800), &Message::Sample(Sample::default()));
        s.tick(ms(800), [0.5, 0.5], CF | (5 * RESUME));
        assert_eq!(
            s.drain().collect::<Vec<_>>(),
            vec![Output::AwaitingResume(StopCause::ControllerQuiet), Output::Send(Message::Heartbeat)]
        );
    }

    #[test]
    fn shutdown_always_stops_and_is_done_at_the_ack_or_after_1_s() {
        let mut s = Safety::new(ms(0), false, Hello::default());
        s.port_opened(ms(0));
        s.frame(ms(10), &info());
        s.drain().for_each(drop);
        assert!(!s.shutdown_done());
        s.shutdown(ms(50), StopCause::Shutdown);
        assert_eq!(sends(&mut s), vec![powers(0, 0), estop(StopReason::HOST_SHUTDOWN)], "never drove, stops anyway");
        assert!(!s.shutdown_done());
        s.frame(ms(60), &Message::StopAck(StopAck::default()));
        assert!(s.shutdown_done());

        let mut s = driving(100);
        s.shutdown(ms(150), StopCause::HubGone);
        assert_eq!(sends(&mut s).last(), Some(&estop(StopReason::HUB_LOST)));
        s.poll(ms(1149));
        assert!(!s.shutdown_done());
        s.poll(ms(1150));
        assert!(s.shutdown_done(), "given up after 1 s");

        let mut s = Safety::new(ms(0), false, Hello::default());
        s.shutdown(ms(0), StopCause::Shutdown);
        assert!(s.shutdown_done(), "no port: nothing to wait for");
    }

    #[test]
    fn in_stepped_mode_the_board_is_judged_per_step_and_a_held_tick_does_not_count_as_hub_silence() {
        let mut s = Safety::new(ms(0), true, Hello { sample_period_ms: 100 });
        s.port_opened(ms(0));
        s.frame(ms(1), &info());
        s.tick(ms(2), [0.5, 0.5], CF);
        assert_eq!(sends(&mut s).last(), Some(&powers(500, 500)));
        // The tick is held while the step's sample is awaited, however long the wait.
        s.poll(ms(900));
        assert_eq!(s.drain().next(), None, "holding a tick: neither the hub nor the board is late");
        s.frame(ms(901), &Message::Sample(Sample::default()));
        s.answered(ms(901));
        // A paused hub: no steps, no samples, and only the hub's silence counts.
        let mut paused = s.clone();
        let (t, cause, sent) = first_stop(&mut paused, 910, 2000).expect("a stop");
        assert_eq!((t, cause), (1110, StopCause::HubQuiet));
        assert_eq!(sent, vec![powers(0, 0), estop(StopReason::HUB_LOST)]);
        // ... unless the board is the emulator (it sent a SimTruth): its clock is held with
        // the hub's, nothing moves, and a long pause of a lock-step run is no reason to stop.
        s.frame(ms(901), &Message::SimTruth(SimTruth::default()));
        assert_eq!(first_stop(&mut s, 910, 5000), None);

        let mut s = Safety::new(ms(0), true, Hello::default());
        s.port_opened(ms(0));
        s.frame(ms(1), &info());
        s.tick(ms(2), [0.5, 0.5], CF);
        s.drain().for_each(drop);
        s.step_unanswered(ms(1002));
        assert_eq!(s.drain().next(), Some(Output::Stop(StopCause::BoardQuiet)));
        assert!(!s.link_up(ms(1002)));
        s.frame(ms(1003), &Message::Sample(Sample::default()));
        assert!(s.link_up(ms(1003)));
    }

    #[test]
    fn per_mille_rounds_and_clamps() {
        assert_eq!([permille(0.5), permille(-0.2504), permille(2.0), permille(-9.0)], [500, -250, 1000, -1000]);
        assert_eq!(permille(f32::NAN), 0);
    }
}
