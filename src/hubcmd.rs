//! `iwsim hub`: loads the map and parameters, runs the hub, prints how the run ended.

use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context as _;
use hub::HubConfig;
use hub::core::Mode;
use records::places::{Checkpoint, Obstacle};
use world::map::builtin::{self, PREFIX};
use world::map::xml::{parse_params, read_text};
use world::map::{Grid, NoiseParams, Wall};

use crate::cli::HubArgs;

/// Builds the hub's configuration from the command line.
pub fn config(args: &HubArgs) -> anyhow::Result<HubConfig> {
    let mut lab = builtin::load_lab_spec(&args.lab).map_err(|e| anyhow::anyhow!("{}:{e}", args.lab))?;
    let obstacle_from = lab.walls.len();
    for spec in &args.obstacle {
        let o = Obstacle::parse(spec)
            .and_then(|o| o.check_inside(lab.width_m, lab.height_m).map(|()| o))
            .map_err(|e| anyhow::anyhow!("--obstacle {e}"))?;
        lab.walls.push(Wall::rectangle(o.x0, o.y0, o.x1, o.y1, o.height));
    }
    let checkpoints = args
        .checkpoint
        .iter()
        .map(|spec| Checkpoint::parse(spec).map_err(|e| anyhow::anyhow!("--checkpoint {e}")))
        .collect::<anyhow::Result<_>>()?;
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
        println!("{}", out.json_line());
    } else {
        println!("tick {} state hash {}", out.ticks, out.state_hash);
        println!("agents: {} connected, {} died", out.agents_seen, out.agents_died);
        for r in &out.robots {
            println!(
                "robot {}: x {:.4} m, y {:.4} m, heading {:.2} deg, flags {}",
                r.id, r.x_m, r.y_m, r.heading_deg, r.flags
            );
        }
        if out.interrupted {
            println!("stopped by a termination signal");
        }
    }
    Ok(ExitCode::SUCCESS)
}
