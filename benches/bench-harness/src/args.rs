//! The command line of `iwsim bench`: one clap struct per benchmark.

use clap::{Args, Subcommand};

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
    /// The RS232 link to a chair's board, against the chair emulator on a pseudo-terminal:
    /// command → board → reading round trip, and the highest control rate the line carries.
    Serial(BenchSerialArgs),
    /// Many navigators sharing the ward in lock-step, as `iwsim run` runs them: ticks per
    /// second (over the run and in its slowest second), the hub's and the navigators' CPU per
    /// tick, and how the traffic went (arrivals, contacts, deadlocks, judged from the record).
    Traffic(BenchTrafficArgs),
    /// Lock-step ticks per second with chairs driven over ROS 2 topics (`iwsim ros2`, a Zenoh
    /// router and a ROS-side controller), beside the same chairs driven over shared memory.
    Ros2(BenchRos2Args),
    /// The peer process of the raw iceoryx2 ping-pong (started by `bench latency`).
    #[command(hide = true)]
    RawPeer(RawPeerArgs),
    /// A Ciber-Rato-style UDP client answering every Measures (started by `bench lockstep`).
    #[command(hide = true)]
    UdpClient(UdpClientArgs),
    /// A shared-memory agent carrying a controller's load (started by `bench lockstep`).
    #[command(hide = true)]
    LoadAgent(LoadAgentArgs),
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

/// Options of `iwsim bench serial`.
#[derive(Debug, Args, Clone)]
pub struct BenchSerialArgs {
    /// The line's baud rate (8N1: 10 bits a byte).
    #[arg(long, default_value_t = 115_200, value_parser = clap::value_parser!(u32).range(1200..=4_000_000))]
    pub baud: u32,
    /// Runs; each figure is the median of its runs with min and max.
    #[arg(long, default_value_t = 5, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=MAX_RUNS))]
    pub runs: usize,
    /// Commands timed in each round-trip run.
    #[arg(long, default_value_t = 50, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=100_000))]
    pub commands: usize,
    /// Seconds of each run at the fastest sample period.
    #[arg(long, default_value_t = 3.0, value_parser = positive_seconds)]
    pub seconds: f64,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Options of `iwsim bench ros2`.
#[derive(Debug, Args, Clone)]
pub struct BenchRos2Args {
    /// Chair counts to measure, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "1,10", value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=100))]
    pub chairs: Vec<usize>,
    /// Ticks per run.
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(10..=1_000_000))]
    pub ticks: u64,
    /// Runs per size and transport (interleaved); each figure is the median with min and max.
    #[arg(long, default_value_t = 5, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=MAX_RUNS))]
    pub runs: usize,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Options of `iwsim bench traffic`.
#[derive(Debug, Args, Clone)]
pub struct BenchTrafficArgs {
    /// Crowd sizes to measure, comma-separated (each is `iwsim run builtin:ward --chairs N`).
    #[arg(long, value_delimiter = ',', default_value = "6,10,20", value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=200))]
    pub chairs: Vec<usize>,
    /// Runs per crowd size, seeds 1, 2, …; each figure is the median of its runs with min and
    /// max (the sizes' runs interleaved).
    #[arg(long, default_value_t = 5, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=MAX_RUNS))]
    pub runs: usize,
    /// Simulated seconds each run may take (the scenario's time limit).
    #[arg(long, default_value_t = 120.0, value_parser = positive_seconds)]
    pub seconds: f64,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

fn positive_seconds(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 && v <= 3600.0 => Ok(v),
        _ => Err(format!("{s:?} is not a number of seconds in (0, 3600]")),
    }
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
    /// How agents attach: over shared memory (shm), the UDP/XML bridge (udp), the Zenoh bridge
    /// on loopback (zenoh); several, comma-separated, run in one invocation with their ratios
    /// (`both` is shm,udp; `all` is shm,udp,zenoh).
    #[arg(long, default_value = "shm", value_delimiter = ',')]
    pub transport: Vec<Transport>,
    /// Run the UDP clients and the Zenoh agents in this network namespace, as on another host
    /// (made beforehand, joined to this one by a veth pair; needs root): the bridges listen on
    /// --netns-address. Shared-memory agents stay here.
    #[arg(long, value_name = "NS", requires = "netns_address")]
    pub netns: Option<String>,
    /// This host's address on the link to --netns, which the bridges listen on.
    #[arg(long, value_name = "ADDRESS", requires = "netns")]
    pub netns_address: Option<std::net::IpAddr>,
    /// Also run over UDP with this many junk datagrams sent at the bridge during the run (half
    /// to its registration port, half to a client's port from a stranger), and report ticks/s
    /// with and without the flood and the bridge's stderr bytes (0: no flood run).
    #[arg(long, default_value_t = 0)]
    pub flood: u64,
    /// Also run over shared memory with the hub recording the run (`iwsim hub --record`), and
    /// report ticks/s with and without and the recording's bytes per robot per tick.
    #[arg(long)]
    pub record: bool,
    /// What the agents do each tick: `ipc` answers constant powers without reading the sensors
    /// (robots 5 m apart, 4 sensors each: the cost of the IPC alone); `real` reads every
    /// sensor block (over UDP: parses every Measures, as a stock Ciber-Rato client does) and
    /// steers each robot by a reactive avoidance rule, with robots 2 m apart and 8 sensors
    /// each, so that about 8 neighbours are in sensor range; `both` runs the two, interleaved,
    /// and prints a labelled line for each.
    #[arg(long, value_enum, default_value = "both")]
    pub load: Load,
    /// Runs of each variant (shm, udp, udp+flood, shm+record, shm+real, udp+real), interleaved
    /// round by round; each figure is the median of its runs with min and max.
    #[arg(long, default_value_t = 5, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=MAX_RUNS))]
    pub runs: usize,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// The most runs `--runs` takes: one run of a variant is seconds, so a thousand is hours.
pub const MAX_RUNS: u64 = 1000;

/// What bench agents do each tick (`--load`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Load {
    /// Constant powers, sensors unread: the IPC alone.
    Ipc,
    /// Every sensor block read, a reactive avoidance rule per robot, robots within each
    /// other's sensor range.
    Real,
    /// Both, interleaved, each on its own line.
    Both,
}

impl Load {
    /// Whether the IPC-only variants run.
    pub fn ipc(self) -> bool {
        matches!(self, Load::Ipc | Load::Both)
    }

    /// Whether the real-load variants run.
    pub fn real(self) -> bool {
        matches!(self, Load::Real | Load::Both)
    }
}

/// How bench agents attach to the hub.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Transport {
    /// Agent SDK over iceoryx2 shared memory.
    Shm,
    /// Ciber-Rato UDP/XML clients through `iwsim udp`.
    Udp,
    /// Agent SDK over Zenoh (TCP on loopback) through `iwsim zenoh`.
    Zenoh,
    /// shm and udp.
    Both,
    /// shm, udp and zenoh.
    All,
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
    /// Start pose of the first robot X,Y (a lattice 5 m apart, ten to a row; IPC only).
    #[arg(long, value_parser = agent_sdk::args::powers, allow_hyphen_values = true)]
    pub pose: [f64; 2],
    /// With the real load: register 8-sensor chairs on the bench lattice (`--first` and
    /// `--total` place them), parse every Measures and steer by the reactive rule.
    #[arg(long)]
    pub real: bool,
    /// With `--real`: the lattice index of the first robot.
    #[arg(long, default_value_t = 0)]
    pub first: usize,
    /// With `--real`: robots on the whole lattice (all clients).
    #[arg(long, default_value_t = 1)]
    pub total: usize,
}

/// Options of the hidden real-load agent.
#[derive(Debug, Args, Clone)]
pub struct LoadAgentArgs {
    /// Session of the hub.
    #[arg(long)]
    pub session: String,
    /// Robots to register.
    #[arg(long, default_value_t = 1)]
    pub robots: usize,
    /// The lattice index of the first robot.
    #[arg(long, default_value_t = 0)]
    pub first: usize,
    /// Robots on the whole lattice (all agents).
    #[arg(long, default_value_t = 1)]
    pub total: usize,
    /// Join through a Zenoh bridge at this endpoint instead of shared memory.
    #[arg(long, value_name = "ENDPOINT")]
    pub zenoh: Option<String>,
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
    /// Thread counts to time, comma-separated, each a variant of the same run (0: one per
    /// core). Default: one thread, and one per core when the machine has more than one.
    #[arg(long, value_delimiter = ',', value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(0..=world::MAX_THREADS as u64))]
    pub threads: Vec<usize>,
    /// The fewest chairs a step is spread over threads for.
    #[arg(long, default_value_t = world::PARALLEL_MIN_ROBOTS)]
    pub parallel_min_robots: usize,
    /// Runs of each thread count, interleaved round by round; each figure is the median of
    /// its runs with min and max. Every run times the same ticks from the same warmed world.
    #[arg(long, default_value_t = 5, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=MAX_RUNS))]
    pub runs: usize,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}
