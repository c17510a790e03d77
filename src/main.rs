//! The `iwsim` binary: parses the command line, starts logging, runs the command.

use std::process::ExitCode;

use clap::Parser;

/// Zenoh's runtimes as iwsim runs them: its receive, accept and network tasks handed over to
/// its one application thread, instead of five more threads per process. On a 2-core machine
/// with ten agent processes this makes lock-step through the bridge about 28 % faster (fewer
/// threads for the scheduler to switch between; `iwsim bench lockstep --agents 10 --transport
/// zenoh`). A `ZENOH_RUNTIME` the user set is kept.
const ZENOH_RUNTIME: &str = "(rx: (handover: app), acc: (handover: app), net: (handover: app))";

fn main() -> ExitCode {
    if std::env::var_os("ZENOH_RUNTIME").is_none() {
        #[allow(unsafe_code)]
        // SAFETY: the first thing main does: no other thread exists yet to read the
        // environment meanwhile.
        unsafe {
            std::env::set_var("ZENOH_RUNTIME", ZENOH_RUNTIME);
        }
    }
    let cli = iwsim::cli::Cli::parse();
    iwsim::init_logging();
    match iwsim::run(cli) {
        Ok(code) => code,
        Err(err) => {
            agent_sdk::report!("iwsim: error: {}", iwsim::error_chain(&err));
            ExitCode::FAILURE
        }
    }
}
