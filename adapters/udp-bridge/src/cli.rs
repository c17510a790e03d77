//! `iwsim udp`: the bridge's command line and its run, printing what the user needs to know.

use std::process::ExitCode;
use std::time::Duration;

use agent_sdk::cli::SessionArgs;

use crate::{Bridge, BridgeConfig};

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
    /// Seconds a robot client may stay silent before its robot is removed.
    #[arg(long, default_value_t = 10.0)]
    pub client_timeout: f64,
}

/// Serves UDP until the hub ends the run or goes away.
pub fn run(args: &UdpArgs) -> anyhow::Result<ExitCode> {
    let cfg = BridgeConfig {
        session: args.hub.session.clone(),
        bind: args.bind,
        port: args.port,
        client_timeout: Duration::try_from_secs_f64(args.client_timeout.max(0.1)).unwrap_or(Duration::MAX),
        connect_timeout: args.hub.timeout(),
    };
    let bridge = Bridge::start(cfg)?;
    eprintln!(
        "iwsim udp: session {:?}, registrations on {}",
        args.hub.session,
        bridge.local_addr().map_or_else(|| format!("{}:{}", args.bind, args.port), |a| a.to_string())
    );
    let counters = bridge.run()?;
    eprintln!(
        "iwsim udp: run over ({} malformed, {} foreign, {} refused, {} timed out)",
        counters.malformed, counters.foreign, counters.refused, counters.timed_out
    );
    Ok(ExitCode::SUCCESS)
}
