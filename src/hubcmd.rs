//! `iwsim hub`: loads the map and parameters, runs the hub, prints how the run ended.

use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context as _;
use hub::HubConfig;
use hub::core::Mode;
use world::map::builtin::{self, PREFIX};
use world::map::xml::{parse_params, read_text};
use world::map::{Grid, NoiseParams, Wall};

use crate::cli::HubArgs;

/// Builds the hub's configuration from the command line.
pub fn config(args: &HubArgs) -> anyhow::Result<HubConfig> {
    let mut lab = builtin::load_lab_spec(&args.lab).map_err(|e| anyhow::anyhow!("{}:{e}", args.lab))?;
    let obstacle_from = lab.walls.len();
    for spec in &args.obstacle {
        let v = agent_sdk::args::numbers(spec, "an obstacle X0,Y0,X1,Y1[,H]", 4, 5)
            .map_err(|e| anyhow::anyhow!("--obstacle {e}"))?;
        let (x0, y0, x1, y1, h) = (v[0], v[1], v[2], v[3], v.get(4).copied().unwrap_or(1.0));
        anyhow::ensure!(
            x0 < x1 && y0 < y1 && h > 0.0,
            "--obstacle {spec}: want X0 < X1, Y0 < Y1 and a positive height"
        );
        anyhow::ensure!(
            x0 >= 0.0 && y0 >= 0.0 && x1 <= lab.width_m && y1 <= lab.height_m,
            "--obstacle {spec}: outside the {} x {} m lab",
            lab.width_m,
            lab.height_m
        );
        lab.walls.push(Wall::rectangle(x0, y0, x1, y1, h));
    }
    let mut checkpoints = Vec::new();
    for spec in &args.checkpoint {
        let v = agent_sdk::args::numbers(spec, "a checkpoint X,Y[,R]", 2, 3)
            .map_err(|e| anyhow::anyhow!("--checkpoint {e}"))?;
        let r = v.get(2).copied().unwrap_or(0.5);
        anyhow::ensure!(r > 0.0, "--checkpoint {spec}: the radius must be positive");
        checkpoints.push([v[0], v[1], r]);
    }
    let grid = match (&args.grid, args.lab.strip_prefix(PREFIX)) {
        (Some(g), _) => builtin::load_grid_spec(g).map_err(|e| anyhow::anyhow!("{g}:{e}"))?,
        (None, Some(name)) => builtin::map(name).map(|m| m.grid).unwrap_or_default(),
        (None, None) => Grid::default(),
    };
    let mut params = match &args.param {
        Some(path) => {
            let text = read_text(path).map_err(|e| anyhow::anyhow!("{e}"))?;
            parse_params(&text).map_err(|e| anyhow::anyhow!("{}:{e}", path.display()))?
        }
        None => world::map::Params::default(),
    };
    if let Some(ms) = args.cycle_ms {
        params.cycle_ms = ms;
    }
    if args.no_noise {
        params.noise = NoiseParams::NONE;
    }
    let tick_limit = if args.ticks > 0 { args.ticks } else { params.sim_time_ticks };
    Ok(HubConfig {
        session: args.session.clone(),
        lab,
        grid,
        params,
        seed: args.seed,
        mode: if args.lockstep { Mode::LockStep } else { Mode::RealTime },
        deadline: Duration::from_millis(args.deadline_ms),
        wait_agents: args.wait_agents,
        start_on_command: args.start_on_command,
        tick_limit,
        max_robots: args.max_robots,
        obstacle_from,
        checkpoints,
    })
}

/// `iwsim hub`.
pub fn run(args: &HubArgs) -> anyhow::Result<ExitCode> {
    let cfg = config(args)?;
    eprintln!(
        "iwsim hub: session {:?}, lab {:?}, {} mode{}",
        cfg.session,
        cfg.lab.name,
        if cfg.mode == Mode::LockStep { "lock-step" } else { "real-time" },
        if cfg.tick_limit > 0 { format!(", {} ticks", cfg.tick_limit) } else { String::new() }
    );
    let out = hub::run(cfg).context("hub")?;
    if args.json {
        let robots: Vec<String> = out
            .robots
            .iter()
            .map(|(id, x, y, h, f)| {
                format!("{{\"id\":{id},\"x_m\":{x},\"y_m\":{y},\"heading_deg\":{h},\"flags\":{f}}}")
            })
            .collect();
        println!(
            "{{\"ticks\":{},\"run_s\":{:.6},\"state_hash\":\"{:016x}\",\"agents_seen\":{},\"agents_died\":{},\"interrupted\":{},\"robots\":[{}]}}",
            out.ticks,
            out.run_s,
            out.state_hash,
            out.agents_seen,
            out.agents_died,
            out.interrupted,
            robots.join(",")
        );
    } else {
        println!("tick {} state hash {:016x}", out.ticks, out.state_hash);
        println!("agents: {} connected, {} died", out.agents_seen, out.agents_died);
        for (id, x, y, h, f) in &out.robots {
            println!("robot {id}: x {x:.4} m, y {y:.4} m, heading {h:.2} deg, flags {f}");
        }
        if out.interrupted {
            println!("stopped by a termination signal");
        }
    }
    Ok(ExitCode::SUCCESS)
}
