//! `iwsim zenoh`: the bridge's command line and its run, printing what the user needs to know.

use std::path::PathBuf;
use std::process::ExitCode;

use agent_sdk::cli::SessionArgs;

use crate::{Bridge, BridgeConfig};

/// Options of `iwsim zenoh`.
#[derive(Debug, clap::Args, Clone)]
#[command(mut_arg("session", |a| a.help("Session of the hub to serve")))]
#[command(mut_arg("connect_timeout", |a| a.help("Seconds to wait for the hub to come up").value_name("CONNECT_TIMEOUT")))]
pub struct ZenohArgs {
    /// `--session`, `--connect-timeout`.
    #[command(flatten)]
    pub hub: SessionArgs,
    /// `--listen`, `--connect`, `--zenoh-config`.
    #[command(flatten)]
    pub endpoints: Endpoints,
    /// Key prefix the session is served under [default: iwsim/<SESSION>].
    #[arg(long, value_name = "PREFIX")]
    pub prefix: Option<String>,
    /// What observers on other machines (a remote viewer, recorder or referee) may read:
    /// `off`, or `world` (every robot's true state each tick, the robots' info and the
    /// observers' map, under <PREFIX>/observe/). Off by default: it is the truth, which
    /// agents under test must not read, and anyone who reaches the endpoint could.
    #[arg(long, value_enum, default_value = "off")]
    pub observers: crate::Observers,
    /// Remote agents to wait for: the bridge tells the hub it is ready (so a lock-step hub's
    /// --wait-agents counts it) once this many remote agents have registered their robots and
    /// said they are ready.
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub wait_agents: u32,
}

/// Where a bridge or an episode host meets its peers (`--listen`, `--connect`,
/// `--zenoh-config`).
#[derive(Debug, clap::Args, Clone)]
pub struct Endpoints {
    /// Zenoh endpoint to listen on for peers (repeatable). Without --listen and --connect:
    /// tcp/0.0.0.0:7447, every interface.
    #[arg(long, value_name = "ENDPOINT")]
    pub listen: Vec<String>,
    /// Zenoh endpoint to connect to, e.g. a router's tcp/HOST:7447 (repeatable).
    #[arg(long, value_name = "ENDPOINT")]
    pub connect: Vec<String>,
    /// A Zenoh configuration file (JSON5) to start from: TLS, authentication, and the like.
    #[arg(long, value_name = "FILE")]
    pub zenoh_config: Option<PathBuf>,
}

impl Endpoints {
    /// The endpoints to listen on: `--listen`'s, or [`DEFAULT_LISTEN`] when neither
    /// `--listen` nor `--connect` was given (a peer must be reachable one way or the other).
    pub fn listen(&self) -> Vec<String> {
        if self.listen.is_empty() && self.connect.is_empty() {
            vec![DEFAULT_LISTEN.to_owned()]
        } else {
            self.listen.clone()
        }
    }
}

/// The endpoint listened on when neither `--listen` nor `--connect` is given.
pub const DEFAULT_LISTEN: &str = "tcp/0.0.0.0:7447";

/// Serves Zenoh until the hub ends the run or goes away.
pub fn run(args: &ZenohArgs) -> anyhow::Result<ExitCode> {
    let listen = args.endpoints.listen();
    let connect = &args.endpoints.connect;
    let cfg = BridgeConfig {
        session: args.hub.session.clone(),
        connect_timeout: args.hub.timeout(),
        listen: listen.clone(),
        connect: connect.clone(),
        config: args.endpoints.zenoh_config.clone(),
        prefix: args.prefix.clone(),
        observers: args.observers,
        wait_agents: args.wait_agents as usize,
    };
    let bridge = Bridge::start(&cfg)?;
    agent_sdk::report!(
        "iwsim zenoh: session {:?} served under {}/ (listening on {}{}){}",
        args.hub.session,
        bridge.prefix(),
        if listen.is_empty() { "nothing".to_owned() } else { listen.join(", ") },
        if connect.is_empty() { String::new() } else { format!("; connected to {}", connect.join(", ")) },
        if args.observers == crate::Observers::World { ", the world to observers" } else { "" }
    );
    let counters = bridge.run()?;
    agent_sdk::report!(
        "iwsim zenoh: run over ({} malformed, {} foreign, {} hellos refused, {} agents lost, {} came back)",
        counters.malformed,
        counters.foreign,
        counters.refused,
        counters.lost,
        counters.came_back
    );
    Ok(ExitCode::SUCCESS)
}

/// Options of `iwsim env-host`.
#[derive(Debug, clap::Args, Clone)]
pub struct EnvHostArgs {
    /// `--listen`, `--connect`, `--zenoh-config`.
    #[command(flatten)]
    pub endpoints: Endpoints,
    /// Episodes running at once, at most.
    #[arg(long, value_name = "N", default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..=256))]
    pub max_episodes: u32,
}

/// Serves episodes until SIGINT or SIGTERM.
pub fn env_host(args: &EnvHostArgs) -> anyhow::Result<ExitCode> {
    crate::episodes::serve(&crate::episodes::HostConfig {
        listen: args.endpoints.listen(),
        connect: args.endpoints.connect.clone(),
        config: args.endpoints.zenoh_config.clone(),
        prefix: None,
        max_episodes: args.max_episodes as usize,
        iwsim: std::env::current_exe()?,
    })?;
    Ok(ExitCode::SUCCESS)
}

/// Options of `iwsim zenoh-router`.
#[derive(Debug, clap::Args, Clone)]
pub struct RouterArgs {
    /// Zenoh endpoint to listen on (repeatable).
    #[arg(long, value_name = "ENDPOINT", default_value = DEFAULT_LISTEN)]
    pub listen: Vec<String>,
    /// A Zenoh configuration file (JSON5) to start from.
    #[arg(long, value_name = "FILE")]
    pub zenoh_config: Option<PathBuf>,
}

/// Runs Zenoh's own router (the engine `zenohd` runs, in router mode) until SIGINT or SIGTERM:
/// for a lab whose bridge and agents meet through a router and that has no `zenohd`.
pub fn router(args: &RouterArgs) -> anyhow::Result<ExitCode> {
    use zenoh::Wait as _;
    agent_sdk::remote::install_stop_handlers();
    let cfg = agent_sdk::remote::config(args.zenoh_config.as_deref(), "router", &args.listen, &[])?;
    let session = zenoh::open(cfg).wait().map_err(|e| anyhow::anyhow!("open a Zenoh router: {e}"))?;
    agent_sdk::report!("iwsim zenoh-router: routing on {}", args.listen.join(", "));
    while !agent_sdk::stop_signalled() {
        // Zenoh's threads do the routing; this one only waits for the word to stop.
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    drop(session);
    Ok(ExitCode::SUCCESS)
}
