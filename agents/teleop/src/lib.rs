//! The teleop agent: drive one chair from a terminal with the arrow keys (or WASD) and watch
//! its sensor readings.
//!
//! The logic is [`Teleop`], fed with key bytes and ticks, which tests drive without a hub or a
//! terminal:
//!
//! ```
//! use teleop::Teleop;
//! use agent_sdk::Tick;
//! use ipc_types::RunState;
//!
//! let mut t = Teleop::new(7);
//! // Three Up presses (one arrow split across two reads) and a left turn.
//! assert!(!t.on_keys(b"w\x1b[").quit);
//! assert!(!t.on_keys(b"Aw\x1bOD").quit);
//! let tick = Tick { tick: 1, sim_time_s: 0.1, run_state: RunState::Running, latency_ns: 0, lockstep: false };
//! let action = t.on_tick(tick, &[]).expect("a running tick is answered");
//! assert_eq!((action.robot_id, action.motors), (7, [0.2, 0.4]));
//! assert!(t.on_keys(b" q").quit);
//! ```
//!
//! [`run`] is the process: it registers the chair through the agent SDK, switches a terminal
//! on stdin to raw input (restored on every way out, panics included, by [`term::RawMode`]),
//! then `poll(2)`s stdin and the hub's tick doorbell, answering every tick with the current
//! powers and redrawing the status at most ten times a second.
#![warn(missing_docs)]

pub mod drive;
pub mod keys;
pub mod term;
pub mod view;

use std::io::Write as _;
use std::os::fd::AsRawFd as _;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use agent_sdk::cli::{BodyArgs, CommonArgs, RobotArgs};
use agent_sdk::logs::RobotLogs;
use agent_sdk::{Agent, AgentError, Tick};
use anyhow::Context as _;
use ipc_types::{ActionBlock, RobotRegistration, RunState, SensorBlock};

use crate::drive::Drive;
use crate::keys::{Key, KeyParser};
use crate::view::{Screen, Status};

/// The help text after the options. (The one-line about comes from the subcommand's doc comment
/// in the root `cli.rs`, which also overrides a long about set here, so the details go after.)
const AFTER_HELP: &str = "\
Registers one chair with the hub of --session and answers every tick with the powers chosen
from the keyboard, while a status block shows the tick, the run state, the speed, turn and wheel
powers, the pose, GPS and compass (when the hub provides them), every proximity reading with a
bar, and the collision flag. Plain ANSI only: works in any terminal and under tmux or screen.

Keys:
  Up    or w    faster: +1 step of speed (full power is 1.0)
  Down  or s    slower, then reverse: -1 step (down to -1.0)
  Left  or a    steer left: +1 step of turn (right wheel up, left wheel down)
  Right or d    steer right: -1 step of turn
  space         stop: speed and turn to 0
  + / -         larger / smaller step (0.01 … 0.5; starts at 0.1)
  r             resume a physical chair after a stop: its adapter holds every stop until
                the operator's word, and drives on once every cause has cleared
  q or Ctrl-C   quit (the chair leaves the world)

Wheel powers are speed - turn (left) and speed + turn (right), each clamped to [-1, 1].

When stdin is not a terminal (a pipe, a script) the same keys are read from it as bytes and
end of input quits; when stdout is not a terminal, a status line is printed per change instead
of the redrawn block.";

/// Options of `iwsim agent teleop`.
#[derive(Debug, clap::Args, Clone)]
#[command(after_help = AFTER_HELP)]
#[command(mut_arg("log", |a| a.help(
    "Write the chair's log (one CSV line per tick: sensors, pose, powers) into this folder"
)))]
#[command(mut_arg("connect_timeout", |a| a.value_name("CONNECT_TIMEOUT")))]
pub struct TeleopArgs {
    /// `--session`, `--connect-timeout`, `--log` (the chair's log, one CSV line per tick).
    #[command(flatten)]
    pub common: CommonArgs,
    /// `--name`, `--id`, `--pose`.
    #[command(flatten)]
    pub robot: RobotArgs,
    /// `--width`, `--height`, `--com`.
    #[command(flatten)]
    pub body: BodyArgs,
    /// Top speed at full power, m/s.
    #[arg(long, default_value_t = 0.49)]
    pub max_speed: f64,
    /// Acceleration curve: the motor filter's memory per tick, [0, 1) (higher is smoother).
    #[arg(long, default_value_t = 0.83)]
    pub accel_curve: f64,
}

/// What a batch of key bytes did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct KeysOutcome {
    /// The speed, turn or step changed.
    pub changed: bool,
    /// The driver asked to leave; keys after the quit key were not applied.
    pub quit: bool,
    /// The driver asked to resume the chair after a stop (`r`).
    pub resume: bool,
}

/// The teleop without I/O: key bytes in, motor actions out.
#[derive(Debug, Clone)]
pub struct Teleop {
    robot_id: u32,
    drive: Drive,
    parser: KeyParser,
    keys: Vec<Key>,
    tick: Option<Tick>,
    block: Option<SensorBlock>,
    notice: Option<String>,
}

impl Teleop {
    /// A stopped chair with robot id `robot_id`.
    pub fn new(robot_id: u32) -> Self {
        Self {
            robot_id,
            drive: Drive::new(),
            parser: KeyParser::new(),
            keys: Vec::new(),
            tick: None,
            block: None,
            notice: None,
        }
    }

    /// Applies the keys in `bytes` (a read from the keyboard; sequences may be split across
    /// reads).
    pub fn on_keys(&mut self, bytes: &[u8]) -> KeysOutcome {
        let mut out = KeysOutcome::default();
        self.keys.clear();
        self.parser.feed(bytes, &mut self.keys);
        for &k in &self.keys {
            match k {
                Key::Quit => {
                    out.quit = true;
                    break;
                }
                Key::Resume => out.resume = true,
                _ => out.changed |= self.drive.apply(k),
            }
        }
        out
    }

    /// Drops a half-typed escape sequence (a lone ESC the terminal sent long ago).
    pub fn on_idle_keyboard(&mut self) {
        self.parser.reset();
    }

    /// Whether an escape sequence is half read.
    pub fn keys_pending(&self) -> bool {
        self.parser.pending()
    }

    /// Takes a tick and this agent's sensor blocks; the answer to send, or `None` when the
    /// run has finished (nothing to answer).
    pub fn on_tick(&mut self, tick: Tick, blocks: &[SensorBlock]) -> Option<ActionBlock> {
        self.tick = Some(tick);
        if let Some(b) = blocks.iter().find(|b| b.robot_id == self.robot_id) {
            self.block = Some(*b);
        }
        if tick.run_state == RunState::Finished {
            return None;
        }
        let [l, r] = self.drive.powers();
        Some(ActionBlock::motors(self.robot_id, l, r))
    }

    /// The driver's command.
    pub fn drive(&self) -> &Drive {
        &self.drive
    }

    /// The last tick.
    pub fn tick(&self) -> Option<Tick> {
        self.tick
    }

    /// The chair's last sensor block.
    pub fn block(&self) -> Option<&SensorBlock> {
        self.block.as_ref()
    }

    /// What the display shows.
    pub fn status<'a>(&'a self, name: &'a str, session: &'a str) -> Status<'a> {
        Status {
            name,
            robot_id: self.robot_id,
            session,
            tick: self.tick,
            block: self.block.as_ref(),
            drive: &self.drive,
            notice: self.notice.as_deref(),
        }
    }

    /// Shows what the last resume request came to.
    pub fn set_notice(&mut self, notice: String) {
        self.notice = Some(notice);
    }
}

/// Why the drive loop ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum End {
    /// `q` or Ctrl-C.
    Quit,
    /// The hub ended the run.
    RunOver,
    /// SIGINT or SIGTERM.
    Interrupted,
    /// End of input on stdin (a pipe closed, a terminal hung up).
    InputClosed,
}

impl End {
    fn message(self) -> &'static str {
        match self {
            End::Quit => "left by the driver",
            End::RunOver => "the hub ended the run",
            End::Interrupted => "stopped by a termination signal",
            End::InputClosed => "end of keyboard input",
        }
    }
}

/// Redraws at most this often on a terminal.
const FRAME_INTERVAL: Duration = Duration::from_millis(100);
/// Prints a status line at most this often when stdout is not a terminal (key presses print
/// at once).
const LINE_INTERVAL: Duration = Duration::from_secs(1);
/// Longest wait in `poll` when nothing is due: the hub's liveness is checked this often.
const IDLE_WAIT: Duration = Duration::from_millis(100);
/// An escape byte with nothing after it for this long was a lone ESC key.
const ESC_TIMEOUT: Duration = Duration::from_millis(100);

/// The status output: a block redrawn in place on a terminal, lines otherwise.
struct Display {
    screen: Option<Screen>,
    last_draw: Option<Instant>,
    dirty: bool,
    urgent: bool,
    last_line_key: String,
}

impl Display {
    fn new(terminal: bool) -> Self {
        Self {
            screen: terminal.then(Screen::default),
            last_draw: None,
            dirty: true,
            urgent: false,
            last_line_key: String::new(),
        }
    }

    fn interval(&self) -> Duration {
        if self.screen.is_some() { FRAME_INTERVAL } else { LINE_INTERVAL }
    }

    /// How long until a pending redraw is due (`IDLE_WAIT` if none is pending).
    fn wait_hint(&self, now: Instant) -> Duration {
        if !self.dirty {
            return IDLE_WAIT;
        }
        if self.urgent && self.screen.is_none() {
            return Duration::ZERO;
        }
        match self.last_draw {
            None => Duration::ZERO,
            Some(t) => (t + self.interval()).saturating_duration_since(now).min(IDLE_WAIT),
        }
    }

    /// Draws if something changed and the rate allows (or `force`).
    fn draw(&mut self, s: &Status, now: Instant, force: bool) {
        if !force && (!self.dirty || self.wait_hint(now) > Duration::ZERO) {
            return;
        }
        let text = match &mut self.screen {
            Some(screen) => screen.frame(&view::screen_lines(s)),
            None => {
                // Print a line only when something besides the clock changed.
                let timeless =
                    Status { tick: s.tick.map(|t| Tick { tick: 0, sim_time_s: 0.0, latency_ns: 0, ..t }), ..*s };
                let key = view::status_line(&timeless);
                if key == self.last_line_key && !force {
                    self.dirty = false;
                    return;
                }
                self.last_line_key = key;
                view::status_line(s) + "\n"
            }
        };
        // A display that cannot be written (a closed pipe) must not stop the driving.
        let mut out = std::io::stdout().lock();
        let _ = out.write_all(text.as_bytes()).and_then(|()| out.flush());
        self.last_draw = Some(now);
        self.dirty = false;
        self.urgent = false;
    }

    /// Leaves the terminal as it was found (cursor shown, below the block) and says why the
    /// teleop ended.
    fn close(&mut self, message: &str) {
        // A raw terminal may not translate "\n"; a pipe or a file wants no "\r".
        let (tail, newline) = self.screen.as_mut().map_or(("", "\n"), |s| (s.finish(), "\r\n"));
        let mut out = std::io::stdout().lock();
        let _ = write!(out, "{tail}iwsim agent teleop: {message}{newline}").and_then(|()| out.flush());
    }
}

impl Drop for Display {
    fn drop(&mut self) {
        // On an error or a panic, at least give the cursor back.
        if let Some(tail) = self.screen.as_mut().map(Screen::finish)
            && !tail.is_empty()
        {
            let mut out = std::io::stdout().lock();
            let _ = out.write_all(tail.as_bytes()).and_then(|()| out.flush());
        }
    }
}

/// Asks the hub to resume chair `robot_id` after a latched stop; says what came of it.
fn resume(session: &str, robot_id: u32) -> String {
    match agent_sdk::control(session, ipc_types::Command::ResumeChair, robot_id) {
        Ok(a) if a.status == 0 => "resume asked: the chair drives on once every cause of its stop has cleared".into(),
        Ok(a) if a.status == 3 => "resume: this robot is simulated, it has no stop to resume".into(),
        Ok(a) => format!("resume refused by the hub (status {})", a.status),
        Err(e) => format!("resume not sent: {e}"),
    }
}

/// Runs the agent until the driver quits, the run ends or the hub goes away (an error).
pub fn run(args: &TeleopArgs) -> anyhow::Result<ExitCode> {
    let mut agent =
        args.common.connect("teleop").with_context(|| format!("cannot join session {:?}", args.common.hub.session))?;
    // Close the agent on every path, errors included: the last process of a session removes
    // its files, even when the hub died first.
    let result = drive(&mut agent, args);
    agent.close();
    result
}

fn registration(args: &TeleopArgs) -> RobotRegistration {
    let b = args.body;
    RobotRegistration::new(&args.robot.name)
        .id(args.robot.id)
        .body(b.width, b.height, b.com)
        .motors(args.max_speed, args.accel_curve)
        .at(args.robot.pose)
}

fn drive(agent: &mut Agent, args: &TeleopArgs) -> anyhow::Result<ExitCode> {
    let id = agent.register(&registration(args)).context("the hub did not take the chair")?;
    agent.ready().context("the hub did not take the ready message")?;

    let stdin = std::io::stdin();
    let stdin_fd = stdin.as_raw_fd();
    // Declared before the display, so it is dropped after it: the last frame and the cursor
    // go out while the terminal is still raw, then the original mode comes back.
    let _raw = if term::is_tty(&stdin) {
        Some(term::RawMode::enter(&stdin).context("cannot switch the terminal to raw input")?)
    } else {
        None
    };
    let mut display = Display::new(term::is_tty(std::io::stdout()));
    let mut teleop = Teleop::new(id);
    let mut logs = RobotLogs::new(args.common.log.as_deref());
    logs.add(id, &args.robot.name);

    let end = drive_loop(agent, args, stdin_fd, &mut teleop, &mut display, &mut logs);
    // The run's final tick when the hub ended the run; what was logged in any case.
    logs.finish(agent).context("cannot write the log")?;
    let end = end?;
    display.draw(&teleop.status(&args.robot.name, &args.common.hub.session), Instant::now(), true);
    display.close(end.message());
    Ok(ExitCode::SUCCESS)
}

fn drive_loop(
    agent: &mut Agent,
    args: &TeleopArgs,
    stdin_fd: i32,
    teleop: &mut Teleop,
    display: &mut Display,
    logs: &mut RobotLogs,
) -> anyhow::Result<End> {
    let mut keyboard = Some(stdin_fd);
    let mut buf = [0u8; 256];
    let mut last_input = Instant::now();
    loop {
        let now = Instant::now();
        let ready = term::poll_readable(keyboard, agent.tick_fd(), display.wait_hint(now))
            .context("cannot wait for the keyboard and the hub")?;
        if ready.first_invalid {
            // No stdin at all: drive on without a keyboard until the run ends.
            keyboard = None;
        }
        if ready.first {
            match term::read_some(std::io::stdin(), &mut buf) {
                Ok(0) => return Ok(End::InputClosed),
                Ok(n) => {
                    last_input = Instant::now();
                    let keys = teleop.on_keys(&buf[..n]);
                    if keys.quit {
                        return Ok(End::Quit);
                    }
                    if keys.resume {
                        teleop.set_notice(resume(agent.session(), teleop.robot_id));
                        display.dirty = true;
                        display.urgent = true;
                    }
                    if keys.changed {
                        display.dirty = true;
                        display.urgent = true;
                    }
                }
                Err(e) if matches!(e.kind(), std::io::ErrorKind::Interrupted | std::io::ErrorKind::WouldBlock) => {}
                // A terminal that hung up reads as EIO.
                Err(_) => return Ok(End::InputClosed),
            }
        } else if teleop.keys_pending() && last_input.elapsed() >= ESC_TIMEOUT {
            teleop.on_idle_keyboard();
        }

        // Read the hub before judging its liveness: its last tick may be waiting.
        match agent.try_tick() {
            Ok(Some(tick)) => {
                let action = teleop.on_tick(tick, agent.sensors());
                // The final tick (unanswered) is logged by `RobotLogs::finish`, as in every agent.
                if let Some(action) = action {
                    agent.send(tick.tick, &[action]).context("cannot send the powers to the hub")?;
                    if let Some(block) = teleop.block() {
                        logs.row(block, tick.sim_time_s, action.motors).context("cannot write the log")?;
                    }
                }
                display.dirty = true;
            }
            Ok(None) => {}
            Err(AgentError::Interrupted) => return Ok(End::Interrupted),
            Err(e) => return Err(e).context("the teleop lost its hub"),
        }
        if agent.finished() {
            return Ok(End::RunOver);
        }
        match agent.check_alive() {
            Ok(()) => {}
            Err(AgentError::Interrupted) => return Ok(End::Interrupted),
            Err(e) => return Err(e).context("the teleop lost its hub"),
        }
        display.draw(&teleop.status(&args.robot.name, &args.common.hub.session), Instant::now(), false);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ipc_types::REG_HAS_POSE;

    fn tick(n: u64, run_state: RunState) -> Tick {
        Tick { tick: n, sim_time_s: n as f64 * 0.02, run_state, latency_ns: 0, lockstep: false }
    }

    #[test]
    fn every_running_tick_is_answered_with_the_current_powers() {
        let mut t = Teleop::new(4);
        assert_eq!(t.on_tick(tick(1, RunState::Running), &[]), Some(ActionBlock::motors(4, 0.0, 0.0)));
        assert_eq!(t.on_keys(b"\x1b[A\x1b[A"), KeysOutcome { changed: true, quit: false, resume: false });
        assert_eq!(t.on_tick(tick(2, RunState::Running), &[]), Some(ActionBlock::motors(4, 0.2, 0.2)));
        t.on_keys(b"\x1b[C");
        assert_eq!(t.on_tick(tick(3, RunState::Paused), &[]), Some(ActionBlock::motors(4, 0.3, 0.1)));
        t.on_keys(b" ");
        assert_eq!(t.on_tick(tick(4, RunState::Running), &[]), Some(ActionBlock::motors(4, 0.0, 0.0)));
    }

    #[test]
    fn the_finished_tick_is_not_answered() {
        let mut t = Teleop::new(4);
        t.on_keys(b"w");
        assert_eq!(t.on_tick(tick(9, RunState::Finished), &[]), None);
        assert_eq!(t.tick().map(|t| t.run_state), Some(RunState::Finished));
    }

    #[test]
    fn keys_after_quit_are_not_applied() {
        let mut t = Teleop::new(1);
        assert_eq!(t.on_keys(b"wqw"), KeysOutcome { changed: true, quit: true, resume: false });
        assert_eq!(t.drive().speed(), 0.1);
        assert_eq!(t.on_keys(b"\x03"), KeysOutcome { changed: false, quit: true, resume: false });
    }

    #[test]
    fn r_asks_to_resume_and_changes_nothing_of_the_drive() {
        let mut t = Teleop::new(1);
        t.on_keys(b"ww");
        assert_eq!(t.on_keys(b"r"), KeysOutcome { changed: false, quit: false, resume: true });
        assert_eq!(t.drive().speed(), 0.2);
        t.set_notice("resume asked".into());
        let s = t.status("chair1", "demo");
        assert!(view::screen_lines(&s).iter().any(|l| l == "resume asked"));
        assert!(view::status_line(&s).ends_with("| resume asked"));
    }

    #[test]
    fn unknown_bytes_change_nothing() {
        let mut t = Teleop::new(1);
        assert_eq!(t.on_keys(b"xyz\x1b[H\r"), KeysOutcome::default());
    }

    #[test]
    fn the_registration_carries_every_option() {
        use clap::Parser as _;
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            args: TeleopArgs,
        }
        let cli = Cli::parse_from(["teleop", "--name", "bob", "--id", "3", "--pose", "-2,6.1,90", "--width", "0.8"]);
        let reg = registration(&cli.args);
        assert_eq!(reg.name.as_str(), Some("bob"));
        assert_eq!((reg.requested_id, reg.flags & REG_HAS_POSE, reg.pose), (3, REG_HAS_POSE, [-2.0, 6.1, 90.0]));
        assert_eq!((reg.width_m, reg.height_m, reg.com), (0.8, 1.0, 0.5));
        assert_eq!((reg.max_speed_mps, reg.accel_curve), (0.49, 0.83));
        let plain = registration(&Cli::parse_from(["teleop"]).args);
        assert_eq!((plain.flags & REG_HAS_POSE, plain.requested_id), (0, 0));
        assert_eq!(plain.name.as_str(), Some("chair1"));
        for junk in ["1,2", "1,2,x", "1,2,inf"] {
            assert!(Cli::try_parse_from(["teleop", "--pose", junk]).is_err(), "{junk}");
        }
    }
}
