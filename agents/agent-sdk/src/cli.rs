//! The command-line options every agent takes, declared once: which session to join, how long
//! to wait for its hub, and where to write the robots' logs. An agent flattens [`CommonArgs`]
//! into its own options:
//!
//! ```
//! use clap::Parser as _;
//!
//! #[derive(clap::Parser)]
//! struct MyAgent {
//!     #[command(flatten)]
//!     common: agent_sdk::cli::CommonArgs,
//!     /// Top speed, m/s.
//!     #[arg(long, default_value_t = 0.5)]
//!     max_speed: f64,
//! }
//!
//! let a = MyAgent::parse_from(["my-agent", "--session", "s1", "--log", "runs"]);
//! assert_eq!((a.common.hub.session.as_str(), a.common.hub.connect_timeout), ("s1", 5.0));
//! assert_eq!(a.common.log.as_deref(), Some(std::path::Path::new("runs")));
//! ```
//!
//! [`RobotArgs`] (`--name`, `--id`, `--pose`) and [`BodyArgs`] (`--width`, `--height`, `--com`)
//! serve the agents that take them in that form. Options whose default differs between agents
//! (top speed, motor filter) stay with each agent. An agent that describes a shared option in its own words (what it logs,
//! say) overrides the help with `#[command(mut_arg("log", |a| a.help("…")))]`; the name,
//! type, default and meaning stay the ones declared here.

use std::path::PathBuf;
use std::time::Duration;

use crate::{Agent, AgentError};
use sim_model::PoseDeg;

/// Which hub to join and how long to wait for it (`--session`, `--connect-timeout`): what
/// every client of a hub takes, agents, the UDP bridge and the viewer alike.
#[derive(Debug, Clone, PartialEq, clap::Args)]
pub struct SessionArgs {
    /// Session of the hub to join.
    #[arg(long, default_value = "default")]
    pub session: String,
    /// Seconds to wait for the hub to start serving the session.
    #[arg(long, value_name = "S", default_value_t = 5.0)]
    pub connect_timeout: f64,
}

impl SessionArgs {
    /// `--connect-timeout` as a duration: negative or NaN is no wait, too large or infinite
    /// waits for ever (rather than failing on a value the user meant as "long").
    pub fn timeout(&self) -> Duration {
        Duration::try_from_secs_f64(self.connect_timeout.max(0.0)).unwrap_or(Duration::MAX)
    }
}

/// The options every agent takes (`--session`, `--connect-timeout`, `--log`).
#[derive(Debug, Clone, PartialEq, clap::Args)]
pub struct CommonArgs {
    /// `--session`, `--connect-timeout`.
    #[command(flatten)]
    pub hub: SessionArgs,
    /// Write one CSV log per robot (one row per tick, thesis Annex C columns) into this
    /// directory.
    #[arg(long, value_name = "DIR")]
    pub log: Option<PathBuf>,
    /// `--zenoh`, `--zenoh-config`.
    #[command(flatten)]
    pub remote: RemoteArgs,
}

/// How to reach a hub on another machine (`--zenoh`, `--zenoh-config`): agents and observers
/// (the viewer) take them.
#[derive(Debug, Clone, Default, PartialEq, Eq, clap::Args)]
pub struct RemoteArgs {
    /// Join a hub on another machine through its Zenoh bridge (`iwsim zenoh` there) at this
    /// endpoint, e.g. tcp/10.0.0.5:7447 (the bridge's, or a Zenoh router's).
    #[arg(long, value_name = "ENDPOINT")]
    pub zenoh: Option<String>,
    /// With --zenoh: a Zenoh configuration file (JSON5) to start from (TLS, authentication).
    #[arg(long, value_name = "FILE", requires = "zenoh")]
    pub zenoh_config: Option<PathBuf>,
}

impl RemoteArgs {
    /// The bridge to reach, if `--zenoh` was given.
    pub fn remote(&self) -> Option<crate::remote::Remote> {
        let endpoint = self.zenoh.clone()?;
        Some(crate::remote::Remote { endpoint, config: self.zenoh_config.clone(), prefix: None })
    }
}

impl CommonArgs {
    /// Joins the session, waiting up to `--connect-timeout` for its hub. The agent's name is
    /// `role` and the process id (`navigator-4711`), unique on the machine.
    /// With `--zenoh`, it joins through the hub's Zenoh bridge instead.
    pub fn connect(&self, role: &str) -> Result<Agent, AgentError> {
        if let Some(remote) = self.remote.remote() {
            return Agent::connect_zenoh(&remote, &self.hub.session, self.hub.timeout());
        }
        Agent::connect_within(&self.hub.session, &format!("{role}-{}", std::process::id()), self.hub.timeout())
    }
}

/// One robot's name, requested id and start pose (`--name`, `--id`, `--pose`), as the agents
/// that drive one chair take them. An agent that means more by one of them says so in its
/// own help with `mut_arg`.
#[derive(Debug, Clone, PartialEq, clap::Args)]
pub struct RobotArgs {
    /// Name of the chair.
    #[arg(long, default_value = "chair1")]
    pub name: String,
    /// Requested id, the 1-based grid slot (0: the first free one).
    #[arg(long, default_value_t = 0)]
    pub id: u32,
    /// Start pose as X,Y,DIR (metres, degrees); without it the chair takes its grid slot.
    #[arg(long, value_name = "X,Y,DIR", value_parser = crate::args::pose, allow_hyphen_values = true)]
    pub pose: Option<PoseDeg>,
}

/// A rectangular body (thesis Table 4.1) as separate options: `--width` (length along the
/// heading), `--height` (size across it) and `--com` (where the wheel axle sits).
#[derive(Debug, Clone, Copy, PartialEq, clap::Args)]
pub struct BodyArgs {
    /// Length along the heading, metres.
    #[arg(long, default_value_t = 1.0)]
    pub width: f64,
    /// Size across the heading, metres.
    #[arg(long, default_value_t = 1.0)]
    pub height: f64,
    /// Centre of movement, (0, 1).
    #[arg(long, default_value_t = 0.5)]
    pub com: f64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser as _;

    #[derive(Debug, clap::Parser)]
    #[command(mut_arg("log", |a| a.help("Write the door's log here.").value_name("LOG")))]
    struct Cli {
        #[command(flatten)]
        common: CommonArgs,
    }

    #[test]
    fn defaults_and_values_parse() {
        let c = Cli::parse_from(["agent"]).common;
        let hub = SessionArgs { session: "default".into(), connect_timeout: 5.0 };
        assert_eq!(c, CommonArgs { hub, log: None, remote: RemoteArgs::default() });
        assert_eq!(c.hub.timeout(), Duration::from_secs(5));
        let c = Cli::parse_from(["agent", "--session", "s", "--connect-timeout", "0.25", "--log", "d"]).common;
        assert_eq!(
            (c.hub.session.as_str(), c.hub.timeout(), c.log),
            ("s", Duration::from_millis(250), Some("d".into()))
        );
        assert!(Cli::try_parse_from(["agent", "--connect-timeout", "soon"]).is_err());
    }

    #[test]
    fn odd_timeouts_do_not_panic() {
        let t = |s: f64| SessionArgs { session: String::new(), connect_timeout: s }.timeout();
        assert_eq!((t(-1.0), t(f64::NAN), t(f64::INFINITY)), (Duration::ZERO, Duration::ZERO, Duration::MAX));
    }

    #[test]
    fn an_agent_may_word_a_shared_option_its_own_way() {
        use clap::CommandFactory as _;
        let help = Cli::command().render_long_help().to_string();
        assert!(help.contains("--log <LOG>") && help.contains("Write the door's log here."), "{help}");
        assert!(help.contains("--connect-timeout <S>") && help.contains("[default: 5]"), "{help}");
    }
}
