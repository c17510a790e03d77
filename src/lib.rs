//! The `iwsim` command: one binary for every process of the simulator. Each subcommand lives
//! in its own module as a library function, so tests and benches call the same code.
#![warn(missing_docs)]

pub mod agentcmd;
pub mod bench;
pub mod benchview;
pub mod cli;
pub mod demo;
pub mod hubcmd;
pub mod mapcheck;
pub mod run;
pub mod scenario;
pub mod udpcmd;
pub mod viewcmd;

use std::process::ExitCode;

use cli::{AgentCommand, BenchCommand, Cli, Command, MapCommand};

/// Logs go to stderr, filtered by `RUST_LOG` (e.g. `RUST_LOG=debug` or `RUST_LOG=hub=trace`);
/// warnings and errors by default.
pub fn init_logging() {
    use tracing_subscriber::filter::{LevelFilter, Targets};
    let filter = std::env::var("RUST_LOG")
        .ok()
        .and_then(|s| s.parse::<Targets>().ok())
        // iceoryx2 is configured in code (`ipc_services::Session`), so its warnings about
        // config files it did not find, and the like, only confuse; its errors still show,
        // and RUST_LOG brings the rest back.
        .unwrap_or_else(|| {
            Targets::new().with_default(LevelFilter::WARN).with_target("iceoryx2_bb_loggers", LevelFilter::ERROR)
        });
    use tracing_subscriber::layer::SubscriberExt;
    use tracing_subscriber::util::SubscriberInitExt;
    let _ = tracing_subscriber::registry()
        .with(tracing_subscriber::fmt::layer().with_writer(std::io::stderr))
        .with(filter)
        .try_init();
}

/// Runs a parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Command::Map { command: MapCommand::Check { file } } => mapcheck::check(&file),
        Command::Bench { command: BenchCommand::World(args) } => bench::world(&args),
        Command::Bench { command: BenchCommand::Latency(args) } => bench::latency(&args),
        Command::Bench { command: BenchCommand::Lockstep(args) } => bench::lockstep(&args),
        Command::Bench { command: BenchCommand::Viewer(args) } => benchview::run(&args),
        Command::Bench { command: BenchCommand::RawPeer(args) } => bench::raw_peer(&args),
        Command::Bench { command: BenchCommand::UdpClient(args) } => bench::udp_client(&args),
        Command::Demo(args) => demo::run(&args),
        Command::Hub(args) => hubcmd::run(&args),
        Command::Udp(args) => udpcmd::run(&args),
        Command::View(args) => viewcmd::run(&args),
        Command::Agent { agent: AgentCommand::Wheelchair(args) } => agentcmd::wheelchair(&args),
        Command::Agent { agent: AgentCommand::Navigator(args) } => navigator::run(&args),
        Command::Agent { agent: AgentCommand::Teleop(args) } => teleop::run(&args),
        Command::Agent { agent: AgentCommand::Door(args) } => door::run(&args),
        Command::Plot(args) => plot::run(&args),
        Command::Run(args) => run::run(&args),
    }
}
