//! `iwsim ros2`: the command line.

use std::path::PathBuf;
use std::process::ExitCode;

use agent_sdk::cli::SessionArgs;
use zenoh::Wait as _;

use crate::bridge::{Bridge, ChairSpec, Ros2Config};

/// Options of `iwsim ros2`.
#[derive(Debug, clap::Args, Clone)]
#[command(long_about = "Serves chairs of a hub's session to ROS 2 over Zenoh, in rmw_zenoh's wire format: \
a node started with RMW_IMPLEMENTATION=rmw_zenoh_cpp (and the same ROS_DOMAIN_ID) sees, per chair NAME, \
/NAME/cmd_vel (in), /NAME/odom, /NAME/tf, /NAME/tf_static, /NAME/scan, /NAME/range/prox0..7, /NAME/imu and \
/NAME/bumper (out), and /clock and /map. The bridge registers each chair (the Intellwheels body, motors and \
eight proximity sensors) and drives it from its cmd_vel.")]
#[command(mut_arg("session", |a| a.help("Session of the hub to serve")))]
#[command(mut_arg("connect_timeout", |a| a.help("Seconds to wait for the hub to come up").value_name("CONNECT_TIMEOUT")))]
pub struct Ros2Args {
    /// `--session`, `--connect-timeout`.
    #[command(flatten)]
    pub hub: SessionArgs,
    /// A chair to serve as NAME (a grid slot) or NAME=X,Y,DIR (start pose, metres and
    /// degrees); repeatable. NAME is its ROS namespace.
    #[arg(long = "chair", value_name = "NAME[=X,Y,DIR]", required = true, value_parser = chair_spec)]
    pub chairs: Vec<ChairSpec>,
    /// Zenoh endpoint to connect to (repeatable). Without --connect and --listen:
    /// tcp/localhost:7447, where rmw_zenoh's router (rmw_zenohd, or `iwsim zenoh-router`) listens.
    #[arg(long, value_name = "ENDPOINT")]
    pub connect: Vec<String>,
    /// Zenoh endpoint to listen on (repeatable).
    #[arg(long, value_name = "ENDPOINT")]
    pub listen: Vec<String>,
    /// A Zenoh configuration file (JSON5) to start from.
    #[arg(long, value_name = "FILE")]
    pub zenoh_config: Option<PathBuf>,
    /// ROS_DOMAIN_ID [default: $ROS_DOMAIN_ID, else 0].
    #[arg(long, value_name = "ID", value_parser = clap::value_parser!(u32).range(0..=232))]
    pub domain: Option<u32>,
    /// Simulated seconds a cmd_vel holds: with no newer one, the chair stops.
    #[arg(long, value_name = "S", default_value_t = 0.5)]
    pub cmd_vel_timeout: f64,
    /// Tell the hub the bridge is ready at once, not once every chair has a controller (a
    /// publisher on its cmd_vel).
    #[arg(long)]
    pub no_wait: bool,
    /// Do not publish map → odom (the start pose) on tf_static: for a stack that localizes
    /// itself (AMCL, SLAM).
    #[arg(long)]
    pub no_map_odom: bool,
    /// Degrees between the rays of the scan made of the proximity cones.
    #[arg(long, value_name = "DEG", default_value_t = 1.0)]
    pub scan_step: f64,
}

fn chair_spec(s: &str) -> Result<ChairSpec, String> {
    match s.split_once('=') {
        None => Ok(ChairSpec { name: s.to_owned(), pose: None }),
        Some((name, pose)) => Ok(ChairSpec { name: name.to_owned(), pose: Some(agent_sdk::args::pose(pose)?) }),
    }
}

/// `ROS_DOMAIN_ID` as ROS 2 reads it: unset or empty is 0.
fn domain_from_env() -> anyhow::Result<u32> {
    match std::env::var("ROS_DOMAIN_ID") {
        Ok(v) if !v.trim().is_empty() => {
            let d: u32 = v.trim().parse().map_err(|_| anyhow::anyhow!("ROS_DOMAIN_ID={v:?} is not a number"))?;
            anyhow::ensure!(d <= 232, "ROS_DOMAIN_ID={d} is out of ROS 2's range 0..=232");
            Ok(d)
        }
        _ => Ok(0),
    }
}

/// Serves until the hub ends the run or goes away.
pub fn run(args: &Ros2Args) -> anyhow::Result<ExitCode> {
    anyhow::ensure!(
        args.cmd_vel_timeout.is_finite() && args.cmd_vel_timeout > 0.0,
        "--cmd-vel-timeout {}: give a positive number of seconds",
        args.cmd_vel_timeout
    );
    anyhow::ensure!(
        args.scan_step.is_finite() && (0.1..=45.0).contains(&args.scan_step),
        "--scan-step {}: give 0.1 to 45 degrees",
        args.scan_step
    );
    let domain = match args.domain {
        Some(d) => d,
        None => domain_from_env()?,
    };
    let connect = if args.connect.is_empty() && args.listen.is_empty() {
        vec!["tcp/localhost:7447".to_owned()]
    } else {
        args.connect.clone()
    };
    let zcfg = agent_sdk::remote::config(args.zenoh_config.as_deref(), "peer", &args.listen, &connect)?;
    let z = zenoh::open(zcfg).wait().map_err(|e| anyhow::anyhow!("open a Zenoh session: {e}"))?;
    let cfg = Ros2Config {
        session: args.hub.session.clone(),
        connect_timeout: args.hub.timeout(),
        domain,
        chairs: args.chairs.clone(),
        cmd_vel_timeout_s: args.cmd_vel_timeout,
        wait_controllers: !args.no_wait,
        map_to_odom: !args.no_map_odom,
        scan_step_rad: args.scan_step.to_radians(),
    };
    let bridge = Bridge::start(cfg, z.clone())?;
    let malformed = bridge.run();
    let _ = z.close().wait();
    let malformed = malformed?;
    if malformed > 0 {
        agent_sdk::report!("iwsim ros2: {malformed} cmd_vel samples were not a geometry_msgs/msg/Twist");
    }
    agent_sdk::report!("iwsim ros2: the hub ended the run");
    Ok(ExitCode::SUCCESS)
}
