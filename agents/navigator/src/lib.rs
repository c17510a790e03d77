//! The navigator agent (being written).

/// Options of `iwsim agent navigator`.
#[derive(Debug, clap::Args, Clone)]
pub struct NavigatorArgs {
    /// Session of the hub to join.
    #[arg(long, default_value = "default")]
    pub session: String,
}

/// Runs the agent.
pub fn run(_args: &NavigatorArgs) -> anyhow::Result<std::process::ExitCode> {
    anyhow::bail!("the navigator is not written yet")
}
