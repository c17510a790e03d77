//! `iwsim serial`: the chair adapter. It joins a physical wheelchair — its acquisition board on
//! an RS232 port, speaking `docs/serial-protocol.md` — to a hub's world as a Real robot: it
//! registers the chair (`REG_CHAIR`, the body and sensors of `sim_model::chair`), forwards the
//! controlling agent's motor powers to the board, integrates the board's encoder counts into an
//! odometry pose, map-matches it to the walls its real sensors see ([`localise`]) and pushes it
//! every tick, and reports the board's real range readings, its
//! encoders and (from an emulator) the chair's true pose. Above all it stops the chair when
//! anything it depends on goes quiet (see [`safety`]).
//!
//! ```no_run
//! use std::sync::atomic::AtomicBool;
//! use clap::Parser as _;
//!
//! #[derive(clap::Parser)]
//! struct Cli {
//!     #[command(flatten)]
//!     serial: serial_bridge::SerialArgs,
//! }
//!
//! let cli = Cli::parse_from([
//!     "serial", "--device", "/dev/ttyUSB0", "--robot", "chair1", "--mode", "augmented", "--pose", "10,6.1,0",
//! ]);
//! static STOP: AtomicBool = AtomicBool::new(false);
//! let outcome = serial_bridge::run(cli.serial, &STOP).expect("a hub, a board");
//! println!("{outcome}");
//! ```
//!
//! The pieces, each testable alone: [`safety`] (the stop rule as a pure state machine),
//! [`odometry`] (wheel counts to a pose), [`localise`] (that pose map-matched to the walls the
//! real sensors see), [`readings`] (board readings to the hub's sensor
//! order), [`port`] (the serial port, the one module that knows the `serialport` crate) and
//! [`board`] (the serial side put together, driven by ticks without a hub).
//!
//! Adapters never link the hub or the world: the hub is reached through the agent SDK.
#![warn(missing_docs)]

pub mod board;
pub mod localise;
pub mod odometry;
pub mod port;
pub mod readings;
pub mod safety;

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use agent_sdk::cli::SessionArgs;
use agent_sdk::{Agent, AgentError};
use ipc_types::{FixedName, REG_CHAIR, RobotKind, RobotRegistration, SensorMode, SensorSpec};
use sim_model::{Pose, PoseDeg, chair};

pub use board::{BoardLink, LinkConfig, Outcome};
pub use localise::Localiser;
pub use port::{Port, PortOpenError};
pub use safety::StopCause;

/// Options of `iwsim serial`.
#[derive(Debug, Clone, PartialEq, clap::Args)]
#[command(long_about = "Joins a physical wheelchair to the hub's world: its acquisition board on a serial \
port (docs/serial-protocol.md) becomes a Real robot named --robot. The agent that registers a robot of \
the same name controls it; its motor powers are forwarded to the board, the board's encoder counts \
become the chair's odometry pose, and its sonar and IR readings reach the controller as --mode says. \
The chair is stopped when the hub, the controller or the board goes quiet for 200 ms, and on Ctrl-C.")]
#[command(mut_arg("session", |a| a.help("Session of the hub to join")))]
pub struct SerialArgs {
    /// `--session`, `--connect-timeout`.
    #[command(flatten)]
    pub hub: SessionArgs,
    /// The board's serial port (a pseudo-terminal's path works too, e.g. the chair
    /// emulator's).
    #[arg(long, value_name = "PATH")]
    pub device: PathBuf,
    /// Baud rate (8N1, no flow control).
    #[arg(long, default_value_t = 115_200, value_parser = clap::value_parser!(u32).range(1..))]
    pub baud: u32,
    /// The chair's name in the hub; its controlling agent registers the same name.
    #[arg(long, value_name = "NAME")]
    pub robot: String,
    /// Where the controlling agent's readings come from: the hub's virtual sensors, the
    /// chair's real ones, or per sensor the nearer of both.
    #[arg(long, value_enum)]
    pub mode: ModeArg,
    /// Where the chair stands on the hub's map at start, X,Y,DIR (metres, degrees): the
    /// odometry starts here. Kept in this wire form, which the registration carries as typed.
    #[arg(long, value_name = "X,Y,DIR", value_parser = agent_sdk::args::pose, allow_hyphen_values = true)]
    pub pose: PoseDeg,
    /// The board is a stepped chair emulator: each tick sends it a SimStep of the hub's cycle
    /// and waits (up to 1 s) for the sample it produces — with a lock-step hub, fast and
    /// deterministic runs.
    #[arg(long)]
    pub stepped: bool,
    /// Push the raw odometry pose: no map matching of the real readings against the map's
    /// walls (see `localise`), so the pose drifts as the wheels slip.
    #[arg(long)]
    pub odometry_only: bool,
    /// Drive on after a stop as soon as every cause has cleared. Without it a stop latches
    /// until the operator resumes the chair (`iwsim resume NAME`, or `r` in teleop): for
    /// emulated chairs and tests, never for a chair with someone in it.
    #[arg(long)]
    pub auto_resume: bool,
}

/// `--mode`: the chair's sensor mode (thesis §5.4.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ModeArg {
    /// The hub's virtual sensors on the chair's twin.
    Virtual,
    /// The chair's own sonars, IR sensors and encoders.
    Real,
    /// Per sensor, the nearer of the real and the virtual reading.
    Augmented,
}

impl ModeArg {
    /// The hub's name for the mode.
    pub fn wire(self) -> SensorMode {
        match self {
            ModeArg::Virtual => SensorMode::Virtual,
            ModeArg::Real => SensorMode::Real,
            ModeArg::Augmented => SensorMode::Augmented,
        }
    }
}

/// Why `iwsim serial` stopped with an error. The chair was told to stop first whenever the
/// port was open.
#[derive(Debug, thiserror::Error)]
pub enum SerialError {
    /// An option's value cannot be used.
    #[error("--{option}: {why}")]
    InvalidOption {
        /// The option, without dashes.
        option: &'static str,
        /// What is wrong with it.
        why: String,
    },
    /// The serial port could not be opened at start.
    #[error(transparent)]
    Open(#[from] PortOpenError),
    /// The hub could not be reached, refused the chair, or went away.
    #[error("{what}: {source}")]
    Hub {
        /// What the adapter was doing.
        what: String,
        /// The hub's answer or the failure.
        source: AgentError,
    },
    /// The hub removed the chair's robot (an operator's command).
    #[error("the hub removed the chair {name} (robot {id})")]
    Removed {
        /// The chair's name.
        name: String,
        /// Its robot id.
        id: u32,
    },
}

/// The chair as the adapter registers it: a Real robot with the chair's body, motors and
/// sensors, starting at `pose` (x, y metres, heading degrees), in sensor mode `mode`.
pub fn registration(name: &str, mode: SensorMode, pose: PoseDeg) -> RobotRegistration {
    let [length, width, com] = chair::BODY;
    let mut reg = RobotRegistration::new(name)
        .body(length, width, com)
        .motors(chair::MAX_SPEED_MPS, chair::ACCEL_CURVE)
        .at(Some(pose));
    reg.kind = RobotKind::Real as u32;
    reg.flags |= REG_CHAIR | mode.reg_flags();
    for (spec, m) in reg.sensors.iter_mut().zip(&chair::SENSORS) {
        *spec = SensorSpec { x_m: m.x_m, y_m: m.y_m, angle_deg: m.angle_deg, cone_deg: m.cone_deg, range_m: m.range_m };
    }
    reg.sensor_count = chair::SENSORS.len().min(reg.sensors.len()) as u32;
    reg
}

/// Runs the adapter until the run ends, `stop` is set, or SIGINT/SIGTERM arrives (the agent
/// SDK's iceoryx2 node catches both and reports them as [`AgentError::Interrupted`], so no
/// handler of the caller's is needed): the chair is stopped (until a StopAck, or 1 s), the
/// adapter leaves the hub and returns what it did. When the hub goes away for good, the chair
/// is stopped the same way and the error says so. Counters go to stderr at exit either way.
pub fn run(args: SerialArgs, stop: &AtomicBool) -> Result<Outcome, SerialError> {
    if FixedName::new(&args.robot).is_none_or(|n| n.as_str().is_none_or(str::is_empty)) {
        return Err(SerialError::InvalidOption {
            option: "robot",
            why: format!("{:?} is not a name of 1 to {} bytes", args.robot, ipc_types::NAME_BYTES - 1),
        });
    }
    if !args.pose.iter().all(|v| v.is_finite()) {
        return Err(SerialError::InvalidOption { option: "pose", why: format!("{:?} is not finite", args.pose) });
    }
    // The port first: a wrong path or a missing permission is told before the hub sees a chair.
    let port = Port::open(&args.device, args.baud)?;
    agent_sdk::report!("iwsim serial: opened {} at {} baud", args.device.display(), args.baud);
    let session = &args.hub.session;
    let mut agent = Agent::connect_within(session, &format!("serial-{}", std::process::id()), args.hub.timeout())
        .map_err(|source| SerialError::Hub { what: format!("connecting to the hub of session {session:?}"), source })?;
    // Close the agent on every path: the hub removes the chair, and the last process of a
    // session removes its files.
    let result = serve(&mut agent, port, &args, stop);
    agent.close();
    result
}

fn serve(agent: &mut Agent, port: Port, args: &SerialArgs, stop: &AtomicBool) -> Result<Outcome, SerialError> {
    let hub = |what: String| move |source| SerialError::Hub { what, source };
    let name = args.robot.as_str();
    let id = agent
        .register(&registration(name, args.mode.wire(), args.pose))
        .map_err(hub(format!("registering the chair {name}")))?;
    agent.ready().map_err(hub("joining the run".into()))?;
    let map = agent.map().map_err(hub("reading the hub's map".into()))?;
    let cfg = LinkConfig {
        device: args.device.clone(),
        baud: args.baud,
        stepped: args.stepped,
        cycle_ms: map.header.cycle_ms,
        hub_ticks_per_m: map.header.params.encoder_ticks_per_m,
        start: Pose::from_wire_deg(args.pose),
        robot: name.to_owned(),
        auto_resume: args.auto_resume,
    };
    agent_sdk::report!(
        "iwsim serial: chair {name} is robot {id} in session {:?} ({:?} sensors{}, {}), starting at {:?}; {}",
        args.hub.session,
        args.mode.wire(),
        if args.stepped { ", stepped board" } else { "" },
        if args.odometry_only { "odometry pose" } else { "odometry map-matched to the walls" },
        args.pose,
        if args.auto_resume { "stops lift when their causes clear" } else { "stops latch until the operator resumes" }
    );
    let mut board = BoardLink::new(cfg, port);
    if !args.odometry_only {
        board.localise(Localiser::new(&map));
    }
    let mut end: Option<Result<(), SerialError>> = None;
    loop {
        if end.is_none() {
            if stop.load(Ordering::Relaxed) {
                agent_sdk::report!("iwsim serial: asked to stop");
                end = Some(Ok(()));
                board.shutdown(StopCause::Shutdown);
            } else if let Err(e) = agent.check_alive() {
                end = Some(give_up(&mut board, e));
            }
        }
        // A hub that is still there gets its ticks answered even while the chair is being
        // stopped: in lock-step it waits for us. The tick waiting is taken before the timers
        // are checked (in `service`): an adapter the machine's load kept off the CPU for a
        // while must not take the hub for quiet when its ticks are queued, unread (issue 27,
        // fault 9: spurious stops under load). The board's frames are read first for the
        // same reason (`on_tick` and `service` both read before they judge).
        if !matches!(end, Some(Err(_))) {
            match agent.try_tick() {
                // The block is read where the hub wrote it; only the action leaves the borrow.
                Ok(Some(tick)) => {
                    match agent
                        .sensors()
                        .iter()
                        .find(|b| b.robot_id == id)
                        .map(|b| board.on_tick(tick.tick, Duration::from_nanos(tick.latency_ns), id, b))
                    {
                        Some(action) => {
                            if let Err(e) = agent.send(tick.tick, &[action]) {
                                end = Some(give_up(&mut board, e));
                            }
                        }
                        None if end.is_none() => {
                            board.shutdown(StopCause::HubGone);
                            end = Some(Err(SerialError::Removed { name: name.to_owned(), id }));
                        }
                        None => {}
                    }
                }
                Ok(None) if agent.finished() && end.is_none() => {
                    agent_sdk::report!("iwsim serial: the hub ended the run");
                    board.shutdown(StopCause::Shutdown);
                    end = Some(Ok(()));
                }
                Ok(None) => {}
                Err(e) if end.is_none() => end = Some(give_up(&mut board, e)),
                Err(_) => {}
            }
        }
        board.service();
        if end.is_some() && board.shutdown_done() {
            let outcome = board.outcome();
            agent_sdk::report!("iwsim serial: {outcome}");
            return match end {
                Some(Err(e)) => Err(e),
                _ => Ok(outcome),
            };
        }
        let fds = [agent.tick_fd(), board.fd().unwrap_or(-1)];
        port::wait_readable(&fds, board::LOOK_EVERY);
    }
}

/// The hub failed `e`: a termination signal ends the run cleanly, anything else (the hub's
/// process gone) is an error. Either way the chair is told to stop.
fn give_up(board: &mut BoardLink, e: AgentError) -> Result<(), SerialError> {
    if matches!(e, AgentError::Interrupted) {
        agent_sdk::report!("iwsim serial: interrupted");
        board.shutdown(StopCause::Shutdown);
        return Ok(());
    }
    agent_sdk::report!("iwsim serial: lost the hub: {e}");
    board.shutdown(StopCause::HubGone);
    Err(SerialError::Hub { what: "serving the chair".into(), source: e })
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser as _;
    use ipc_types::{REG_HAS_POSE, REG_SENSORS_AUGMENTED};

    #[derive(Debug, clap::Parser)]
    struct Cli {
        #[command(flatten)]
        serial: SerialArgs,
    }

    #[test]
    fn the_options_parse_and_the_required_ones_are_required() {
        let a = Cli::try_parse_from([
            "serial",
            "--device",
            "/dev/pts/7",
            "--robot",
            "chair1",
            "--mode",
            "real",
            "--pose",
            "10,6.1,-90",
        ])
        .expect("valid")
        .serial;
        assert_eq!((a.baud, a.mode, a.pose, a.stepped), (115_200, ModeArg::Real, [10.0, 6.1, -90.0], false));
        assert_eq!((a.hub.session.as_str(), a.device), ("default", PathBuf::from("/dev/pts/7")));
        let a = Cli::try_parse_from([
            "serial",
            "--device",
            "d",
            "--robot",
            "c",
            "--mode",
            "augmented",
            "--pose",
            "1,2,3",
            "--baud",
            "9600",
            "--stepped",
            "--session",
            "s",
        ])
        .expect("valid")
        .serial;
        assert_eq!(
            (a.baud, a.mode.wire(), a.stepped, a.hub.session.as_str()),
            (9600, SensorMode::Augmented, true, "s")
        );
        for missing in ["--device", "--robot", "--mode", "--pose"] {
            let mut argv = vec!["serial", "--device", "d", "--robot", "c", "--mode", "real", "--pose", "1,2,3"];
            let at = argv.iter().position(|a| *a == missing).expect("present");
            argv.drain(at..at + 2);
            let err = Cli::try_parse_from(argv).expect_err(missing).to_string();
            assert!(err.contains(missing), "{missing}: {err}");
        }
        assert!(
            Cli::try_parse_from(["serial", "--device", "d", "--robot", "c", "--mode", "dream", "--pose", "1,2,3"])
                .is_err()
        );
        assert!(
            Cli::try_parse_from(["serial", "--device", "d", "--robot", "c", "--mode", "real", "--pose", "1,2"])
                .is_err()
        );
        let zero = ["serial", "--device", "d", "--robot", "c", "--mode", "real", "--pose", "1,2,3", "--baud", "0"];
        assert!(Cli::try_parse_from(zero).is_err());
    }

    #[test]
    fn the_chair_registers_as_a_real_robot_with_the_chairs_body_sensors_and_start_pose() {
        let reg = registration("chair1", SensorMode::Augmented, [10.0, 6.1, 90.0]);
        assert_eq!(reg.kind, RobotKind::Real as u32);
        assert_eq!(reg.flags, REG_CHAIR | REG_HAS_POSE | REG_SENSORS_AUGMENTED);
        assert_eq!([reg.width_m, reg.height_m, reg.com], chair::BODY);
        assert_eq!([reg.max_speed_mps, reg.accel_curve], [chair::MAX_SPEED_MPS, chair::ACCEL_CURVE]);
        assert_eq!(reg.pose, [10.0, 6.1, 90.0]);
        assert_eq!(reg.sensor_count as usize, chair::SENSORS.len());
        for (spec, m) in reg.sensors.iter().zip(&chair::SENSORS) {
            assert_eq!(
                [spec.x_m, spec.y_m, spec.angle_deg, spec.cone_deg, spec.range_m],
                [m.x_m, m.y_m, m.angle_deg, m.cone_deg, m.range_m]
            );
        }
        assert_eq!(reg.name.as_str(), Some("chair1"));
        assert_eq!(registration("c", SensorMode::Virtual, [0.0; 3]).flags, REG_CHAIR | REG_HAS_POSE);
    }

    #[test]
    fn bad_names_and_poses_are_refused_before_anything_is_opened() {
        static STOP: AtomicBool = AtomicBool::new(false);
        let args = |robot: &str, pose: [f64; 3]| SerialArgs {
            hub: SessionArgs { session: "none".into(), connect_timeout: 0.0 },
            device: PathBuf::from("/nonexistent/iwsim-serial-test"),
            baud: 115_200,
            robot: robot.into(),
            mode: ModeArg::Real,
            pose,
            stepped: false,
            odometry_only: false,
            auto_resume: false,
        };
        let long = "x".repeat(256);
        for (robot, pose, option) in
            [("", [0.0; 3], "robot"), (long.as_str(), [0.0; 3], "robot"), ("c", [f64::NAN, 0.0, 0.0], "pose")]
        {
            match run(args(robot, pose), &STOP) {
                Err(SerialError::InvalidOption { option: o, .. }) => assert_eq!(o, option),
                other => panic!("{robot:?} {pose:?}: {other:?}"),
            }
        }
        match run(args("c", [0.0; 3]), &STOP) {
            Err(SerialError::Open(e)) => {
                let text = e.to_string();
                assert!(text.contains("cannot open serial port /nonexistent/iwsim-serial-test"), "{text}");
            }
            other => panic!("{other:?}"),
        }
    }
}
