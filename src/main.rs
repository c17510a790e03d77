//! The `iwsim` binary: parses the command line, starts logging, runs the command.

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
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
