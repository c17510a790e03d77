//! The navigator's planning on the ward (`builtin:ward`): one navigator's first plan (the
//! grid's cost-to-go, then the hybrid search), after five ticks of standing still and looking,
//! from a room, through its doorway, down the 2 m corridor towards another room; alone, with
//! three chairs standing in the corridor that it has never been told of (its sensors find
//! them, as with a chair that is not a navigator), and with two chairs side by side across the
//! corridor ahead, which leave no way past: the search that finds nothing, the costliest.
//!
//! Run: `cargo bench --bench plan`. Each case prints, once, the searches it ran, the nodes
//! they expanded and the ticks the plan took (a search goes on over ticks past a few thousand
//! expansions), so a change's time per search can be told apart from a change in how much it
//! searched; the time is the plan's, over all its ticks.

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use navigator::geom::Pose;
use navigator::map::NavMap;
use navigator::sensors::Input;
use navigator::{Checkpoint, NavConfig, Navigator};
use sim_model::PoseDeg;
use world::map::{Grid, Params, builtin};
use world::{ProximitySpec, RobotSpec, World};

/// A case: the chair's start (x, y, heading in degrees), its goal, and chairs standing where
/// it will pass (x, y, heading).
struct Case {
    name: &'static str,
    start: PoseDeg,
    goal: [f64; 2],
    standing: &'static [PoseDeg],
}

const CASES: &[Case] = &[
    // Out of a room on the south side, along the corridor, into a room on the north side.
    Case { name: "room_to_room", start: [7.5, 3.0, 90.0], goal: [22.5, 11.0], standing: &[] },
    // Straight down the corridor.
    Case { name: "corridor", start: [4.0, 7.0, 0.0], goal: [30.0, 7.0], standing: &[] },
    // As the first, with chairs standing in the corridor just beyond the doorway.
    Case {
        name: "room_to_room_past_chairs",
        start: [7.5, 3.0, 90.0],
        goal: [22.5, 11.0],
        standing: &[[10.0, 6.6, 0.0], [13.0, 7.4, 180.0], [16.5, 6.6, 0.0]],
    },
    // Two chairs side by side across the corridor, 2 m ahead: no way past.
    Case {
        name: "corridor_blocked",
        start: [9.0, 7.0, 0.0],
        goal: [30.0, 7.0],
        standing: &[[11.6, 6.5, 90.0], [11.6, 7.5, 90.0]],
    },
];

/// Ticks the navigator stands and looks before the timed plan: its sensed map holds what its
/// sensors see from the start, as when it plans again after waiting.
const LOOK_TICKS: u64 = 5;

/// The world of a case and a navigator that has not yet planned, as the hub and the agent
/// would set them up.
fn setup(case: &Case) -> (World, world::RobotHandle, Navigator) {
    let lab = builtin::map("ward").expect("the ward is built in").lab.clone();
    let mut world = World::new(&lab, Params::default(), 1).expect("a valid world");
    let goal = places::Checkpoint { x: case.goal[0], y: case.goal[1], radius: 0.5 };
    let hub_params = hub::core::hub_params(world.params(), hub::core::Mode::LockStep, 0, 1000);
    let (header, items) =
        hub::core::pack_map(&lab, &Grid::default(), lab.walls.len(), std::slice::from_ref(&goal), 100, hub_params);
    let cfg = NavConfig {
        checkpoints: vec![Checkpoint::from(&goal)],
        start: Pose::from_deg(case.start[0], case.start[1], case.start[2]),
        encoder_ticks_per_m: header.params.encoder_ticks_per_m,
        ..NavConfig::intellwheels()
    };
    let sensors: Vec<ProximitySpec> = cfg
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
    let spec = |x: f64, y: f64, deg: f64, name: String| {
        RobotSpec::at(x, y, deg)
            .body(cfg.body.width_m, cfg.body.height_m, cfg.body.com)
            .motors(cfg.max_speed_mps, cfg.accel_curve)
            .sensors(sensors.clone())
            .named(&name)
    };
    let handle = world.add_robot(spec(case.start[0], case.start[1], case.start[2], "chair".into())).expect("a chair");
    for (k, &[x, y, deg]) in case.standing.iter().enumerate() {
        world.add_robot(spec(x, y, deg, format!("standing{k}"))).expect("a standing chair");
    }
    world.refresh_sensors();
    let mut nav = Navigator::new(NavMap::from_items(&header, &items).expect("the map reads back"), cfg);
    nav.hold();
    for tick in 0..LOOK_TICKS {
        tick_on(&world, handle, &mut nav, tick);
    }
    nav.resume();
    (world, handle, nav)
}

/// One tick of the navigator on the readings the hub would give it.
fn tick_on(world: &World, handle: world::RobotHandle, nav: &mut Navigator, tick: u64) -> [f64; 2] {
    let robot = world.robot(handle).expect("the chair");
    let block = hub::core::pack_sensor_block(robot, 1, tick, |_| 2);
    nav.step(&Input::from_block(&block, tick as f64 * 0.1)).powers
}

/// The ticks of the first plan, to its end (a long search goes on over several ticks, the
/// chair standing); how many ticks it took.
fn first_plan(world: &World, handle: world::RobotHandle, nav: &mut Navigator) -> u64 {
    let mut tick = LOOK_TICKS;
    black_box(tick_on(world, handle, nav, tick));
    while nav.searching() {
        tick += 1;
        black_box(tick_on(world, handle, nav, tick));
    }
    tick - LOOK_TICKS + 1
}

fn navigator_plan(c: &mut Criterion) {
    let mut group = c.benchmark_group("navigator_first_plan");
    group.sample_size(20);
    group.measurement_time(Duration::from_secs(6));
    for case in CASES {
        let (world, handle, mut nav) = setup(case);
        let ticks = first_plan(&world, handle, &mut nav);
        let s = nav.stats();
        println!(
            "{}: {} searches ({} found nothing), {} nodes expanded, over {ticks} tick(s)",
            case.name, s.plans, s.failed_plans, s.expansions
        );
        group.bench_with_input(BenchmarkId::from_parameter(case.name), case, |b, case| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                for _ in 0..iters {
                    let (world, handle, mut nav) = setup(case);
                    let t = Instant::now();
                    black_box(first_plan(&world, handle, &mut nav));
                    total += t.elapsed();
                }
                total
            })
        });
    }
    group.finish();
}

criterion_group!(benches, navigator_plan);
criterion_main!(benches);
