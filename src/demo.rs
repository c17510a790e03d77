//! `iwsim demo`: the main job as it stands — chairs driving on the LIACC floor in-process, with
//! the thesis's dynamic characteristic check, a summary, and optional CSV logs.
//!
//! The shared-memory hub, the agents and the live viewer replace this in-process loop as they
//! arrive; the summary stays.

use std::fmt::Write as _;
use std::io::Write as _;
use std::process::ExitCode;

use anyhow::Context as _;
use hub::map::builtin;
use hub::math::Pose;
use hub::tiled::{chair_spec, wander};
use hub::world::{Action, RobotSpec, World};

use crate::cli::DemoArgs;

/// Full power from rest: top speed (m/s) and 10–90 % rise time (s) of a chair, measured from
/// its positions tick by tick (thesis §7.2).
pub fn dynamic_characteristic(max_speed: f64, curve: f64, dt: f64) -> anyhow::Result<(f64, f64)> {
    let map = builtin::map("liacc").context("built-in LIACC map")?;
    let params = hub::map::Params { noise: hub::map::NoiseParams::NONE, ..Default::default() };
    let mut w = World::new(&map.lab, params, 0)?;
    // Along the long corridor from checkpoint 1.
    let r = w.add_robot(RobotSpec::at(10.0, 6.1, 0.0).body(1.1, 0.65, 0.8).motors(max_speed, curve))?;
    let mut speeds = Vec::new();
    let mut last = 10.0;
    for _ in 0..100 {
        w.step(&[Action::motors(r, 1.0, 1.0)], dt);
        let x = w.robot(r).context("chair")?.pose.x;
        speeds.push((x - last) / dt);
        last = x;
    }
    let top = speeds.iter().copied().fold(0.0, f64::max);
    let first = |f: f64| speeds.iter().position(|&v| v >= f * top).unwrap_or(0);
    Ok((top, (first(0.9) - first(0.1)) as f64 * dt))
}

/// Runs the demo.
pub fn run(args: &DemoArgs) -> anyhow::Result<ExitCode> {
    let map = builtin::map("liacc").context("built-in LIACC map")?;
    let mut world = World::new(&map.lab, hub::map::Params::default(), args.seed)?;
    let mut chairs = Vec::new();
    for (k, start) in map.grid.poses.iter().enumerate() {
        let spec =
            chair_spec(Pose::from_deg(start.pos.x, start.pos.y, start.heading_deg)).named(&format!("chair{}", k + 1));
        if world.is_free(&spec) {
            chairs.push(world.add_robot(spec)?);
        }
    }
    let mut logs = match &args.out {
        Some(dir) => {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
            let mut files = Vec::new();
            for k in 0..chairs.len() {
                let path = dir.join(format!("chair{}.csv", k + 1));
                let mut f = std::io::BufWriter::new(
                    std::fs::File::create(&path).with_context(|| format!("creating {}", path.display()))?,
                );
                write!(f, "tick,time_s,encoder_left_ticks,encoder_right_ticks")?;
                for s in 0..8 {
                    write!(f, ",proximity{s}_m")?;
                }
                writeln!(f, ",heading_deg,x_m,y_m,collision")?;
                files.push(f);
            }
            Some(files)
        }
        None => None,
    };

    let dt = 0.1;
    let ticks = (args.seconds / dt).round().max(1.0) as u64;
    let starts: Vec<Pose> = chairs.iter().filter_map(|&h| world.robot(h).map(|r| r.pose)).collect();
    let mut travelled = vec![0.0; chairs.len()];
    let mut actions: Vec<Action> = Vec::new();
    for _ in 0..ticks {
        wander(&world, &chairs, &mut actions);
        let before: Vec<Pose> = chairs.iter().filter_map(|&h| world.robot(h).map(|r| r.pose)).collect();
        world.step(&actions, dt);
        for (k, &h) in chairs.iter().enumerate() {
            let Some(r) = world.robot(h) else { continue };
            travelled[k] += (r.pose.position() - before[k].position()).norm();
            if let Some(files) = logs.as_mut() {
                let rd = &r.readings;
                let mut line =
                    format!("{},{:.3},{},{}", world.tick(), world.time_s(), rd.encoder_ticks[0], rd.encoder_ticks[1]);
                for d in rd.proximity() {
                    write!(line, ",{d:.4}")?;
                }
                writeln!(
                    line,
                    ",{:.3},{:.4},{:.4},{}",
                    r.pose.heading_deg(),
                    r.pose.x,
                    r.pose.y,
                    u8::from(r.collision)
                )?;
                files[k].write_all(line.as_bytes())?;
            }
        }
    }
    if let Some(files) = logs.as_mut() {
        for f in files {
            f.flush()?;
        }
    }

    println!(
        "iwsim demo: {} chairs wandering on the LIACC floor (thesis Annex D), {:.0} s simulated in {} ticks of {} ms, seed {}",
        chairs.len(),
        world.time_s(),
        world.tick(),
        dt * 1000.0,
        args.seed
    );
    println!("  {:<8} {:>16} {:>16} {:>10} {:>10}", "chair", "start (x, y)", "end (x, y)", "driven m", "contacts");
    for (k, &h) in chairs.iter().enumerate() {
        let Some(r) = world.robot(h) else { continue };
        println!(
            "  {:<8} {:>16} {:>16} {:>10.1} {:>10}",
            r.spec.name,
            format!("({:.1}, {:.1})", starts[k].x, starts[k].y),
            format!("({:.1}, {:.1})", r.pose.x, r.pose.y),
            travelled[k],
            r.collision_count
        );
    }
    let (top, rise) = dynamic_characteristic(0.49, 0.83, 0.1)?;
    println!(
        "  dynamic characteristic (thesis 7.2: MaxSpeed 0.49, AccelerationCurve 0.83, 100 ms): top speed {top:.3} m/s, 10-90% rise time {rise:.1} s"
    );
    println!("  final state hash {:016x}", world.state_hash());
    if let Some(dir) = &args.out {
        println!("  logs: {}/chair*.csv", dir.display());
    }
    Ok(ExitCode::SUCCESS)
}
