//! The navigator agent: drives a wheelchair through a list of checkpoints on the hub's map,
//! finding obstacles it was not told about with its proximity sensors.
//!
//! - **Where it is**: wheel-encoder odometry by default ([`pose`]); GPS or both fused on
//!   request. Never the hub's ground truth.
//! - **What is around**: the known walls from the hub's map ([`map`], [`model`]) and a layer
//!   of obstacles found by the proximity sensors, as occupancy evidence so that 0.1 m of
//!   sensor noise neither invents nor erases them ([`grid`]). Scenario obstacles the hub
//!   flags are left out of the map on purpose: the thesis's chair did not know them either.
//! - **Which way**: per leg, A* on a grid of the lab grown by the chair's half-width for the
//!   route through rooms and doors, and a Dijkstra cost-to-go on the same grid ([`plan`]);
//!   then hybrid A* over (x, y, heading) with the chair's real rectangle ([`hybrid`]), which
//!   is what a rear-wheel-drive chair needs to thread a 1 m gap. It plans again whenever a
//!   newly sensed obstacle stands on the path.
//! - **How**: a path follower on the axle with curvature feed-forward, speed lowered near
//!   obstacles and in turns, wheel powers that account for the motor filter ([`track`]), and
//!   a reactive layer that slows or stops for readings nothing in the model explains.
//! - **Sensor source** ([`sensors`]): Virtual (the hub's readings) runs; Real and Augmented
//!   are designed in the types and wait for the serial bridge.
//! - **Other chairs** ([`traffic`], [`manoeuvre`], [`Pilot`]): navigators say where they are;
//!   a chair parked for good or for us is planned round from what it said, and two that meet
//!   head-on agree by messages who pulls over.
//!
//! [`Navigator::step`] is the logic without I/O, [`Pilot::tick`] the same with the traffic
//! rule; [`run`] connects a `Pilot` to a hub.
//!
//! ```
//! use navigator::geom::{Pose, V2};
//! use navigator::map::{MapWall, NavMap};
//! use navigator::{Body, Checkpoint, NavConfig, Navigator, PoseSourceKind};
//!
//! // A 10 m x 4 m room with a pillar, and one checkpoint to stop at.
//! let mut map = NavMap::empty(10.0, 4.0);
//! map.walls.push(MapWall::rectangle(4.0, 1.5, 4.5, 2.5, false));
//! let body = Body::INTELLWHEELS;
//! let cfg = NavConfig {
//!     sensors: navigator::sensors::default_layout(&body.footprint()),
//!     checkpoints: vec![Checkpoint { pos: V2::new(8.0, 2.0), radius_m: 0.5 }],
//!     start: Pose::from_deg(1.0, 2.0, 0.0),
//!     ..NavConfig::intellwheels()
//! };
//! let mut nav = Navigator::new(map, cfg);
//! let input = navigator::sensors::Input {
//!     tick: 0,
//!     time_s: 0.0,
//!     proximity_m: [3.0; 8],
//!     proximity_count: 8,
//!     encoder_ticks: [0, 0],
//!     gps: None,
//!     compass_deg: Some(0.0),
//!     collision: false,
//! };
//! let out = nav.step(&input);
//! assert!(out.powers.iter().all(|p| p.abs() <= 1.0));
//! assert!(!nav.finished());
//! ```
#![warn(missing_docs)]

mod agent;
pub mod geom;
pub mod grid;
pub mod hybrid;
pub mod manoeuvre;
pub mod map;
pub mod model;
mod navigator;
pub mod pilot;
pub mod plan;
pub mod pose;
pub mod sensors;
pub mod track;
pub mod traffic;
pub mod zones;

use agent_sdk::cli::{CommonArgs, RobotArgs};

pub use agent::run;
pub use navigator::{Body, Checkpoint, NavConfig, NavEvent, NavStats, Navigator, Output, POSE_MARGIN_M, WALL_FIX_GAIN};
pub use pilot::{Pilot, PilotOutput};
pub use pose::PoseSourceKind;
pub use sensors::Mode;

/// Options of `iwsim agent navigator`.
///
/// ```text
/// iwsim agent navigator --session s1 --checkpoint 10,6.1 --checkpoint 20,6.1
/// ```
/// drives from the first checkpoint (its start, heading towards the second) to the second,
/// and stops there.
#[derive(Debug, clap::Args, Clone)]
#[command(mut_arg("log", |a| a.help(
    "Write the chair's CSV log (one row per tick, thesis Annex C columns) into this directory"
)))]
#[command(mut_arg("name", |a| a.help("The chair's name (at most 31 bytes); also its log file's name")))]
#[command(mut_arg("id", |a| a.help("Requested robot id (a grid slot of the hub); 0 takes the first free one")))]
#[command(mut_arg("pose", |a| a.help(
    "Start pose X,Y,DIR in metres and degrees. Default: the first checkpoint, heading towards the second"
)))]
pub struct NavigatorArgs {
    /// `--session`, `--connect-timeout`, `--log` (the chair's CSV log, one row per tick).
    #[command(flatten)]
    pub common: CommonArgs,
    /// `--name`, `--id`, `--pose` (the default pose: the first checkpoint, heading towards the
    /// second).
    #[command(flatten)]
    pub robot: RobotArgs,
    /// A checkpoint X,Y or X,Y,R in metres; passing within R (default 0.5 m) counts. Repeat it in
    /// driving order (at least one); the chair stops at the last, within --arrive.
    #[arg(
        long = "checkpoint",
        value_name = "X,Y[,R]",
        value_parser = parse_checkpoint,
        allow_hyphen_values = true,
        required = true
    )]
    pub checkpoints: Vec<places::Checkpoint>,
    /// The body W,H,COM: length along the heading and width in metres, and where the wheel
    /// axle sits along the length from the rear (0.8: the Intellwheels rear-wheel-drive
    /// chair; 0.5: mid-wheel drive).
    #[arg(long, value_name = "W,H,COM", value_parser = parse_body, default_value = "1.1,0.65,0.8")]
    pub body: [f64; 3],
    /// Top speed in m/s (thesis §7.2: 0.49).
    #[arg(long, default_value_t = 0.49)]
    pub max_speed: f64,
    /// The motor filter's coefficient in [0, 1): the larger, the slower the motors respond
    /// (thesis §7.2: 0.83).
    #[arg(long, default_value_t = 0.83)]
    pub accel_curve: f64,
    /// Cruising speed as a fraction of the top speed, in (0, 1]. The chair slows down near
    /// obstacles, in tight turns and before stopping.
    #[arg(long, default_value_t = 0.6)]
    pub cruise: f64,
    /// Stop within this distance of the last checkpoint, metres. If a sensed obstacle
    /// leaves no room there, the chair stops at the nearest place within the checkpoint's
    /// radius.
    #[arg(long, default_value_t = 0.2)]
    pub arrive: f64,
    /// Where the pose estimate comes from: wheel-encoder odometry, GPS (the hub's GPS must
    /// be on; 0.5 m noise by default; a physical chair's GPS is the pose its adapter pushes,
    /// exactly), or odometry pulled slowly towards GPS.
    #[arg(long, value_enum, default_value_t = PoseSourceKind::Odometry)]
    pub pose_source: PoseSourceKind,
    /// Where the sensor readings come from: virtual (the hub's), real (a physical chair's own
    /// sensors and encoders) or augmented (the nearer of real and virtual, per sensor). Real and
    /// augmented attach to the physical chair of this name, whose adapter (`iwsim serial`) must
    /// be registered first.
    #[arg(long = "sensors", visible_alias = "mode", value_enum, default_value_t = Mode::Virtual)]
    pub mode: Mode,
    /// Claim doorways and other one-lane zones by message before entering them, first come
    /// first served (beyond the thesis; off by default while it is tuned for many chairs).
    #[arg(long)]
    pub zone_claims: bool,
    /// Keep right in two-lane corridors: the planner's cost per metre driven per metre left
    /// of the lane's middle (0: off, the default while it is tuned for many chairs).
    #[arg(long, value_name = "COST", default_value_t = 0.0, value_parser = parse_keep_right)]
    pub keep_right: f64,
    /// Bound each tick's path search to N expansions; a longer search goes on in the next
    /// ticks while the chair stands. Default: 4000 when the hub runs in real time (a few tens
    /// of milliseconds, so the answer comes within the 100 ms cycle and the chair is not left
    /// driving on a stale command while the navigator thinks), none in lock-step (each
    /// search ends in its tick; the hub waits). In lock-step a bound keeps one chair's long
    /// search from holding the run, and changes how traffic goes.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(100..))]
    pub plan_allowance: Option<u64>,
    /// Correct the pose estimate's position from proximity readings of the map's walls: the
    /// share of each reading's disagreement taken per tick (0, the default: off; 0.01 works).
    /// Fewer wall contacts, but not more chairs home in a crowd (docs/agents.md).
    #[arg(long, value_name = "GAIN", default_value_t = 0.0, value_parser = parse_gain)]
    pub wall_fix: f64,
}

fn parse_gain(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && (0.0..=0.5).contains(&v) => Ok(v),
        _ => Err(format!("{s:?}: a gain from 0 to 0.5")),
    }
}

fn parse_keep_right(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && (0.0..=100.0).contains(&v) => Ok(v),
        _ => Err(format!("{s:?}: a cost from 0 to 100")),
    }
}

fn parse_checkpoint(s: &str) -> Result<places::Checkpoint, String> {
    places::Checkpoint::parse(s).map_err(|e| e.to_string())
}

fn parse_body(s: &str) -> Result<[f64; 3], String> {
    let v = agent_sdk::args::fixed::<3>(s, "a body W,H,COM", None)?;
    if v[0] <= 0.0 || v[1] <= 0.0 || !(v[2] > 0.0 && v[2] < 1.0) {
        return Err(format!("{s:?}: W and H must be positive and COM in (0, 1)"));
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        args: NavigatorArgs,
    }

    #[test]
    fn options_parse_with_negative_numbers_and_defaults() {
        let cli = Cli::try_parse_from([
            "nav",
            "--checkpoint",
            "10,6.1",
            "--checkpoint",
            "20,-6.1,0.3",
            "--pose",
            "-1,2,-90",
            "--pose-source",
            "fused",
        ])
        .expect("valid");
        let a = cli.args;
        let cp = |x, y, radius| places::Checkpoint { x, y, radius };
        assert_eq!(a.checkpoints, vec![cp(10.0, 6.1, 0.5), cp(20.0, -6.1, 0.3)]);
        assert_eq!(a.robot.pose, Some([-1.0, 2.0, -90.0]));
        assert_eq!(a.body, [1.1, 0.65, 0.8]);
        assert_eq!((a.max_speed, a.accel_curve, a.mode), (0.49, 0.83, Mode::Virtual));
        assert_eq!(a.pose_source, PoseSourceKind::Fused);
        assert!(Cli::try_parse_from(["nav"]).is_err(), "a checkpoint is required");
        assert!(Cli::try_parse_from(["nav", "--checkpoint", "1"]).is_err());
        assert!(Cli::try_parse_from(["nav", "--checkpoint", "1,2", "--body", "1,1,1"]).is_err());
        assert!(Cli::try_parse_from(["nav", "--checkpoint", "1,2", "--sensors", "augmented"]).is_ok());
    }
}
