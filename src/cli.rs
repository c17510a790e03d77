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
    Demo(DemoArgs),
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
    Run(RunArgs),
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
        command: BenchCommand,
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

/// Options of `iwsim run`.
#[derive(Debug, Args, Clone)]
pub struct RunArgs {
    /// The scenario: a TOML file, or builtin:dynamics, builtin:slalom, builtin:door,
    /// builtin:corridor-swap, builtin:demo.
    pub scenario: String,
    /// Step as fast as the agents allow (deterministic) instead of in real time.
    #[arg(long)]
    pub lockstep: bool,
    /// No viewer.
    #[arg(long)]
    pub headless: bool,
    /// Seed (default: the scenario's).
    #[arg(long, conflicts_with = "seeds")]
    pub seed: Option<u64>,
    /// A batch of runs, one per seed, A..B inclusive (headless), with a table at the end.
    #[arg(long, value_name = "A..B")]
    pub seeds: Option<String>,
    /// Where logs and summary.json go (default runs/<scenario>; a batch uses seed-N/ below it).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Where the viewer serves (use 0.0.0.0:8080 to watch from another machine).
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub http: std::net::SocketAddr,
    /// Let the viewer's page start, pause, step and stop the run.
    #[arg(long)]
    pub allow_control: bool,
    /// Print only the summary.
    #[arg(long)]
    pub quiet: bool,
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
    Wheelchair(WheelchairArgs),
    /// Autonomous driving through checkpoints: a route planned on the hub's map, obstacles
    /// avoided with the proximity sensors.
    Navigator(navigator::NavigatorArgs),
    /// Drive a chair from the terminal with the arrow keys or WASD.
    Teleop(teleop::TeleopArgs),
    /// Normal, sliding and rotating doors that open for what their sensors see or when a
    /// robot asks.
    Door(door::DoorArgs),
}

/// Options of `iwsim agent wheelchair`.
#[derive(Debug, Args, Clone)]
#[command(long_about = "Registers one or more wheelchairs and drives each by a script: constant motor \
powers, or a list of waypoints it drives to in turn (steering on the hub's pose: this is a scripted \
test agent, not a navigator) before it stops.

With --config FILE the chairs come from a TOML file, one [[chairs]] table each:

  [[chairs]]
  name = \"chair1\"
  pose = [12.5, 6.0, 180.0]      # x, y metres, heading degrees
  body = [1.1, 0.65, 0.8]        # length, width (wheel track), centre of movement
  max_speed = 0.49               # m/s at full power
  accel_curve = 0.83             # motor filter, thesis chapter 4
  sensors = [[0.88, 0.0, 0.0, 60.0, 3.0]]   # x, y, angle, cone, range (default: thesis Table 4.5)
  powers = [1.0, 1.0]            # script: constant powers, or
  waypoints = [[7.0, 6.0]]       # script: drive to each point in turn, then stop
  speed = 0.5                    # power used on the way to waypoints
  start_s = 0.0                  # wait this long before moving

Without --config, the options below describe --robots identical chairs.")]
pub struct WheelchairArgs {
    /// Session of the hub to join.
    #[arg(long, default_value = "default")]
    pub session: String,
    /// Chairs from a TOML file (see above); the body and script options below are ignored.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Write one CSV log per chair into this directory.
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Robots to register.
    #[arg(long, default_value_t = 1)]
    pub robots: usize,
    /// Name prefix of the robots.
    #[arg(long, default_value = "chair")]
    pub name: String,
    /// Requested id of the first robot (0: first free grid slot).
    #[arg(long, default_value_t = 0)]
    pub id: u32,
    /// Start pose of the first robot as X,Y,DIR (metres, degrees); further robots form a
    /// lattice `--spacing` apart, ten to a row. Without it, robots take grid slots.
    #[arg(long, value_parser = agent_sdk::args::pose, allow_hyphen_values = true)]
    pub pose: Option<[f64; 3]>,
    /// Distance between robots of the lattice, metres.
    #[arg(long, default_value_t = 2.0)]
    pub spacing: f64,
    /// Motor powers LEFT,RIGHT in [-1, 1].
    #[arg(long, value_parser = agent_sdk::args::powers, default_value = "0.5,0.5", allow_hyphen_values = true)]
    pub powers: [f64; 2],
    /// How the chairs move: simulated (the hub moves them) or real (this agent moves them and
    /// tells the hub their poses, standing in for physical chairs).
    #[arg(long, value_enum, default_value = "simulated")]
    pub kind: crate::agentcmd::ChairKind,
    /// Length along the heading, metres.
    #[arg(long, default_value_t = 1.0)]
    pub width: f64,
    /// Size across the heading, metres.
    #[arg(long, default_value_t = 1.0)]
    pub height: f64,
    /// Centre of movement, (0, 1).
    #[arg(long, default_value_t = 0.5)]
    pub com: f64,
    /// Top speed, m/s.
    #[arg(long, default_value_t = 0.5)]
    pub max_speed: f64,
    /// Acceleration curve, [0, 1).
    #[arg(long, default_value_t = 0.5)]
    pub accel_curve: f64,
    /// Stop after answering this many ticks (0: until the run ends).
    #[arg(long, default_value_t = 0)]
    pub ticks: u64,
    /// Spin on shared memory instead of sleeping between ticks.
    #[arg(long)]
    pub busy_poll: bool,
    /// Wait this many seconds for the hub to start serving the session.
    #[arg(long, default_value_t = 5.0)]
    pub connect_timeout: f64,
    /// At the end, print the hub-publish → agent-has-it latency percentiles as JSON.
    #[arg(long)]
    pub report_latency: bool,
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

/// `iwsim bench …`
#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// World model throughput: ticks per second of tiled LIACC floors with N chairs.
    World(BenchWorldArgs),
    /// Hub publish -> agent has its sensor block, busy-poll and blocking, against a raw
    /// iceoryx2 ping-pong measured in the same run.
    Latency(BenchLatencyArgs),
    /// End-to-end lock-step ticks per second with agents as separate processes.
    Lockstep(BenchLockstepArgs),
    /// The viewer page's frame rates with many chairs in a real headless Chromium, and the
    /// hub's lock-step rate with and without a viewer attached.
    Viewer(BenchViewerArgs),
    /// The peer process of the raw iceoryx2 ping-pong (started by `bench latency`).
    #[command(hide = true)]
    RawPeer(RawPeerArgs),
    /// A Ciber-Rato-style UDP client answering every Measures (started by `bench lockstep`).
    #[command(hide = true)]
    UdpClient(UdpClientArgs),
}

/// Options of `iwsim bench latency`.
#[derive(Debug, Args, Clone)]
pub struct BenchLatencyArgs {
    /// Samples per measurement (after 100 warm-up ones).
    #[arg(long, default_value_t = 20_000)]
    pub samples: u64,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Options of `iwsim bench viewer`.
#[derive(Debug, Args, Clone)]
pub struct BenchViewerArgs {
    /// Chairs on the floor.
    #[arg(long, default_value_t = 1000)]
    pub robots: usize,
    /// Seconds to count the page's frames in each view.
    #[arg(long, default_value_t = 5.0)]
    pub seconds: f64,
    /// Lock-step ticks for the hub-cost runs.
    #[arg(long, default_value_t = 2000)]
    pub ticks: u64,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Options of `iwsim bench lockstep`.
#[derive(Debug, Args, Clone)]
pub struct BenchLockstepArgs {
    /// Agent processes.
    #[arg(long, default_value_t = 1)]
    pub agents: usize,
    /// Robots each agent registers.
    #[arg(long, default_value_t = 100)]
    pub robots_per_agent: usize,
    /// Ticks to run.
    #[arg(long, default_value_t = 5000)]
    pub ticks: u64,
    /// Agents attach over shared memory (shm), over the UDP/XML bridge (udp), or both in
    /// one run with the ratio (both).
    #[arg(long, default_value = "shm")]
    pub transport: Transport,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// How bench agents attach to the hub.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Transport {
    /// Agent SDK over iceoryx2 shared memory.
    Shm,
    /// Ciber-Rato UDP/XML clients through `iwsim udp`.
    Udp,
    /// Both, one after the other, with the ratio.
    Both,
}

/// Options of the hidden UDP bench client.
#[derive(Debug, Args, Clone)]
pub struct UdpClientArgs {
    /// The bridge's registration address.
    #[arg(long)]
    pub server: std::net::SocketAddr,
    /// Robots to register (one socket each, as Ciber-Rato clients do).
    #[arg(long, default_value_t = 1)]
    pub robots: usize,
    /// Start pose of the first robot X,Y (a lattice 5 m apart, ten to a row).
    #[arg(long, value_parser = agent_sdk::args::powers, allow_hyphen_values = true)]
    pub pose: [f64; 2],
}

/// Options of the hidden raw ping-pong peer.
#[derive(Debug, Args, Clone)]
pub struct RawPeerArgs {
    /// Session (iceoryx2 domain) of the ping-pong.
    #[arg(long)]
    pub session: String,
    /// Pings to answer.
    #[arg(long)]
    pub samples: u64,
    /// Spin instead of sleeping.
    #[arg(long)]
    pub busy_poll: bool,
    /// Sleep on the event (the default).
    #[arg(long)]
    pub blocking: bool,
}

/// Options of `iwsim bench world`.
#[derive(Debug, Args, Clone)]
pub struct BenchWorldArgs {
    /// Number of chairs (ten per LIACC floor).
    #[arg(long, default_value_t = 1000)]
    pub robots: usize,
    /// Ticks to time.
    #[arg(long, default_value_t = 300)]
    pub ticks: u64,
    /// Ticks the chairs drive, untimed, before timing starts (100 = 10 simulated seconds).
    /// The load grows as chairs gather near walls and each other: after 6,000 ticks each
    /// chair has about twice as many edges in sensor range.
    #[arg(long, default_value_t = 100)]
    pub warmup: u64,
    /// Seed for placement and noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Options of `iwsim demo`.
#[derive(Debug, Args, Clone)]
pub struct DemoArgs {
    /// Simulated seconds to run (default: the whole demo, 75 s).
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Seed for the world's noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Where the logs and summary.json go.
    #[arg(long, default_value = "runs/demo")]
    pub out: PathBuf,
    /// No viewer.
    #[arg(long)]
    pub headless: bool,
    /// As fast as the agents allow instead of real time (implies --headless makes sense).
    #[arg(long)]
    pub lockstep: bool,
    /// Where the viewer serves (0.0.0.0:8080 to watch from another machine).
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub http: std::net::SocketAddr,
    /// Let the viewer's page start, pause, step and stop the run.
    #[arg(long)]
    pub allow_control: bool,
}
