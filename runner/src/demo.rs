//! `iwsim demo`: the main job — the slalom and the automatic door of the thesis's chapter 7 on
//! the LIACC floor, in real time, with the viewer, then a summary.

use std::process::ExitCode;

use anyhow::Context as _;
use world::map::builtin;
use world::{Action, RobotSpec, World};

use crate::args::DemoArgs;
use crate::run::RunOptions;
use crate::scenario::Scenario;
use crate::signals::Signals;

/// Full power from rest: top speed (m/s) and 10–90 % rise time (s) of a chair, measured from
/// its positions tick by tick (thesis §7.2).
pub fn dynamic_characteristic(max_speed: f64, curve: f64, dt: f64) -> anyhow::Result<(f64, f64)> {
    let map = builtin::map("liacc").context("built-in LIACC map")?;
    let params = world::map::Params { noise: world::map::NoiseParams::NONE, ..Default::default() };
    let mut w = World::new(&map.lab, params, 0)?;
    // Along the long corridor from checkpoint 1.
    let r = w.add_robot(
        RobotSpec::at(10.0, 6.1, 0.0)
            .body(sim_model::chair::BODY[0], sim_model::chair::BODY[1], sim_model::chair::BODY[2])
            .motors(max_speed, curve),
    )?;
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

/// Runs the demo: `builtin:demo` as real processes (hub, navigator, door, wheelchair and the
/// viewer), then its summary and the thesis's dynamic characteristic.
pub fn run(args: &DemoArgs) -> anyhow::Result<ExitCode> {
    // First, before any thread starts (see `signals`).
    let signals = Signals::install()?;
    if let Some(session) = &args.session {
        ipc_services::Session::new(session)?;
    }
    let mut scenario = Scenario::load("builtin:demo")?;
    if let Some(s) = args.seconds {
        let max = crate::scenario::MAX_SECONDS;
        anyhow::ensure!(s > 0.0 && s <= max, "--seconds {s}: must be more than 0 and at most {max} (a week)");
        scenario.seconds = s;
    }
    ipc_services::report!(
        "iwsim demo: {} — {} s simulated on the LIACC floor (thesis Annex D), {}, seed {}",
        scenario.description,
        scenario.seconds,
        if args.lockstep { "lock-step" } else { "real time" },
        args.seed
    );
    let opts = RunOptions {
        lockstep: args.lockstep,
        viewer: args.viewer.clone(),
        verbose: true,
        session: args.session.clone(),
        hub_options: Vec::new(),
        zenoh: None,
    };
    let end = crate::run::run_once(&scenario, args.seed, &args.out, &opts, &signals)?;
    crate::run::print_summary(&end.summary, end.chair.as_ref(), &args.out);
    if end.interrupted.is_some() {
        return Ok(crate::run::exit_code(&end));
    }
    let (top, rise) = dynamic_characteristic(0.49, 0.83, 0.1)?;
    println!(
        "  dynamic characteristic (thesis 7.2: MaxSpeed 0.49, AccelerationCurve 0.83, 100 ms): top speed {top:.3} m/s, 10-90% rise time {rise:.1} s"
    );
    Ok(crate::run::exit_code(&end))
}
