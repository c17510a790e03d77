//! `iwsim udp`: the Ciber-Rato / Intellwheels UDP/XML bridge.

use std::process::ExitCode;
use std::time::Duration;

use udp_bridge::{Bridge, BridgeConfig};

use crate::cli::UdpArgs;

/// Serves UDP until the hub ends the run or goes away.
pub fn run(args: &UdpArgs) -> anyhow::Result<ExitCode> {
    let cfg = BridgeConfig {
        session: args.session.clone(),
        bind: args.bind,
        port: args.port,
        client_timeout: Duration::from_secs_f64(args.client_timeout.max(0.1)),
        connect_timeout: Duration::from_secs_f64(args.connect_timeout.max(0.0)),
    };
    let bridge = Bridge::start(cfg)?;
    eprintln!(
        "iwsim udp: session {:?}, registrations on {}",
        args.session,
        bridge.local_addr().map_or_else(|| format!("{}:{}", args.bind, args.port), |a| a.to_string())
    );
    let counters = bridge.run()?;
    eprintln!(
        "iwsim udp: run over ({} malformed, {} foreign, {} refused, {} timed out)",
        counters.malformed, counters.foreign, counters.refused, counters.timed_out
    );
    Ok(ExitCode::SUCCESS)
}
