//! The `iwsim` command: one binary for every process of the simulator. Each subcommand lives
//! in its own module as a library function, so tests and benches call the same code.
#![warn(missing_docs)]

pub mod cli;
pub mod mapcheck;
pub mod record;
pub mod resume;
mod stop_on_signals;

use std::process::ExitCode;
use std::sync::atomic::AtomicBool;

use cli::{AgentCommand, Cli, Command, MapCommand};

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

/// An error and its causes as one line, `outer: cause: …`, leaving out a cause whose text the
/// line already holds (many errors print their source themselves, and the chain would say it
/// twice).
pub fn error_chain(err: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if line.contains(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
    }
    line
}

/// Runs a parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Command::Map { command: MapCommand::Check { file } } => mapcheck::check(&file),
        Command::Bench { command } => bench_harness::run(&command),
        Command::Demo(args) => runner::demo::run(&args),
        Command::Hub(args) => hub::cli::run(&args),
        Command::Replay(args) => hub::replay::run(&args),
        Command::Record(args) => record::record(&args),
        Command::Udp(args) => udp_bridge::cli::run(&args),
        Command::Zenoh(args) => zenoh_bridge::cli::run(&args),
        Command::ZenohRouter(args) => zenoh_bridge::cli::router(&args),
        Command::Ros2(args) => ros2_bridge::cli::run(&args),
        Command::EnvHost(args) => zenoh_bridge::cli::env_host(&args),
        Command::View(args) => viewer::cli::run(&args),
        Command::Agent { agent: AgentCommand::Wheelchair(args) } => wheelchair::run(&args),
        Command::Agent { agent: AgentCommand::Navigator(args) } => navigator::run(&args),
        Command::Agent { agent: AgentCommand::Teleop(args) } => teleop::run(&args),
        Command::Agent { agent: AgentCommand::Door(args) } => door::run(&args),
        Command::Plot(args) => plot::run(&args),
        Command::Run(args) => runner::run::run(&args),
        Command::Serial(args) => {
            // The agent SDK's iceoryx2 node turns SIGINT/SIGTERM into a clean stop of the
            // adapter (the chair is stopped first), so no flag of ours is needed.
            let never = AtomicBool::new(false);
            serial_bridge::run(args, &never)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Resume(args) => resume::resume(&args),
        Command::ChairEmulator(args) => {
            let stop = stop_on_signals::install()?;
            chair_emulator::run(args, stop)?;
            Ok(ExitCode::SUCCESS)
        }
    }
}

#[cfg(test)]
mod tests {
    /// An error that prints its source itself, as many of ours do.
    #[derive(Debug)]
    struct Read(std::io::Error);

    impl std::fmt::Display for Read {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            write!(f, "cannot read the log: {}", self.0)
        }
    }

    impl std::error::Error for Read {
        fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
            Some(&self.0)
        }
    }

    #[test]
    fn an_error_chain_says_each_cause_once() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "No such file");
        let err = anyhow::Error::new(Read(io)).context("plotting");
        assert_eq!(super::error_chain(&err), "plotting: cannot read the log: No such file");
        let plain = anyhow::anyhow!("inner").context("outer");
        assert_eq!(super::error_chain(&plain), "outer: inner");
    }
}
