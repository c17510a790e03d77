//! The command line (clap derive). Subcommand names are the contract the docs and tests use.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

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
    Hub(HubArgs),
    /// Serves the Ciber-Rato / Intellwheels UDP/XML protocol to remote agents and viewers.
    Udp(UdpArgs),
    /// Serves a live view of a session to browsers (2D top view and 3D).
    View(ViewArgs),
    /// Draws a run log's trajectory over the map and its speed over time as SVG.
    Plot(plot::PlotArgs),
    /// Runs a scenario (a TOML file or builtin:NAME): the hub, its agents and the viewer as
    /// processes, then a summary from the robots' logs. Exit code 0 when the expected outcome
    /// holds. Built in: dynamics, slalom, door, corridor-swap, demo.
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

/// Options of `iwsim hub`.
#[derive(Debug, Args, Clone)]
pub struct HubArgs {
    /// Lab file, or builtin:liacc, builtin:thesis, builtin:maze.
    #[arg(long, default_value = "builtin:liacc")]
    pub lab: String,
    /// Grid file (start poses); a built-in lab brings its own grid.
    #[arg(long)]
    pub grid: Option<String>,
    /// Parameters file (Ciber-Rato `<Parameters>`).
    #[arg(long)]
    pub param: Option<PathBuf>,
    /// Session name: hubs, agents and viewers of one run share it.
    #[arg(long, default_value = "default")]
    pub session: String,
    /// Tick period in milliseconds (real time; also the simulated step in lock-step).
    #[arg(long)]
    pub cycle_ms: Option<u32>,
    /// Step as soon as every agent has answered, instead of every cycle.
    #[arg(long)]
    pub lockstep: bool,
    /// Lock-step: step without an agent that has not answered after this long.
    #[arg(long, default_value_t = 1000)]
    pub deadline_ms: u64,
    /// Seed of the world's random generator.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Stop after this many ticks (0: run until stopped).
    #[arg(long, default_value_t = 0)]
    pub ticks: u64,
    /// Switch every sensor and motor noise off.
    #[arg(long)]
    pub no_noise: bool,
    /// Start tick 0 once this many agents are ready.
    #[arg(long, default_value_t = 0)]
    pub wait_agents: usize,
    /// Wait for a Start command before tick 0.
    #[arg(long)]
    pub start_on_command: bool,
    /// Robots the hub accepts (at most 10,000).
    #[arg(long, default_value_t = ipc_types::MAX_ROBOTS)]
    pub max_robots: usize,
    /// Print the end-of-run summary as one JSON object.
    #[arg(long)]
    pub json: bool,
    /// A scenario obstacle: a static box X0,Y0,X1,Y1 (metres) of height H (default 1.0 m),
    /// sensed and collided with like a wall. Repeatable.
    #[arg(long, value_name = "X0,Y0,X1,Y1[,H]", allow_hyphen_values = true)]
    pub obstacle: Vec<String>,
    /// A scenario checkpoint X,Y with radius R (default 0.5 m), shown by viewers. Repeatable.
    #[arg(long, value_name = "X,Y[,R]", allow_hyphen_values = true)]
    pub checkpoint: Vec<String>,
}

/// Options of `iwsim udp`.
#[derive(Debug, Args, Clone)]
pub struct UdpArgs {
    /// Session of the hub to serve.
    #[arg(long, default_value = "default")]
    pub session: String,
    /// Address to bind: 127.0.0.1 (this machine only) unless the LAN is wanted (0.0.0.0).
    #[arg(long, default_value = "127.0.0.1")]
    pub bind: std::net::IpAddr,
    /// Registration port (Ciber-Rato clients hard-code 6000).
    #[arg(long, default_value_t = 6000)]
    pub port: u16,
    /// Seconds a robot client may stay silent before its robot is removed.
    #[arg(long, default_value_t = 10.0)]
    pub client_timeout: f64,
    /// Seconds to wait for the hub to come up.
    #[arg(long, default_value_t = 5.0)]
    pub connect_timeout: f64,
}

/// Options of `iwsim view`.
#[derive(Debug, Args, Clone)]
pub struct ViewArgs {
    /// Session of the hub to show.
    #[arg(long, default_value = "default")]
    pub session: String,
    /// Address to serve the page on: loopback unless the LAN is wanted (0.0.0.0:8080).
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub http: std::net::SocketAddr,
    /// Let pages start, pause, step and stop the run.
    #[arg(long)]
    pub allow_control: bool,
    /// Seconds to wait for the hub to come up.
    #[arg(long, default_value_t = 5.0)]
    pub connect_timeout: f64,
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
        /// The file, or builtin:liacc, builtin:thesis, builtin:maze.
        file: String,
    },
}
