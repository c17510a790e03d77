//! `iwsim udp`: the bridge's command line and its run, printing what the user needs to know.

use std::process::ExitCode;
use std::time::Duration;

use agent_sdk::cli::SessionArgs;

use crate::{Bridge, BridgeConfig, Viewers};

/// Options of `iwsim udp`.
#[derive(Debug, clap::Args, Clone)]
#[command(mut_arg("session", |a| a.help("Session of the hub to serve")))]
#[command(mut_arg("connect_timeout", |a| a.help("Seconds to wait for the hub to come up").value_name("CONNECT_TIMEOUT")))]
pub struct UdpArgs {
    /// `--session`, `--connect-timeout`.
    #[command(flatten)]
    pub hub: SessionArgs,
    /// Address to bind: 127.0.0.1 (this machine only) unless the LAN is wanted (0.0.0.0).
    #[arg(long, default_value = "127.0.0.1")]
    pub bind: std::net::IpAddr,
    /// Registration port (Ciber-Rato clients hard-code 6000).
    #[arg(long, default_value_t = 6000)]
    pub port: u16,
    /// Remove a robot whose client stays silent this many seconds. Without it (as in
    /// Ciber-Rato) a silent robot is never removed and keeps its last powers.
    #[arg(long, value_name = "S", value_parser = client_timeout_s)]
    pub client_timeout: Option<f64>,
    /// Let registered viewers and panels start, pause and stop the run and remove robots
    /// (Ciber-Rato's Viewer sends Start); without it their commands are ignored and counted.
    #[arg(long)]
    pub allow_control: bool,
    /// Who may register as a viewer or panel, which sees every robot's true pose and the
    /// scenario's obstacles: loopback (this machine), any, or off.
    #[arg(long, value_enum, default_value_t = Viewers::Loopback)]
    pub viewers: Viewers,
    /// An address that may register as a viewer whatever `--viewers` says. Repeatable.
    #[arg(long, value_name = "IP")]
    pub viewer_allow: Vec<std::net::IpAddr>,
    /// Tell the hub the bridge is ready (its `--wait-agents` counts it) only once this many
    /// robots registered: a lock-step run then starts with every client's robot in it.
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    pub wait_robots: u64,
}

/// The shortest `--client-timeout`, seconds: the bridge looks at its clients every 20 ms, and a
/// client needs a few cycles to answer.
pub const MIN_CLIENT_TIMEOUT_S: f64 = 0.1;
/// The longest `--client-timeout`, seconds (a day): a silent robot is removed some time.
pub const MAX_CLIENT_TIMEOUT_S: f64 = 86_400.0;

/// Parses `--client-timeout`: seconds in [`MIN_CLIENT_TIMEOUT_S`, `MAX_CLIENT_TIMEOUT_S`].
fn client_timeout_s(text: &str) -> Result<f64, String> {
    let s: f64 = text.trim().parse().map_err(|_| format!("{text:?} is not a number of seconds"))?;
    if (MIN_CLIENT_TIMEOUT_S..=MAX_CLIENT_TIMEOUT_S).contains(&s) {
        Ok(s)
    } else {
        Err(format!("{text} is not in {MIN_CLIENT_TIMEOUT_S}..={MAX_CLIENT_TIMEOUT_S} seconds"))
    }
}

/// Serves UDP until the hub ends the run or goes away.
pub fn run(args: &UdpArgs) -> anyhow::Result<ExitCode> {
    let cfg = BridgeConfig {
        session: args.hub.session.clone(),
        bind: args.bind,
        port: args.port,
        // In range by its parser; the clamp keeps a hand-built UdpArgs from panicking.
        client_timeout: args
            .client_timeout
            .map(|s| Duration::from_secs_f64(s.clamp(MIN_CLIENT_TIMEOUT_S, MAX_CLIENT_TIMEOUT_S))),
        connect_timeout: args.hub.timeout(),
        allow_control: args.allow_control,
        viewers: args.viewers,
        viewer_allow: args.viewer_allow.clone(),
        wait_robots: usize::try_from(args.wait_robots).unwrap_or(usize::MAX),
    };
    let bridge = Bridge::start(cfg)?;
    agent_sdk::report!(
        "iwsim udp: session {:?}, registrations on {}",
        args.hub.session,
        bridge.local_addr().map_or_else(|| format!("{}:{}", args.bind, args.port), |a| a.to_string())
    );
    let counters = bridge.run()?;
    agent_sdk::report!(
        "iwsim udp: run over ({} malformed, {} foreign, {} refused, {} timed out, {} viewer commands ignored, {} viewers refused)",
        counters.malformed,
        counters.foreign,
        counters.refused,
        counters.timed_out,
        counters.ignored_commands,
        counters.refused_viewers
    );
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser as _;

    #[derive(Debug, clap::Parser)]
    struct Cli {
        #[command(flatten)]
        udp: UdpArgs,
    }

    #[test]
    fn a_client_timeout_out_of_range_is_a_one_line_error_naming_the_option_and_range() {
        for bad in ["1e30", "inf", "NaN", "0", "-1", "0.05", "86401"] {
            let arg = format!("--client-timeout={bad}");
            let err = Cli::try_parse_from(["udp", arg.as_str()]).expect_err(bad).to_string();
            let line = err.lines().next().unwrap_or_default();
            assert!(line.contains("--client-timeout") && line.contains("0.1..=86400"), "{bad}: {line}");
        }
        for good in ["0.1", "10", "86400"] {
            let args = Cli::try_parse_from(["udp", "--client-timeout", good]).expect(good);
            assert_eq!(args.udp.client_timeout, Some(good.parse::<f64>().expect("a number")));
        }
    }

    #[test]
    fn by_default_no_robot_is_removed_for_silence() {
        let args = Cli::try_parse_from(["udp"]).expect("no options");
        assert_eq!(args.udp.client_timeout, None);
    }
}
