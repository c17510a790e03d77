//! `iwsim view`: the viewer's command line and its run.

use std::process::ExitCode;

use agent_sdk::cli::SessionArgs;

use crate::{Viewer, ViewerConfig};

/// Options of `iwsim view`.
#[derive(Debug, clap::Args, Clone)]
#[command(mut_arg("session", |a| a.help("Session of the hub to show")))]
#[command(mut_arg("connect_timeout", |a| a.help("Seconds to wait for the hub to come up").value_name("CONNECT_TIMEOUT")))]
pub struct ViewArgs {
    /// `--session`, `--connect-timeout`.
    #[command(flatten)]
    pub hub: SessionArgs,
    /// Address to serve the page on: loopback unless the LAN is wanted (0.0.0.0:8080).
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub http: std::net::SocketAddr,
    /// Let pages start, pause, step and stop the run.
    #[arg(long)]
    pub allow_control: bool,
    /// Accept WebSockets from pages of this origin too (repeatable), e.g. http://lab-pc:8080;
    /// by default only pages this viewer served may connect.
    #[arg(long = "allow-origin", value_name = "ORIGIN")]
    pub allow_origin: Vec<String>,
    /// Answer requests addressed to this host name too (repeatable), e.g. lab-pc (any port) or
    /// lab-pc:8080: the name the page is opened under on a LAN. By default only the address the
    /// viewer listens on (and localhost over loopback) is answered, so another site's page
    /// cannot reach it by making its own name resolve here (DNS rebinding).
    #[arg(long = "allow-host", value_name = "HOST", value_parser = crate::server::allowed_host)]
    pub allow_host: Vec<String>,
    /// `--zenoh`, `--zenoh-config`: show a hub on another machine, through its Zenoh bridge
    /// (started there with `--observers world`).
    #[command(flatten)]
    pub remote: agent_sdk::cli::RemoteArgs,
}

/// Serves the viewer until the hub ends the run.
pub fn run(args: &ViewArgs) -> anyhow::Result<ExitCode> {
    let v = Viewer::start(ViewerConfig {
        session: args.hub.session.clone(),
        http: args.http,
        allow_control: args.allow_control,
        allowed_origins: args.allow_origin.clone(),
        allowed_hosts: args.allow_host.clone(),
        connect_timeout: args.hub.timeout(),
        remote: args.remote.remote(),
    })?;
    let addr = v.local_addr().unwrap_or(args.http);
    agent_sdk::report!("iwsim view: session {:?}, open http://{addr}/", args.hub.session);
    v.run()?;
    Ok(ExitCode::SUCCESS)
}
