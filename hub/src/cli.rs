//! `iwsim hub`'s command line: the options, the configuration they make (map, parameters,
//! scenario obstacles and checkpoints), and the run, printing how it ended.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use crate::HubConfig;
use crate::core::Mode;
use anyhow::Context as _;
use places::{Checkpoint, Obstacle};
use world::map::builtin::{self, PREFIX};
use world::map::xml::{parse_params, read_text};
use world::map::{Grid, NoiseParams, Wall};

/// The longest `--deadline-ms`: a day. Longer could not be told apart from "wait for ever", and
/// the map header carries the deadline as 32-bit milliseconds.
pub const MAX_DEADLINE_MS: u64 = 86_400_000;

/// Options of `iwsim hub`.
#[derive(Debug, clap::Args, Clone)]
pub struct HubArgs {
    /// Lab file, or builtin:liacc, builtin:thesis, builtin:maze, builtin:ward.
    #[arg(long, default_value = "builtin:liacc")]
    pub lab: String,
    /// Grid file (start poses); a built-in lab brings its own grid.
    #[arg(long)]
    pub grid: Option<String>,
    /// Parameters file (Ciber-Rato `<Parameters>`).
    #[arg(long)]
    pub param: Option<PathBuf>,
    /// Session name: hubs, agents and viewers of one run share it.
    #[arg(long, default_value = "default")]
    pub session: String,
    /// Tick period in milliseconds (real time; also the simulated step in lock-step).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub cycle_ms: Option<u32>,
    /// Step as soon as every agent has answered, instead of every cycle.
    #[arg(long)]
    pub lockstep: bool,
    /// Lock-step: step without an agent that has not answered after this long.
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..=MAX_DEADLINE_MS))]
    pub deadline_ms: u64,
    /// Seed of the world's random generator.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Stop after this many ticks (0: run until stopped).
    #[arg(long, default_value_t = 0)]
    pub ticks: u64,
    /// Switch every sensor and motor noise off.
    #[arg(long)]
    pub no_noise: bool,
    /// Start tick 0 once this many agents are ready.
    #[arg(long, default_value_t = 0, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(0..=ipc_types::MAX_AGENTS as u64))]
    pub wait_agents: usize,
    /// Wait for a Start command before tick 0.
    #[arg(long)]
    pub start_on_command: bool,
    /// Robots the hub accepts (at most 10,000).
    #[arg(long, default_value_t = ipc_types::MAX_ROBOTS, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=ipc_types::MAX_ROBOTS as u64))]
    pub max_robots: usize,
    /// Print the end-of-run summary as one JSON object.
    #[arg(long)]
    pub json: bool,
    /// A scenario obstacle: a static box X0,Y0,X1,Y1 (metres) of height H (default 1.0 m),
    /// sensed and collided with like a wall. Repeatable.
    #[arg(long, value_name = "X0,Y0,X1,Y1[,H]", allow_hyphen_values = true)]
    pub obstacle: Vec<String>,
    /// A scenario checkpoint X,Y with radius R (default 0.5 m), shown by viewers. Repeatable.
    #[arg(long, value_name = "X,Y[,R]", allow_hyphen_values = true)]
    pub checkpoint: Vec<String>,
    /// Record the run to this MCAP file: an exact replay journal (`iwsim replay`) and the
    /// world per tick in Foxglove's schemas.
    #[arg(long, value_name = "FILE.mcap")]
    pub record: Option<PathBuf>,
    /// Threads the world's step may use (0: one per core). A run is the same on any number.
    #[arg(long, default_value_t = 0, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(0..=world::MAX_THREADS as u64))]
    pub threads: usize,
    /// The fewest robots a step is spread over threads for (smaller worlds step on one thread,
    /// where handing out work would cost more than it saves).
    #[arg(long, default_value_t = world::PARALLEL_MIN_ROBOTS)]
    pub parallel_min_robots: usize,
    /// Lock-step: how long the hub spins for the agents' answers before it sleeps, while
    /// every agent it waits for can have a core of its own (0: never spin). A fast agent's
    /// answer then costs no wake-up of the hub.
    #[arg(long, default_value_t = crate::ANSWER_SPIN_US, value_parser = clap::builder::RangedU64ValueParser::<u64>::new().range(0..=100_000))]
    pub answer_spin_us: u64,
    /// The Ciber-Rato scoring mode (the real simulator's `--scoring N`): 0 competitive (the
    /// default), 1 control, 2 mapping, 3 planning, 4 line control (2022), 5 line mapping,
    /// 6 line planning, 7 line control (2023). Overrides the parameters file's `Scoring`.
    #[arg(long, value_name = "N")]
    pub scoring: Option<u32>,
    /// A robot name that may register as Real (a physical chair whose adapter pushes its
    /// pose). Repeatable; without it the hub refuses every Real robot, so no agent can place
    /// a robot where it likes to probe the world.
    #[arg(long, value_name = "NAME")]
    pub real: Vec<String>,
}

/// Builds the hub's configuration from the command line.
pub fn config(args: &HubArgs) -> anyhow::Result<HubConfig> {
    let mut lab = builtin::load_lab_spec(&args.lab).map_err(|e| anyhow::anyhow!("{}", e.in_file(&args.lab)))?;
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
        (Some(g), _) => builtin::load_grid_spec(g, &lab).map_err(|e| anyhow::anyhow!("{}", e.in_file(g)))?,
        (None, Some(name)) => builtin::map(name).map(|m| m.grid).unwrap_or_default(),
        (None, None) => Grid::default(),
    };
    let mut params = match &args.param {
        Some(path) => {
            let file = path.display().to_string();
            let text = read_text(path).map_err(|e| anyhow::anyhow!("{}", e.in_file(&file)))?;
            parse_params(&text).map_err(|e| anyhow::anyhow!("{}", e.in_file(&file)))?
        }
        None => world::map::Params::default(),
    };
    if let Some(ms) = args.cycle_ms {
        params.cycle_ms = ms;
    }
    if args.no_noise {
        params.noise = NoiseParams::NONE;
    }
    if let Some(n) = args.scoring {
        params.challenge.scoring =
            world::challenge::Scoring::from_number(n).map_err(|e| anyhow::anyhow!("--scoring {n}: {e}"))?;
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
        record: args.record.clone(),
        threads: args.threads,
        parallel_min_robots: args.parallel_min_robots,
        answer_spin: Duration::from_micros(args.answer_spin_us),
        real: args.real.clone(),
    })
}

/// `iwsim hub`.
pub fn run(args: &HubArgs) -> anyhow::Result<ExitCode> {
    let cfg = config(args)?;
    // A session name iceoryx2 cannot use is the user's mistake: say so before the banner that
    // would announce a session that never comes up.
    ipc_services::Session::new(&cfg.session).context("hub")?;
    ipc_services::report!(
        "iwsim hub: session {:?}, lab {:?}, {} mode{}",
        cfg.session,
        cfg.lab.name,
        if cfg.mode == Mode::LockStep { "lock-step" } else { "real-time" },
        if cfg.tick_limit > 0 { format!(", {} ticks", cfg.tick_limit) } else { String::new() }
    );
    let out = crate::run(cfg).context("hub")?;
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
        if let Ok(mode) = world::challenge::Scoring::from_number(out.scoring) {
            let order = if mode.lower_is_better() { "lower is better" } else { "higher is better" };
            println!("challenge: scoring {} ({}; {order})", out.scoring, mode.name());
        }
        for s in &out.scores {
            println!(
                "score {} {:?}: {}, score {}, arrival tick {}, returning ticks {}, collisions {}, visited {:?}",
                s.id, s.name, s.state, s.score, s.arrival_tick, s.returning_ticks, s.collisions, s.visited
            );
        }
        if let Some(path) = &args.record {
            println!(
                "recorded {} bytes to {} ({} world frames for people dropped; the replay journal is whole)",
                out.recorded_bytes,
                path.display(),
                out.recording_dropped_frames
            );
        }
        if out.interrupted {
            println!("stopped by a termination signal");
        }
    }
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser as _;

    #[derive(Debug, clap::Parser)]
    struct Cli {
        #[command(flatten)]
        hub: HubArgs,
    }

    /// The one-line error clap gives for `args`, or `None` when they parse.
    fn refusal(args: &[&str]) -> Option<String> {
        let argv = std::iter::once("hub").chain(args.iter().copied());
        Cli::try_parse_from(argv).err().map(|e| e.to_string().lines().next().unwrap_or_default().to_owned())
    }

    #[test]
    fn values_the_hub_cannot_honour_are_refused_with_the_option_and_its_range() {
        for (args, range) in [
            (&["--deadline-ms", "0"][..], "1..=86400000"),
            (&["--deadline-ms", "86400001"][..], "1..=86400000"),
            (&["--wait-agents", "129"][..], "0..=128"),
            (&["--max-robots", "0"][..], "1..=10000"),
            (&["--max-robots", "10001"][..], "1..=10000"),
            (&["--cycle-ms", "0"][..], "1..=4294967295"),
        ] {
            let line = refusal(args).unwrap_or_else(|| panic!("{args:?} was accepted"));
            assert!(line.contains(args[0]) && line.contains(range), "{args:?}: {line}");
        }
    }

    #[test]
    fn the_limits_themselves_are_accepted() {
        for args in [
            &["--deadline-ms", "1"][..],
            &["--deadline-ms", "86400000"][..],
            &["--wait-agents", "128"][..],
            &["--max-robots", "1"][..],
            &["--max-robots", "10000"][..],
            &["--cycle-ms", "1"][..],
        ] {
            assert_eq!(refusal(args), None, "{args:?}");
        }
    }
}
