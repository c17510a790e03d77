//! The command lines of `iwsim run` and `iwsim demo`.

use std::path::PathBuf;

use clap::Args;

/// Options of `iwsim run`.
#[derive(Debug, Args, Clone)]
pub struct RunArgs {
    /// The scenario: a TOML file, or builtin:dynamics, builtin:slalom, builtin:door,
    /// builtin:corridor-swap, builtin:demo, builtin:slalom-real, builtin:slalom-augmented,
    /// builtin:ward.
    pub scenario: String,
    /// Step as fast as the agents allow (deterministic) instead of in real time.
    #[arg(long)]
    pub lockstep: bool,
    /// Lock-step: how long (ms) a tick waits for its agents before the hub steps without the
    /// late ones (default: the scenario's `deadline_ms`, else 5000). A ROS 2 stack that plans
    /// for seconds needs more; a deadline that is met never changes the run.
    #[arg(long, value_name = "MS", value_parser = clap::value_parser!(u64).range(1..=hub::cli::MAX_DEADLINE_MS))]
    pub deadline_ms: Option<u64>,
    /// The viewer.
    #[command(flatten)]
    pub viewer: ViewerArgs,
    /// Print the scenario as a learning environment runs it (lab, checkpoints, obstacles,
    /// start poses, time, tick, noise, deadline) as JSON, and run nothing: the Python
    /// package reads scenario files this way.
    #[arg(long)]
    pub describe: bool,
    /// Seed (default: the scenario's).
    #[arg(long, conflicts_with = "seeds")]
    pub seed: Option<u64>,
    /// A batch of runs, one per seed, A..B inclusive (headless), with a table at the end.
    #[arg(long, value_name = "A..B")]
    pub seeds: Option<String>,
    /// Place this many navigator chairs, each with its own goal, seeded by the run's seed (the
    /// scenario's [crowd], or one of this size with its defaults, on the scenario's lab).
    #[arg(long, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=crate::crowd::Crowd::MAX_CHAIRS as u64))]
    pub chairs: Option<usize>,
    /// Where logs, the recording (run.mcap) and summary.json go (default runs/<scenario>; a batch uses seed-N/ below it).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print only the summary.
    #[arg(long)]
    pub quiet: bool,
    /// Session name, so `iwsim view --session NAME` or `iwsim udp --session NAME` can attach
    /// to the run (default: a unique name, run-<pid>-<seed>-<n>).
    #[arg(long)]
    pub session: Option<String>,
    /// Run the scenario's physical chair in this sensor mode instead of its own: the adapter's
    /// mode and the chair's agent's `sensors` (e.g. virtual, to see what the merge is worth).
    #[arg(long, value_enum, value_name = "MODE")]
    pub chair_mode: Option<crate::scenario::ChairMode>,
    /// The scenario's physical chair pushes its raw odometry pose: no map matching (to see
    /// what localisation is worth).
    #[arg(long)]
    pub chair_odometry_only: bool,
    /// Threads the hub's world step may use (0: one per core); a seeded run is the same on any
    /// number.
    #[arg(long, default_value_t = 0, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(0..=world::MAX_THREADS as u64))]
    pub threads: usize,
    /// The fewest robots the hub spreads a step over threads for (0: any world).
    #[arg(long, default_value_t = world::PARALLEL_MIN_ROBOTS)]
    pub parallel_min_robots: usize,
    /// Lock-step: how long (µs) the hub spins for its agents' answers before it sleeps, while
    /// each agent it waits for can have a core (0: never); timing only, never the run.
    #[arg(long, default_value_t = hub::ANSWER_SPIN_US, value_parser = clap::builder::RangedU64ValueParser::<u64>::new().range(0..=100_000))]
    pub answer_spin_us: u64,
    /// Run these agents as on other machines: through a Zenoh bridge (`iwsim zenoh`) the run
    /// starts beside its hub, each agent with `--zenoh`. `all`, or agent numbers as the
    /// scenario lists them (`2` or `1,3`).
    #[arg(long, value_name = "all|N,…", value_parser = crate::run::ZenohAgents::parse)]
    pub zenoh_agents: Option<crate::run::ZenohAgents>,
    /// With --zenoh-agents: where the bridge listens (and those agents connect) [default:
    /// tcp/127.0.0.1 on a free port].
    #[arg(long, value_name = "ENDPOINT", requires = "zenoh_agents")]
    pub zenoh_listen: Option<String>,
    /// With --zenoh-agents: start those agents in this network namespace (`ip netns exec NS`,
    /// as root), another host as far as the network goes.
    #[arg(long, value_name = "NS", requires = "zenoh_agents")]
    pub zenoh_netns: Option<String>,
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
    /// Where the logs, the recording (run.mcap) and summary.json go.
    #[arg(long, default_value = "runs/demo")]
    pub out: PathBuf,
    /// The viewer.
    #[command(flatten)]
    pub viewer: ViewerArgs,
    /// Print the scenario as a learning environment runs it (lab, checkpoints, obstacles,
    /// start poses, time, tick, noise, deadline) as JSON, and run nothing: the Python
    /// package reads scenario files this way.
    #[arg(long)]
    pub describe: bool,
    /// As fast as the agents allow instead of real time (implies --headless makes sense).
    #[arg(long)]
    pub lockstep: bool,
    /// Session name, so `iwsim view --session NAME` or `iwsim udp --session NAME` can attach
    /// to the demo (default: a unique name, run-<pid>-<seed>-<n>).
    #[arg(long)]
    pub session: Option<String>,
}

/// The viewer a run starts (`iwsim view`), as `iwsim run` and `iwsim demo` ask for it.
#[derive(Debug, Args, Clone)]
pub struct ViewerArgs {
    /// No viewer.
    #[arg(long)]
    pub headless: bool,
    /// Where the viewer serves (use 0.0.0.0:8080 to watch from another machine).
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub http: std::net::SocketAddr,
    /// Let the viewer's page start, pause, step and stop the run.
    #[arg(long)]
    pub allow_control: bool,
    /// A host name the viewer may be opened under besides its address (`lab-pc`, or
    /// `lab-pc:8080` for one port), passed to `iwsim view`. Repeatable.
    #[arg(long, value_name = "HOST")]
    pub allow_host: Vec<String>,
}
