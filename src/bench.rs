//! `iwsim bench …`: figures printed as text or JSON.

use std::process::ExitCode;
use std::time::{Duration, Instant};

use hub::tiled::TiledWorld;

use crate::cli::BenchWorldArgs;

/// Result of `iwsim bench world`.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldBench {
    /// Chairs in the world.
    pub robots: usize,
    /// Ticks timed.
    pub ticks: u64,
    /// Ticks per second of `World::step` alone.
    pub ticks_per_s: f64,
    /// Microseconds per robot per tick.
    pub us_per_robot_tick: f64,
    /// Median time of one tick, milliseconds.
    pub p50_tick_ms: f64,
    /// Time to build the world and place the chairs, seconds.
    pub build_s: f64,
}

/// Steps tiled LIACC floors with `robots` chairs and times `World::step` (the controller that
/// makes the actions runs between ticks and is not timed).
/// The chairs first drive `warmup` ticks untimed, so every run times the same stretch of the
/// same (seeded) drive.
pub fn measure_world(robots: usize, ticks: u64, warmup: u64, seed: u64) -> anyhow::Result<WorldBench> {
    let t0 = Instant::now();
    let mut w = TiledWorld::build(robots, seed)?;
    let build_s = t0.elapsed().as_secs_f64();
    for _ in 0..warmup {
        w.tick(0.1);
    }
    let mut per_tick = Vec::with_capacity(ticks as usize);
    let mut total = Duration::ZERO;
    for _ in 0..ticks {
        w.control();
        let t = Instant::now();
        w.step_only(0.1);
        let dt = t.elapsed();
        total += dt;
        per_tick.push(dt);
    }
    per_tick.sort_unstable();
    let secs = total.as_secs_f64().max(1e-12);
    Ok(WorldBench {
        robots,
        ticks,
        ticks_per_s: ticks as f64 / secs,
        us_per_robot_tick: secs * 1e6 / (ticks as f64 * robots.max(1) as f64),
        p50_tick_ms: per_tick.get(per_tick.len() / 2).map_or(0.0, |d| d.as_secs_f64() * 1e3),
        build_s,
    })
}

/// `iwsim bench world`.
pub fn world(args: &BenchWorldArgs) -> anyhow::Result<ExitCode> {
    let b = measure_world(args.robots, args.ticks, args.warmup, args.seed)?;
    if args.json {
        println!(
            "{{\"robots\":{},\"ticks\":{},\"warmup\":{},\"ticks_per_s\":{:.1},\"us_per_robot_tick\":{:.4},\"p50_tick_ms\":{:.4},\"build_s\":{:.3}}}",
            b.robots, b.ticks, args.warmup, b.ticks_per_s, b.us_per_robot_tick, b.p50_tick_ms, b.build_s
        );
    } else {
        println!(
            "world: {} chairs on tiled LIACC floors, 8 proximity sensors each, noise on\n  {:.1} ticks/s  ({:.3} us per robot-tick, median tick {:.3} ms, {} ticks timed; built in {:.2} s)\n  real-time factor at 100 ms ticks: {:.1}x",
            b.robots,
            b.ticks_per_s,
            b.us_per_robot_tick,
            b.p50_tick_ms,
            b.ticks,
            b.build_s,
            b.ticks_per_s / 10.0
        );
    }
    Ok(ExitCode::SUCCESS)
}
