//! The navigator in closed loop with the hub's world model, in-process: the world steps with
//! noise on (the wheels slipping as the hub's default has them), its readings reach the
//! navigator as the SDK's sensor blocks carry them, and the map reaches it as the hub
//! publishes it (scenario obstacles flagged, so the navigator must find them with its sensors).
//!
//! Each run prints a line (time, contacts, the chair's closest approach to anything, where it
//! stopped) with `--nocapture`. For development: `NAV_SEEDS=21-120` runs other seeds (lists
//! and ranges, comma-separated) and `NAV_TRACE=1` prints every tick of every run (true and
//! estimated pose, powers, unexplained readings, each plan with the sensed map around the
//! slalom); by default the seeds are the fixed ones each test names.

use ipc_types::{MapHeader, MapItem, SensorBlock};
use navigator::geom::{Footprint, Pose, V2};
use navigator::map::NavMap;
use navigator::sensors::Input;
use navigator::{Body, Checkpoint, NavConfig, NavEvent, Navigator, PoseSourceKind};
use world::map::{Grid, Lab, NoiseParams, Params, Wall, builtin};
use world::{Action, ProximitySpec, Robot, RobotSpec, World};

/// A run to simulate.
#[derive(Debug, Clone)]
struct Scenario {
    map: &'static str,
    /// Scenario obstacles: boxes x0, y0, x1, y1 (1 m tall), unknown to the navigator.
    obstacles: Vec<[f64; 4]>,
    start: [f64; 3],
    checkpoints: Vec<places::Checkpoint>,
    body: Body,
    time_limit_s: f64,
    /// Where the navigator's pose comes from.
    pose_source: PoseSourceKind,
    /// GPS on with this noise (metres, degrees); off when `None`.
    gps: Option<[f64; 2]>,
    /// Encoder slip, a fraction per tick.
    encoder_slip_frac: f64,
}

impl Scenario {
    /// The Intellwheels chair on `map` from `start` through `checkpoints` (X, Y, radius),
    /// no obstacles, pose from odometry, GPS off, the hub's default noise and wheel slip.
    fn route(map: &'static str, start: [f64; 3], checkpoints: &[[f64; 3]], time_limit_s: f64) -> Self {
        Self {
            map,
            obstacles: vec![],
            start,
            checkpoints: checkpoints.iter().map(|&[x, y, radius]| places::Checkpoint { x, y, radius }).collect(),
            body: Body::INTELLWHEELS,
            time_limit_s,
            pose_source: PoseSourceKind::Odometry,
            gps: None,
            encoder_slip_frac: NoiseParams::default().encoder_slip_frac,
        }
    }
}

/// How a run went.
#[derive(Debug, Clone, PartialEq)]
struct Outcome {
    seed: u64,
    finished: bool,
    reached: usize,
    time_s: f64,
    contacts: u64,
    min_clearance_m: f64,
    end: V2,
    plans: u32,
    expansions: u64,
    /// The farthest the navigator's estimate was from the chair's true position, metres.
    max_position_error_m: f64,
    /// Likewise for the heading, degrees.
    max_heading_error_deg: f64,
    /// For each checkpoint the navigator said it reached, how far the chair truly was from
    /// its centre then, metres (the judge counts it only within its radius).
    reached_true_m: Vec<f64>,
}

/// The map exactly as the hub publishes it (`hub::core::pack_map`): walls from `obstacle_from`
/// on are flagged as the scenario's obstacles.
fn map_items(
    lab: &Lab,
    params: &Params,
    obstacle_from: usize,
    checkpoints: &[places::Checkpoint],
) -> (MapHeader, Vec<MapItem>) {
    let hub_params = hub::core::hub_params(params, hub::core::Mode::LockStep, 0, 1000);
    hub::core::pack_map(lab, &Grid::default(), obstacle_from, checkpoints, 100, hub_params)
}

/// A robot's sensor block exactly as the hub packs it (`hub::core::pack_sensor_block`).
fn sensor_block(r: &Robot, tick: u64) -> SensorBlock {
    hub::core::pack_sensor_block(r, 1, tick, |_| 2)
}

/// The chair's true clearance to every wall and obstacle of the lab.
fn clearance(lab: &Lab, fp: &Footprint, r: &Robot) -> f64 {
    let pose = Pose::new(r.pose.x, r.pose.y, r.pose.theta);
    let mut best = f64::INFINITY;
    for w in &lab.walls {
        let n = w.corners.len();
        for i in 0..n {
            let (a, b) = (w.corners[i], w.corners[(i + 1) % n]);
            let (a, b) = (pose.to_body(V2::new(a.x, a.y)), pose.to_body(V2::new(b.x, b.y)));
            best = best.min(fp.body_segment_distance(a, b));
        }
    }
    best
}

/// The chair the navigator is configured for, as the hub would register it.
fn chair_spec(cfg: &NavConfig, name: &str) -> RobotSpec {
    let sensors = cfg
        .sensors
        .iter()
        .map(|m| ProximitySpec {
            x_m: m.x_m,
            y_m: m.y_m,
            angle_rad: m.angle_rad,
            cone_rad: m.cone_rad,
            range_m: Some(m.range_m),
        })
        .collect();
    RobotSpec::at(cfg.start.x, cfg.start.y, sim_model::wire_deg(cfg.start.theta))
        .body(cfg.body.width_m, cfg.body.height_m, cfg.body.com)
        .motors(cfg.max_speed_mps, cfg.accel_curve)
        .sensors(sensors)
        .named(name)
}

/// A trace line's middle: the chair's true pose, the navigator's estimate and the powers.
fn trace_pose(robot: &Robot, est: Pose, powers: [f64; 2]) -> String {
    format!(
        "true ({:.3}, {:.3}, {:6.1}°) est ({:.3}, {:.3}) powers ({:+.2}, {:+.2})",
        robot.pose.x,
        robot.pose.y,
        robot.pose.heading_deg(),
        est.x,
        est.y,
        powers[0],
        powers[1]
    )
}

/// The seeds to run: `NAV_SEEDS` (lists and ranges, comma-separated) when set, else `default`.
fn seed_list(default: std::ops::RangeInclusive<u64>) -> Vec<u64> {
    match std::env::var_os("NAV_SEEDS") {
        Some(v) => v
            .to_string_lossy()
            .split(',')
            .flat_map(|t| match t.split_once('-') {
                Some((a, b)) => (a.parse().unwrap_or(1)..=b.parse().unwrap_or(0)).collect::<Vec<u64>>(),
                None => t.parse().ok().into_iter().collect(),
            })
            .collect(),
        None => default.collect(),
    }
}

fn simulate(s: &Scenario, seed: u64) -> Outcome {
    let trace = std::env::var_os("NAV_TRACE").is_some();
    let map = builtin::map(s.map).expect("a built-in map");
    let mut lab = map.lab.clone();
    let known = lab.walls.len();
    for &[x0, y0, x1, y1] in &s.obstacles {
        lab.walls.push(Wall::rectangle(x0, y0, x1, y1, 1.0));
    }
    let mut params = Params::default();
    assert!(params.noise.proximity_m > 0.0 && params.noise.motor_frac > 0.0, "noise on");
    params.noise.encoder_slip_frac = s.encoder_slip_frac;
    if let Some([pos_m, heading_deg]) = s.gps {
        params.sensors.gps = true;
        (params.noise.gps_pos_m, params.noise.gps_heading_deg) = (pos_m, heading_deg);
    }
    let mut world = World::new(&lab, params, seed).expect("a valid world");
    let (header, items) = map_items(&lab, world.params(), known, &s.checkpoints);
    // The scale the navigator agent reads from the hub's map header.
    let ticks_per_m = header.params.encoder_ticks_per_m;
    let base = NavConfig::intellwheels();
    let cfg = NavConfig {
        body: s.body,
        sensors: navigator::sensors::default_layout(&s.body.footprint()),
        checkpoints: s.checkpoints.iter().map(Checkpoint::from).collect(),
        start: Pose::from_deg(s.start[0], s.start[1], s.start[2]),
        encoder_ticks_per_m: ticks_per_m,
        pose_source: s.pose_source,
        // As the agent reads it from the hub's map header.
        proximity_noise_m: header.params.noise_proximity_m,
        ..base
    };
    let handle = world.add_robot(chair_spec(&cfg, "chair")).expect("a valid chair");
    world.refresh_sensors();
    let nav_map = NavMap::from_items(&header, &items).expect("the published map reads back");
    let fp = s.body.footprint();
    let mut nav = Navigator::new(nav_map, cfg);
    let mut min_clearance = f64::INFINITY;
    let mut finished_at = None;
    let limit = (s.time_limit_s / 0.1).round() as u64;
    let mut last_plans = 0;
    let (mut max_position_error, mut max_heading_error) = (0.0f64, 0.0f64);
    let mut reached_true_m = Vec::new();
    for tick in 0..=limit {
        let robot = world.robot(handle).expect("the chair");
        min_clearance = min_clearance.min(clearance(&lab, &fp, robot));
        let time_s = tick as f64 * 0.1;
        let block = sensor_block(robot, tick);
        let input = Input::from_block(&block, time_s);
        let out = nav.step(&input);
        // The estimate the navigator steered by this tick, against where the chair was.
        let est = nav.pose();
        max_position_error = max_position_error.max((est.pos() - V2::new(robot.pose.x, robot.pose.y)).norm());
        max_heading_error = max_heading_error.max(sim_model::wrap_rad(est.theta - robot.pose.theta).abs().to_degrees());
        if trace {
            eprintln!(
                "seed {seed} t {time_s:5.1} {} clr {:.3}",
                trace_pose(robot, nav.pose(), out.powers),
                clearance(&lab, &fp, robot)
            );
            for e in &out.events {
                eprintln!("seed {seed} event {e:?}");
            }
            for (k, m) in nav.config().sensors.iter().enumerate() {
                let cone = m.cone(&nav.pose());
                let (d, e) = (input.proximity_m[k], nav.model().expected_reading(&cone, m.range_m));
                if e - d > 0.25 && d < m.range_m - 0.2 {
                    let hit = cone.apex + V2::unit(cone.dir) * d;
                    eprintln!("seed {seed}   sensor {k}: {d:.2} (walls {e:.2}) at ({:.2}, {:.2})", hit.x, hit.y);
                }
            }
            if nav.stats().plans != last_plans {
                last_plans = nav.stats().plans;
                let path = nav.path();
                let summary: Vec<String> = path
                    .iter()
                    .step_by(4)
                    .map(|p| format!("({:.2},{:.2},{:.0})", p.x, p.y, p.theta.to_degrees()))
                    .collect();
                eprintln!("seed {seed} plan {} ({} poses): {}", last_plans, path.len(), summary.join(" "));
                eprintln!("{}", ascii_map(&nav, 14.5, 20.5, 5.0, 7.0));
            }
        }
        if out.events.iter().any(|e| matches!(e, NavEvent::Finished { .. })) {
            finished_at = Some(time_s);
        }
        for e in &out.events {
            if let NavEvent::Reached { index, .. } = e {
                let c = &s.checkpoints[*index];
                reached_true_m.push((robot.pose.x - c.x).hypot(robot.pose.y - c.y));
            }
        }
        // After the end, keep stepping a little with the powers it sends (zero): the chair
        // must come to rest without touching anything.
        if let Some(t) = finished_at
            && time_s > t + 2.0
        {
            break;
        }
        world.step(&[Action::motors(handle, out.powers[0], out.powers[1])], 0.1);
    }
    let robot = world.robot(handle).expect("the chair");
    Outcome {
        seed,
        finished: nav.finished(),
        reached: nav.next_checkpoint(),
        time_s: finished_at.unwrap_or(f64::INFINITY),
        contacts: robot.collision_count,
        min_clearance_m: min_clearance,
        end: V2::new(robot.pose.x, robot.pose.y),
        plans: nav.stats().plans,
        expansions: nav.stats().expansions,
        max_position_error_m: max_position_error,
        max_heading_error_deg: max_heading_error,
        reached_true_m,
    }
}

/// The sensed obstacles in a window, one character per cell: `#` known wall, `o` sensed.
fn ascii_map(nav: &Navigator, x0: f64, x1: f64, y0: f64, y1: f64) -> String {
    let m = nav.model();
    let spec = m.spec();
    let mut rows = Vec::new();
    let (cx0, cy0) = spec.clamp_cell(V2::new(x0, y0));
    let (cx1, cy1) = spec.clamp_cell(V2::new(x1, y1));
    for iy in (cy0..=cy1).rev() {
        let mut row = format!("{:5.2} ", spec.center(0, iy).y);
        for ix in cx0..=cx1 {
            let i = spec.index(ix, iy);
            row.push(if m.statics.occupied(i) {
                '#'
            } else if m.sensed.occupied(i) {
                'o'
            } else if m.sensed.evidence(i) > 0.0 {
                '.'
            } else {
                ' '
            });
        }
        rows.push(row);
    }
    rows.join("\n")
}

/// Runs every seed, two at a time.
fn simulate_seeds(s: &Scenario, seeds: std::ops::RangeInclusive<u64>) -> Vec<Outcome> {
    let seeds = seed_list(seeds);
    let workers = std::thread::available_parallelism().map_or(2, |n| n.get()).clamp(1, 4);
    let mut out: Vec<Outcome> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..workers)
            .map(|w| {
                let seeds = &seeds;
                scope.spawn(move || {
                    seeds.iter().skip(w).step_by(workers).map(|&seed| simulate(s, seed)).collect::<Vec<_>>()
                })
            })
            .collect();
        handles.into_iter().flat_map(|h| h.join().expect("a simulation thread")).collect()
    });
    out.sort_by_key(|o| o.seed);
    for o in &out {
        eprintln!(
            "{}: seed {:2}: {} of {} checkpoints, t {:.1} s, {} contacts, min clearance {:.3} m, end ({:.2}, {:.2}), {} plans, {} expansions, pose error up to {:.3} m / {:.1}°, checkpoints counted up to {:.3} m off in truth",
            s.map,
            o.seed,
            o.reached,
            s.checkpoints.len(),
            o.time_s,
            o.contacts,
            o.min_clearance_m,
            o.end.x,
            o.end.y,
            o.plans,
            o.expansions,
            o.max_position_error_m,
            o.max_heading_error_deg,
            o.reached_true_m.iter().copied().fold(0.0, f64::max)
        );
    }
    out
}

mod slalom {
    use super::*;

    /// Thesis Table 7.3, virtual/automatic: LIACC corridor, start at checkpoint 1 (10.0, 6.1)
    /// heading 0°, stop at checkpoint 2 (20.0, 6.1), boxes A and B in the way.
    pub fn scenario() -> Scenario {
        Scenario {
            obstacles: vec![[17.0, 6.1, 17.6, 6.4], [19.4, 5.5, 20.0, 5.9]],
            ..Scenario::route("liacc", [10.0, 6.1, 0.0], &[[10.0, 6.1, 0.5], [20.0, 6.1, 0.5]], 120.0)
        }
    }

    #[test]
    fn the_intellwheels_chair_clears_the_slalom_on_every_seed_without_a_contact() {
        let s = scenario();
        let outcomes = simulate_seeds(&s, 1..=20);
        assert!(!outcomes.is_empty());
        for o in &outcomes {
            assert!(o.finished && o.reached == 2, "seed {} did not reach checkpoint 2: {o:?}", o.seed);
            assert_eq!(o.contacts, 0, "seed {} touched something: {o:?}", o.seed);
            assert!(o.time_s <= s.time_limit_s);
            assert!((o.end - V2::new(20.0, 6.1)).norm() <= 0.5, "seed {} stopped at {:?}", o.seed, o.end);
        }
    }
}

mod untuned_maps {
    use super::*;

    fn check(s: &Scenario, seeds: std::ops::RangeInclusive<u64>) {
        let outcomes = simulate_seeds(s, seeds);
        assert!(!outcomes.is_empty());
        for o in outcomes {
            assert!(o.finished && o.reached == s.checkpoints.len(), "seed {} did not arrive: {o:?}", o.seed);
            assert_eq!(o.contacts, 0, "seed {} touched something: {o:?}", o.seed);
            // What the navigator counted, the judge counts too: it was truly inside each.
            for (k, (d, c)) in o.reached_true_m.iter().zip(&s.checkpoints).enumerate() {
                assert!(*d <= c.radius, "seed {}: checkpoint {} counted {d:.3} m from its centre", o.seed, k + 1);
            }
            let last = s.checkpoints[s.checkpoints.len() - 1];
            assert!((o.end - V2::new(last.x, last.y)).norm() <= 0.25, "seed {} stopped at {:?}", o.seed, o.end);
        }
    }

    #[test]
    fn from_the_liacc_corridor_through_the_west_door_into_the_south_west_room() {
        let s = Scenario::route("liacc", [14.0, 6.0, 180.0], &[[14.0, 6.0, 0.5], [5.0, 3.0, 0.5]], 120.0);
        check(&s, 1..=3);
    }

    #[test]
    fn from_the_liacc_corridor_through_the_narrow_door_into_the_west_corridor() {
        let s = Scenario::route("liacc", [14.0, 6.0, 180.0], &[[14.0, 6.0, 0.5], [5.0, 8.8, 0.5]], 150.0);
        check(&s, 1..=3);
    }

    #[test]
    fn through_the_maze() {
        let s = Scenario::route("maze", [1.0, 7.0, 90.0], &[[1.0, 7.0, 0.5], [9.0, 1.0, 0.5]], 200.0);
        check(&s, 1..=3);
    }

    #[test]
    fn a_mid_wheel_drive_chair_across_the_maze() {
        let s = Scenario {
            body: Body { width_m: 1.0, height_m: 0.6, com: 0.5 },
            ..Scenario::route("maze", [1.0, 13.0, 0.0], &[[1.0, 13.0, 0.5], [13.0, 9.0, 0.5], [25.0, 7.0, 0.5]], 300.0)
        };
        check(&s, 1..=2);
    }

    /// Checkpoints of 0.3 m on the way across the maze: the navigator counts one only well
    /// inside it by its own pose, so the chair passes each inside in truth too (it once
    /// passed them along their edge, and the judge missed some by millimetres).
    #[test]
    fn small_checkpoints_on_the_way_are_passed_inside_in_truth() {
        let s = Scenario {
            body: Body { width_m: 1.0, height_m: 0.6, com: 0.5 },
            ..Scenario::route(
                "maze",
                [1.0, 13.0, 0.0],
                &[[1.0, 13.0, 0.3], [7.0, 13.0, 0.3], [13.0, 9.0, 0.3], [19.0, 9.0, 0.3], [25.0, 7.0, 0.3]],
                300.0,
            )
        };
        // Seed 3 counted checkpoint 2 at 0.302 m in truth under the old rule.
        check(&s, 1..=4);
    }

    /// The west-door route again, the pose from GPS alone: an indoor positioning system of
    /// 2 cm and 1° (the GPS sensor with its noise set so).
    #[test]
    fn through_the_west_door_on_a_precise_gps_alone() {
        let s = Scenario {
            pose_source: PoseSourceKind::Gps,
            gps: Some([0.02, 1.0]),
            ..Scenario::route("liacc", [14.0, 6.0, 180.0], &[[14.0, 6.0, 0.5], [5.0, 3.0, 0.5]], 120.0)
        };
        check(&s, 1..=3);
    }

    /// And with odometry corrected by Ciber-Rato's default GPS (0.5 m, 5°): the fusion keeps
    /// the GPS's noise out of the path while it holds odometry's drift in check.
    #[test]
    fn through_the_west_door_on_odometry_fused_with_a_noisy_gps() {
        let s = Scenario {
            pose_source: PoseSourceKind::Fused,
            gps: Some([0.5, 5.0]),
            ..Scenario::route("liacc", [14.0, 6.0, 180.0], &[[14.0, 6.0, 0.5], [5.0, 3.0, 0.5]], 120.0)
        };
        check(&s, 1..=3);
    }

    #[test]
    fn round_the_thesis_maps_wall_into_the_pocket_of_the_l() {
        let s = Scenario::route("thesis", [3.0, 7.0, 0.0], &[[3.0, 7.0, 0.5], [19.5, 8.5, 0.5]], 150.0);
        check(&s, 1..=3);
    }
}

mod slip {
    use super::*;

    /// What a run with slipping wheels must show: it arrives untouched, and the navigator knew
    /// where it was all along, to within what its clearances can absorb.
    fn check(s: &Scenario, seeds: std::ops::RangeInclusive<u64>) -> Vec<Outcome> {
        assert!(s.encoder_slip_frac > 0.0, "the wheels slip");
        let outcomes = simulate_seeds(s, seeds);
        assert!(!outcomes.is_empty());
        for o in &outcomes {
            assert!(o.finished && o.reached == s.checkpoints.len(), "seed {} did not arrive: {o:?}", o.seed);
            assert_eq!(o.contacts, 0, "seed {} touched something: {o:?}", o.seed);
            assert!(
                o.max_position_error_m < 0.10,
                "seed {}: the estimate strayed {:.3} m",
                o.seed,
                o.max_position_error_m
            );
            assert!(
                o.max_heading_error_deg < 3.0,
                "seed {}: the heading strayed {:.1}°",
                o.seed,
                o.max_heading_error_deg
            );
        }
        outcomes
    }

    /// The slalom with the hub's default slip (2 % a tick): the drift that pure dead reckoning
    /// would gather over the 10 m (about 2° and 0.2 m, see `world::map::NoiseParams::WHEELCHAIR`)
    /// is more than the 0.2–0.4 m gaps past boxes A and B allow; the compass-held odometry
    /// keeps the estimate within 10 cm.
    #[test]
    fn with_the_wheels_slipping_the_chair_knows_where_it_is_through_the_slalom() {
        let s = slalom::scenario();
        assert_eq!(s.encoder_slip_frac, NoiseParams::WHEELCHAIR.encoder_slip_frac);
        check(&s, 1..=5);
    }

    /// Twice the default slip on the longest route (the maze, about 20 m with many turns).
    #[test]
    fn with_twice_the_slip_the_chair_still_knows_where_it_is_through_the_maze() {
        let s = Scenario {
            encoder_slip_frac: 2.0 * NoiseParams::WHEELCHAIR.encoder_slip_frac,
            ..Scenario::route("maze", [1.0, 7.0, 90.0], &[[1.0, 7.0, 0.5], [9.0, 1.0, 0.5]], 200.0)
        };
        check(&s, 1..=3);
    }
}

mod corridor_swap {
    use super::*;
    use navigator::Pilot;
    use world::Message;

    /// One chair of a meeting: where it starts and where it goes.
    struct Chair {
        name: &'static str,
        start: [f64; 3],
        goal: [f64; 2],
    }

    /// How each chair did, and how near the two came.
    #[derive(Debug)]
    struct Swap {
        seed: u64,
        /// Per chair: arrived, arrival time, contacts, end.
        chairs: Vec<(bool, f64, u64, V2)>,
        /// The least distance between the two chairs' rectangles, metres.
        min_gap_m: f64,
        /// The least clearance of either chair to a wall, metres.
        min_clearance_m: f64,
        /// The least distance between any two chairs' rectangles, the silent ones included.
        min_gap_any_m: f64,
        /// Contacts of the silent chairs.
        silent_contacts: u64,
    }

    /// A chair that is not a navigator (a teleop chair, a Ciber-Rato robot): it says nothing
    /// and stands where it started.
    struct Silent {
        name: &'static str,
        start: [f64; 3],
    }

    /// What else a run has beside its navigators.
    #[derive(Default)]
    struct Extra {
        silent: Vec<Silent>,
        /// Of the messages each navigator would hear, this percentage is lost (drawn per
        /// message from the seed, the tick and the listener).
        loss_pct: u64,
    }

    /// Whether the `k`-th message `listener` would hear at `tick` is lost.
    fn lost(seed: u64, tick: u64, listener: usize, k: usize, loss_pct: u64) -> bool {
        // splitmix64 of the four: a fixed, well-mixed draw.
        let mut z = seed
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .wrapping_add(tick << 20)
            .wrapping_add((listener as u64) << 8)
            .wrapping_add(k as u64);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        z % 100 < loss_pct
    }

    /// The distance between two chairs' rectangles (0 when they overlap).
    fn gap(fp: &Footprint, a: &Robot, b: &Robot) -> f64 {
        let pa = Pose::new(a.pose.x, a.pose.y, a.pose.theta);
        let pb = Pose::new(b.pose.x, b.pose.y, b.pose.theta);
        if fp.meets(&pa, fp, &pb, 0.0) {
            return 0.0;
        }
        let (ca, cb) = (fp.corners(&pa, 0.0), fp.corners(&pb, 0.0));
        let mut best = f64::INFINITY;
        for k in 0..4 {
            let (a0, a1) = (pb.to_body(ca[k]), pb.to_body(ca[(k + 1) % 4]));
            let (b0, b1) = (pa.to_body(cb[k]), pa.to_body(cb[(k + 1) % 4]));
            best = best.min(fp.body_segment_distance(a0, a1)).min(fp.body_segment_distance(b0, b1));
        }
        best
    }

    fn simulate(chairs: &[Chair], seconds: f64, seed: u64) -> Swap {
        simulate_on("liacc", chairs, seconds, seed, false, 0.0)
    }

    /// As [`simulate`], on built-in map `map`, with the zone rule on when `zone_claims` and
    /// chairs keeping right at `keep_right` (0: off).
    fn simulate_on(map: &str, chairs: &[Chair], seconds: f64, seed: u64, zone_claims: bool, keep_right: f64) -> Swap {
        simulate_with(map, chairs, seconds, seed, zone_claims, keep_right, &Extra::default())
    }

    /// As [`simulate_on`], with silent chairs and lost messages.
    fn simulate_with(
        map: &str,
        chairs: &[Chair],
        seconds: f64,
        seed: u64,
        zone_claims: bool,
        keep_right: f64,
        extra: &Extra,
    ) -> Swap {
        let trace = std::env::var_os("NAV_TRACE").is_some();
        let lab = builtin::map(map).expect("a built-in map").lab.clone();
        let params = Params::default();
        assert!(params.noise.encoder_slip_frac > 0.0, "the wheels slip");
        let mut world = World::new(&lab, params, seed).expect("a valid world");
        let body = Body::INTELLWHEELS;
        let fp = body.footprint();
        let checkpoints: Vec<places::Checkpoint> =
            chairs.iter().map(|c| places::Checkpoint { x: c.goal[0], y: c.goal[1], radius: 0.5 }).collect();
        let (header, items) = map_items(&lab, world.params(), lab.walls.len(), &checkpoints);
        let ticks_per_m = header.params.encoder_ticks_per_m;
        let mut fleet = Vec::new();
        for (c, goal) in chairs.iter().zip(&checkpoints) {
            let cfg = NavConfig {
                checkpoints: vec![Checkpoint::from(goal)],
                start: Pose::from_deg(c.start[0], c.start[1], c.start[2]),
                encoder_ticks_per_m: ticks_per_m,
                keep_right,
                proximity_noise_m: header.params.noise_proximity_m,
                ..NavConfig::intellwheels()
            };
            let handle = world.add_robot(chair_spec(&cfg, c.name)).expect("a valid chair");
            let nav_map = NavMap::from_items(&header, &items).expect("the published map reads back");
            let pilot = Pilot::new(c.name, Navigator::new(nav_map, cfg));
            let pilot = if zone_claims { pilot.with_zone_claims() } else { pilot };
            fleet.push((handle, pilot, None::<f64>));
        }
        let mut silent = Vec::new();
        for q in &extra.silent {
            let cfg =
                NavConfig { start: Pose::from_deg(q.start[0], q.start[1], q.start[2]), ..NavConfig::intellwheels() };
            silent.push(world.add_robot(chair_spec(&cfg, q.name)).expect("a valid chair"));
        }
        world.refresh_sensors();
        let mut min_gap = f64::INFINITY;
        let mut min_gap_any = f64::INFINITY;
        let mut min_clearance = f64::INFINITY;
        let limit = (seconds / 0.1).round() as u64;
        for tick in 0..=limit {
            let time_s = tick as f64 * 0.1;
            let mut actions = Vec::new();
            for (listener, (handle, pilot, done)) in fleet.iter_mut().enumerate() {
                let name = pilot.name().to_owned();
                let robot = world.robot(*handle).expect("a chair");
                min_clearance = min_clearance.min(clearance(&lab, &fp, robot));
                let block = sensor_block(robot, tick);
                let input = Input::from_block(&block, time_s);
                let heard: Vec<&[u8]> = robot
                    .inbox
                    .iter()
                    .enumerate()
                    .filter(|&(k, _)| !lost(seed, tick, listener, k, extra.loss_pct))
                    .map(|(_, h)| h.message.as_bytes())
                    .collect();
                let out = pilot.tick(&input, heard);
                if trace {
                    eprintln!(
                        "seed {seed} t {time_s:5.1} {name} {} {:?}",
                        trace_pose(robot, pilot.navigator().pose(), out.powers),
                        pilot.traffic().state()
                    );
                    for n in out.notes.iter().map(|n| n.to_string()).chain(out.events.iter().map(|e| format!("{e:?}")))
                    {
                        eprintln!("seed {seed} {name}: {n}");
                    }
                }
                if done.is_none() && pilot.navigator().finished() {
                    *done = Some(time_s);
                }
                let mut action = Action::motors(*handle, out.powers[0], out.powers[1]);
                action.say = out.say.as_deref().map(|s| Message::new(s.as_bytes()).expect("a short message"));
                actions.push(action);
            }
            for handle in &silent {
                actions.push(Action::motors(*handle, 0.0, 0.0));
            }
            let (a, b) = (&fleet[0].0, &fleet[1].0);
            min_gap = min_gap.min(gap(&fp, world.robot(*a).expect("a chair"), world.robot(*b).expect("a chair")));
            let all: Vec<_> = fleet.iter().map(|f| f.0).chain(silent.iter().copied()).collect();
            for (i, a) in all.iter().enumerate() {
                for b in &all[i + 1..] {
                    let (ra, rb) = (world.robot(*a).expect("a chair"), world.robot(*b).expect("a chair"));
                    min_gap_any = min_gap_any.min(gap(&fp, ra, rb));
                }
            }
            if fleet.iter().all(|(_, _, done)| done.is_some_and(|t| time_s > t + 2.0)) {
                break;
            }
            world.step(&actions, 0.1);
        }
        let chairs = fleet
            .iter()
            .map(|(h, pilot, done)| {
                let r = world.robot(*h).expect("a chair");
                (
                    pilot.navigator().finished(),
                    done.unwrap_or(f64::INFINITY),
                    r.collision_count,
                    V2::new(r.pose.x, r.pose.y),
                )
            })
            .collect();
        let silent_contacts = silent.iter().map(|h| world.robot(*h).expect("a chair").collision_count).sum();
        Swap {
            seed,
            chairs,
            min_gap_m: min_gap,
            min_clearance_m: min_clearance,
            min_gap_any_m: min_gap_any,
            silent_contacts,
        }
    }

    /// The built-in corridor-swap scenario: chair1 east from (14.5, 6.0), chair2 west from
    /// (24.5, 6.0), in the 1.78 m LIACC corridor; both must arrive without touching anything.
    #[test]
    fn two_chairs_meeting_head_on_in_the_corridor_agree_and_both_arrive_untouched() {
        let chairs = [
            Chair { name: "chair1", start: [14.5, 6.0, 0.0], goal: [24.5, 6.0] },
            Chair { name: "chair2", start: [24.5, 6.0, 180.0], goal: [14.5, 6.0] },
        ];
        let runs: Vec<Swap> = std::thread::scope(|scope| {
            let handles: Vec<_> = seed_list(1..=3)
                .into_iter()
                .map(|seed| {
                    scope.spawn({
                        let chairs = &chairs;
                        move || simulate(chairs, 150.0, seed)
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().expect("a simulation thread")).collect()
        });
        assert!(!runs.is_empty());
        for r in &runs {
            eprintln!("corridor swap: {r:?}");
        }
        for r in &runs {
            for (k, (arrived, t, contacts, end)) in r.chairs.iter().enumerate() {
                let goal = V2::new(chairs[k].goal[0], chairs[k].goal[1]);
                assert!(*arrived && *t <= 150.0, "seed {}: {} did not arrive: {r:?}", r.seed, chairs[k].name);
                assert_eq!(*contacts, 0, "seed {}: {} touched something: {r:?}", r.seed, chairs[k].name);
                assert!((*end - goal).norm() <= 0.5, "seed {}: {} stopped at {end:?}", r.seed, chairs[k].name);
            }
            assert!(r.min_gap_m > 0.05, "seed {}: the chairs came within {:.3} m", r.seed, r.min_gap_m);
            assert!(r.min_clearance_m > 0.02, "seed {}: {:.3} m from a wall", r.seed, r.min_clearance_m);
        }
    }

    /// A deadlock made on purpose: four chairs meet where two doorways face each other
    /// across the ward's corridor, one from each room and one along the corridor each way,
    /// each bound across the junction. They keep right and claim doorways, as `builtin:ward`
    /// has them. None touches anything, and all four arrive within 150 s, on every seed
    /// (1–4 here; on seeds 1–10 the last arrives within 104 s). Before chairs passing a
    /// doorway along the corridor stopped claiming it, seed 3 stayed knotted: chair4 gave way
    /// in the north room at x 17.5 and chair3, parked at its goal in front of that doorway,
    /// shut it in (on seeds 1–10, 7 untied; without doorway claims at all, 9).
    #[test]
    fn four_chairs_knotted_at_a_ward_junction_never_touch_and_untie_it() {
        let chairs = [
            Chair { name: "chair1", start: [12.5, 3.2, 90.0], goal: [12.5, 11.0] },
            Chair { name: "chair2", start: [12.5, 10.8, -90.0], goal: [12.5, 2.8] },
            Chair { name: "chair3", start: [8.0, 6.5, 0.0], goal: [17.5, 6.5] },
            Chair { name: "chair4", start: [17.0, 7.5, 180.0], goal: [7.5, 7.5] },
        ];
        let limit = 150.0;
        let runs: Vec<Swap> = std::thread::scope(|scope| {
            let handles: Vec<_> = seed_list(1..=4)
                .into_iter()
                .map(|seed| {
                    scope.spawn({
                        let chairs = &chairs;
                        move || simulate_on("ward", chairs, limit, seed, true, 2.0)
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().expect("a simulation thread")).collect()
        });
        assert!(!runs.is_empty());
        for r in &runs {
            eprintln!("ward junction: {r:?}");
        }
        for r in &runs {
            for (k, (_, _, contacts, _)) in r.chairs.iter().enumerate() {
                assert_eq!(*contacts, 0, "seed {}: {} touched something: {r:?}", r.seed, chairs[k].name);
            }
            assert!(r.min_gap_m > 0.0, "seed {}: two chairs touched", r.seed);
        }
        for r in &runs {
            assert!(r.chairs.iter().all(|c| c.0), "seed {}: not all four arrived within {limit} s: {r:?}", r.seed);
        }
    }

    /// Three chairs in the LIACC corridor (1.78 m): chair2 and chair3 westbound one behind
    /// the other, chair1 eastbound. None touches another or a wall on any of 10 seeds (they
    /// used to: the safety layer now stops short of a chair that said where it is), and all
    /// three arrive on every seed: chair3, with chair2 pulled over just ahead of it, backs
    /// into the side behind chair2 (it stood in the middle on 3 seeds of 10 before it could
    /// pull over backwards, and nobody got by).
    #[test]
    fn three_chairs_in_one_corridor_two_one_way_and_one_the_other_never_touch_and_all_arrive() {
        let chairs = [
            Chair { name: "chair1", start: [13.0, 6.0, 0.0], goal: [25.5, 6.0] },
            Chair { name: "chair2", start: [22.5, 6.0, 180.0], goal: [12.0, 6.0] },
            Chair { name: "chair3", start: [25.0, 6.0, 180.0], goal: [14.5, 6.0] },
        ];
        let limit = 150.0;
        let runs: Vec<Swap> = std::thread::scope(|scope| {
            let handles: Vec<_> = seed_list(1..=10)
                .into_iter()
                .map(|seed| {
                    scope.spawn({
                        let chairs = &chairs;
                        move || simulate(chairs, limit, seed)
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().expect("a simulation thread")).collect()
        });
        assert!(!runs.is_empty());
        for r in &runs {
            eprintln!("three in a corridor: {r:?}");
        }
        for r in &runs {
            for (k, (_, _, contacts, _)) in r.chairs.iter().enumerate() {
                assert_eq!(*contacts, 0, "seed {}: {} touched something: {r:?}", r.seed, chairs[k].name);
            }
            assert!(r.min_gap_m > 0.0, "seed {}: two chairs touched", r.seed);
        }
        let all_arrived = runs.iter().filter(|r| r.chairs.iter().all(|c| c.0)).count();
        assert_eq!(all_arrived, runs.len(), "all three arrived on {all_arrived} of {} seeds", runs.len());
    }

    /// Runs `chairs` (and `extra`) on `map` for `seeds`, a thread each.
    fn runs_with(
        map: &str,
        chairs: &[Chair],
        limit: f64,
        seeds: std::ops::RangeInclusive<u64>,
        extra: &Extra,
    ) -> Vec<Swap> {
        std::thread::scope(|scope| {
            let handles: Vec<_> = seed_list(seeds)
                .into_iter()
                .map(|seed| scope.spawn(move || simulate_with(map, chairs, limit, seed, false, 1.0, extra)))
                .collect();
            handles.into_iter().map(|h| h.join().expect("a simulation thread")).collect()
        })
    }

    /// Nothing touched anything, and (if `arrive`) every navigator arrived within the limit.
    fn untouched(what: &str, chairs: &[Chair], runs: &[Swap], arrive: bool) {
        assert!(!runs.is_empty());
        for r in runs {
            eprintln!("{what}: {r:?}");
        }
        for r in runs {
            for (k, (arrived, _, contacts, _)) in r.chairs.iter().enumerate() {
                assert_eq!(*contacts, 0, "seed {}: {} touched something: {r:?}", r.seed, chairs[k].name);
                assert!(*arrived || !arrive, "seed {}: {} did not arrive: {r:?}", r.seed, chairs[k].name);
            }
            assert_eq!(r.silent_contacts, 0, "seed {}: a silent chair was touched: {r:?}", r.seed);
            assert!(r.min_gap_any_m > 0.0, "seed {}: two chairs touched", r.seed);
        }
    }

    /// A chair that is no navigator (it says nothing) stands broken down in the eastbound
    /// lane of the ward's corridor while two navigators come by, one each way: it is found by
    /// the sensors alone and nobody touches it or anybody else. (Before the safety layer
    /// minded what the sensed map holds, a navigator pulling over pushed into it for a
    /// minute on two of these seeds.) Getting past is not yet sure: on seeds 2 and 3 the
    /// eastbound chair gets round it and arrives, on seed 1 it does not (it did before
    /// doorways stopped ending the corridor's lanes), and the westbound one never does;
    /// arrivals are printed, not asserted.
    #[test]
    fn a_silent_chair_standing_in_the_corridor_is_never_touched() {
        let chairs = [
            Chair { name: "chair1", start: [14.5, 6.5, 0.0], goal: [26.0, 6.5] },
            Chair { name: "chair2", start: [26.5, 7.5, 180.0], goal: [14.0, 7.5] },
        ];
        let extra = Extra { silent: vec![Silent { name: "teleop", start: [20.0, 6.5, 0.0] }], loss_pct: 0 };
        let runs = runs_with("ward", &chairs, 120.0, 1..=3, &extra);
        untouched("silent chair standing", &chairs, &runs, false);
    }

    /// Half of all messages lost: two chairs meeting head-on in the LIACC corridor (1.78 m, too
    /// narrow to pass without one pulling over) still never touch, and both arrive.
    #[test]
    fn with_half_the_messages_lost_two_chairs_meeting_head_on_never_touch() {
        let chairs = [
            Chair { name: "chair1", start: [14.5, 6.0, 0.0], goal: [24.5, 6.0] },
            Chair { name: "chair2", start: [24.5, 6.0, 180.0], goal: [14.5, 6.0] },
        ];
        let extra = Extra { silent: vec![], loss_pct: 50 };
        let runs = std::thread::scope(|scope| {
            let handles: Vec<_> = seed_list(1..=3)
                .into_iter()
                .map(|seed| {
                    let (chairs, extra) = (&chairs, &extra);
                    scope.spawn(move || simulate_with("liacc", chairs, 150.0, seed, false, 0.0, extra))
                })
                .collect();
            handles.into_iter().map(|h| h.join().expect("a simulation thread")).collect::<Vec<_>>()
        });
        untouched("half the messages lost", &chairs, &runs, true);
    }
}

/// The navigator's expected reading (its own cone geometry, used by its safety layer and to
/// tell walls from obstacles) against the hub's world (the readings agents get), noise off, at
/// 300 poses of the ward, each chair at least 5 cm clear of every wall (a sensor inside a wall
/// is no case to agree on: the world reads past a wall it starts in).
mod cone_geometry {
    use super::*;

    #[test]
    fn the_navigators_expected_readings_are_the_worlds() {
        let lab = builtin::map("ward").expect("a built-in map").lab.clone();
        let params = Params { noise: NoiseParams::NONE, ..Params::default() };
        let cfg = NavConfig::intellwheels();
        let (header, items) = map_items(&lab, &params, lab.walls.len(), &[]);
        let nav_map = NavMap::from_items(&header, &items).expect("the published map reads back");
        let model = navigator::model::WorldModel::new(nav_map, cfg.body.footprint());
        let mut worst = (0.0f64, String::new());
        let (mut readings, mut walls_seen) = (0, 0);
        // A fixed LCG: the same poses every run.
        let mut state = 12345u64;
        let mut next = || {
            state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut placed = 0;
        while placed < 300 {
            let pose = Pose::from_deg(1.0 + 38.0 * next(), 1.0 + 12.0 * next(), -180.0 + 360.0 * next());
            if model.wall_clearance(&pose, 1.0) < 0.05 {
                continue;
            }
            let mut world = World::new(&lab, params.clone(), 1).expect("a valid world");
            let cfg = NavConfig { start: pose, ..NavConfig::intellwheels() };
            let handle = world.add_robot(chair_spec(&cfg, "chair")).expect("a chair clear of the walls");
            world.refresh_sensors();
            let r = world.robot(handle).expect("placed");
            placed += 1;
            for (k, (mount, &got)) in cfg.sensors.iter().zip(r.readings.proximity()).enumerate() {
                let expected = model.expected_reading(&mount.cone(&pose), mount.range_m);
                readings += 1;
                walls_seen += usize::from(got < mount.range_m);
                let d = (expected - got).abs();
                if d > worst.0 {
                    worst = (d, format!("{pose:?} sensor {k}: navigator {expected:.4}, world {got:.4}"));
                }
            }
        }
        assert!(walls_seen > readings / 4, "{walls_seen} of {readings} readings saw a wall");
        assert!(worst.0 < 1e-6, "they differ by up to {} m: {}", worst.0, worst.1);
    }
}
