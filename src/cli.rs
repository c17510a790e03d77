//! The command line (clap derive). Subcommand names are the contract the docs and tests use.

use clap::{Parser, Subcommand};

/// iwsim: a co-simulation hub for intelligent wheelchairs.
#[derive(Debug, Parser)]
#[command(name = "iwsim", version, about, long_about = None)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// Subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Runs the demo: the slalom and the automatic door on the LIACC floor in real time, with
    /// the viewer (its address is printed) and a summary.
    Demo(runner::DemoArgs),
    /// Map files: check a lab, grid or parameters file.
    Map {
        /// What to do with the map.
        #[command(subcommand)]
        command: MapCommand,
    },
    /// Runs a hub: loads a map and serves its world over shared memory to agents.
    Hub(hub::cli::HubArgs),
    /// Replays a recorded run (an MCAP file) from its replay journal; --check compares every
    /// tick's state hash with the recording's.
    Replay(hub::replay::ReplayArgs),
    /// Records a running session as an observer, on this machine or on another through the
    /// session's Zenoh bridge (`--zenoh`, the bridge with `--observers world`): the world each
    /// tick and the map, on the hub recorder's Foxglove channels, for `iwsim plot` and Foxglove.
    /// It has no replay journal (an observer sees no actions): `iwsim hub --record` has. On the
    /// hub's machine it sees each snapshot it is in time for: every tick in real time, not every
    /// one in lock-step (it says how many it missed).
    Record(crate::record::RecordArgs),
    /// Serves the Ciber-Rato / Intellwheels UDP/XML protocol to remote agents and viewers.
    Udp(udp_bridge::cli::UdpArgs),
    /// Serves a session to agents on other machines over Zenoh (`iwsim agent … --zenoh
    /// tcp/HOST:7447` on theirs), in lock-step, with the shared-memory payloads.
    Zenoh(zenoh_bridge::cli::ZenohArgs),
    /// A Zenoh router (Zenoh's own, as `zenohd` runs it) for a bridge and agents that meet
    /// through one: `iwsim zenoh --connect` and the agents' `--zenoh` name it.
    ZenohRouter(zenoh_bridge::cli::RouterArgs),
    /// Serves chairs to ROS 2 over Zenoh in rmw_zenoh's wire format: per chair NAME, cmd_vel in;
    /// odom, tf, scan, ranges, imu and bumper out; /clock and /map (nodes started with
    /// RMW_IMPLEMENTATION=rmw_zenoh_cpp see them, with no ROS 2 install here).
    Ros2(ros2_bridge::cli::Ros2Args),
    /// Hosts episodes for learning environments on other machines (the Python
    /// `ChairsParallelEnv(..., zenoh="tcp/HOST:7447")`): each reset starts a lock-step hub of
    /// its scenario here, served to it over Zenoh with the truth for its referee.
    EnvHost(zenoh_bridge::cli::EnvHostArgs),
    /// Joins a physical wheelchair to a hub over its board's serial port (RS232): the chair
    /// becomes a Real robot that the agent registering the same name drives.
    Serial(serial_bridge::SerialArgs),
    /// Resumes a physical chair after a stop: its adapter holds every stop until this word
    /// (or `iwsim serial --auto-resume`), and drives it again once every cause has cleared.
    Resume(crate::resume::ResumeArgs),
    /// A stand-in for a physical wheelchair and its acquisition board on a pseudo-terminal:
    /// a simulated chair in its own room, with a real chair's imperfections.
    ChairEmulator(chair_emulator::EmulatorArgs),
    /// Serves a live view of a session to browsers (2D top view and 3D).
    View(viewer::cli::ViewArgs),
    /// Draws a run's trajectories over the map and speeds over time as SVG, from its recording
    /// (run.mcap) or from its robots' CSV logs.
    Plot(plot::PlotArgs),
    /// Runs a scenario (a TOML file or builtin:NAME): the hub, its agents and the viewer as
    /// processes, then a summary judged from the hub's recording of the run (run.mcap). Exit
    /// code 0 when the expected outcome holds. Built in: dynamics, slalom, door, corridor-swap,
    /// demo, slalom-real, slalom-augmented, ward.
    Run(runner::RunArgs),
    /// Runs an agent process.
    Agent {
        /// Which agent.
        #[command(subcommand)]
        agent: AgentCommand,
    },
    /// Benchmarks that print figures (add --json for machine-readable output).
    Bench {
        /// Which benchmark.
        #[command(subcommand)]
        command: bench_harness::BenchCommand,
    },
}

/// `iwsim agent …`
#[derive(Debug, Subcommand)]
pub enum AgentCommand {
    /// One or more wheelchairs driven with constant powers (a first user of the agent SDK).
    Wheelchair(wheelchair::WheelchairArgs),
    /// Autonomous driving through checkpoints: a route planned on the hub's map, obstacles
    /// avoided with the proximity sensors.
    Navigator(navigator::NavigatorArgs),
    /// Drive a chair from the terminal with the arrow keys or WASD.
    Teleop(teleop::TeleopArgs),
    /// Normal, sliding and rotating doors that open for what their sensors see or when a
    /// robot asks.
    Door(door::DoorArgs),
}

/// `iwsim map …`
#[derive(Debug, Subcommand)]
pub enum MapCommand {
    /// Validates a lab, grid or parameters XML file (or `builtin:NAME`): prints a summary, or
    /// the error with its line and column.
    Check {
        /// The file, or builtin:liacc, builtin:thesis, builtin:maze, builtin:ward.
        file: String,
    },
}
