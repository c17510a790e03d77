//! `iwsim plot`: a run's trajectories over the map (thesis Fig. 7.6) and speeds over time
//! (Figs. 7.3–7.4), as one SVG; several robots of one run in one figure, a colour each.
//!
//! It draws from either of what a run leaves behind:
//!
//! - the run's **recording** (`run.mcap`, read by [`track`]): every robot's true pose at every
//!   recorded tick, and the lab, obstacles and checkpoints of its run start;
//! - the robots' **CSV logs** (read by [`log`]): what each agent's own sensors said, so a
//!   trajectory only where the run gave its robots a GPS (`x_m`, `y_m` are NaN otherwise).
//!
//! ```
//! use std::path::Path;
//! use plot::draw::{Figure, render};
//! use plot::log::{RunLog, speeds};
//! use plot::scene::{Checkpoint, Scene};
//!
//! let text = "tick,time_s,x_m,y_m,collision\n1,0.1,10.0,6.1,0\n2,0.2,10.05,6.1,0\n3,0.3,10.1,6.1,0\n";
//! let log = RunLog::parse(text, Path::new("chair1.csv"))?;
//! assert!((speeds(&log.samples)[0].speed_m_s - 0.5).abs() < 1e-9);
//!
//! let scene = Scene { checkpoints: vec![Checkpoint::parse("10,6.1")?], ..Default::default() };
//! let svg = render(&Figure { title: "chair1.csv".into(), logs: vec![("chair1".into(), &log)], scene: &scene })?;
//! assert!(svg.contains("<polyline"));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! The map comes from `--lab`, `--obstacle` and `--checkpoint`, or else from the recording's
//! run start, or from the `summary.json` that `iwsim run` leaves beside its logs; with none of
//! these, the trajectory is drawn alone.

#![warn(missing_docs)]

pub mod draw;
pub mod log;
pub mod scene;
pub mod track;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context as _;

use crate::log::RunLog;
use crate::scene::{Checkpoint, Obstacle, Scene, SummaryScene};
use crate::track::RecordedRun;

/// Name of the run summary read from the log's directory.
pub const SUMMARY_FILE: &str = "summary.json";

/// The first bytes of every MCAP file (the recording format).
const MCAP_MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// Options of `iwsim plot`.
#[derive(Debug, clap::Args, Clone)]
#[command(after_help = "\
Accepts a run's recording (run.mcap, which `iwsim run` and `iwsim hub --record` write): every \
robot's true trajectory and speed, over the lab, obstacles and checkpoints of the run; --robot \
picks robots. Or the CSV logs of robots (one per robot, from `iwsim run` and the agents): \
what each robot's GPS said, so only for runs with a GPS; the map then comes from the \
summary.json beside the logs.

Examples:
  iwsim plot runs/door/run.mcap
  iwsim plot runs/door/run.mcap --robot chair1 --out chair1.svg
  iwsim plot runs/gps/chair1.csv runs/gps/chair2.csv")]
pub struct PlotArgs {
    /// A run's recording (`.mcap`), or the CSV logs of robots of one run (`.csv`, several are
    /// drawn together, a colour each).
    #[arg(required = true, num_args = 1.., value_name = "RECORDING|LOG")]
    pub log: Vec<PathBuf>,
    /// Draws only this robot of the recording (repeatable) [default: every robot].
    #[arg(long, value_name = "NAME")]
    pub robot: Vec<String>,
    /// The SVG to write [default: the recording's or log's path with `.svg`; for several
    /// logs, `trajectories.svg` beside the first].
    #[arg(long, value_name = "FILE.svg")]
    pub out: Option<PathBuf>,
    /// Lab drawn under the trajectory: builtin:liacc, builtin:thesis, builtin:maze, builtin:ward or a lab
    /// file [default: the recording's lab, or the `lab` of summary.json beside the log, else
    /// none].
    #[arg(long)]
    pub lab: Option<String>,
    /// A scenario obstacle X0,Y0,X1,Y1 (metres), height H (default 1.0 m). Repeatable;
    /// replaces the recording's or summary.json's obstacles.
    #[arg(long, value_name = "X0,Y0,X1,Y1[,H]", allow_hyphen_values = true)]
    pub obstacle: Vec<String>,
    /// A scenario checkpoint X,Y (metres) with radius R (default 0.5 m). Repeatable; replaces
    /// the recording's or summary.json's checkpoints.
    #[arg(long, value_name = "X,Y[,R]", allow_hyphen_values = true)]
    pub checkpoint: Vec<String>,
    /// Ignore the summary.json beside the logs.
    #[arg(long)]
    pub no_summary: bool,
}

impl PlotArgs {
    /// The file to write.
    pub fn out_path(&self) -> PathBuf {
        if let Some(out) = &self.out {
            return out.clone();
        }
        match self.log.as_slice() {
            [one] => one.with_extension("svg"),
            logs => logs
                .first()
                .map_or_else(|| PathBuf::from("trajectories.svg"), |first| first.with_file_name("trajectories.svg")),
        }
    }

    /// The first input (the one whose directory may hold a summary.json).
    fn first_log(&self) -> anyhow::Result<&Path> {
        self.log.first().map(PathBuf::as_path).context("no log given")
    }
}

/// Whether `path` is a recording rather than a CSV log: named `.mcap`, or starting with the
/// MCAP magic (whatever its name).
pub fn is_recording(path: &Path) -> bool {
    if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("mcap")) {
        return true;
    }
    let mut magic = [0u8; MCAP_MAGIC.len()];
    // Only a regular file is looked into: opening a FIFO with no writer would block for ever
    // (the reader then says what the path is).
    places::files::open_regular(path).and_then(|mut f| std::io::Read::read_exact(&mut f, &mut magic)).is_ok()
        && &magic == MCAP_MAGIC
}

/// Reads the inputs and the map, draws the SVG, writes it, and prints the path written (and,
/// on stderr, what a cut-short recording lost).
pub fn run(args: &PlotArgs) -> anyhow::Result<ExitCode> {
    let (out, note) = draw(args)?;
    if let Some(note) = note {
        eprintln!("iwsim plot: note: {note}; drawn up to there");
    }
    println!("{}", out.display());
    Ok(ExitCode::SUCCESS)
}

/// What [`run`] does, without printing: returns the path written.
pub fn plot(args: &PlotArgs) -> anyhow::Result<PathBuf> {
    draw(args).map(|(out, _)| out)
}

/// Draws and writes the SVG; returns its path and, for a recording cut short, what was lost.
fn draw(args: &PlotArgs) -> anyhow::Result<(PathBuf, Option<String>)> {
    let out = args.out_path();
    if let Some(input) = args.log.iter().find(|l| **l == out) {
        let what = if is_recording(input) { "recording" } else { "log" };
        anyhow::bail!("{}: the SVG would overwrite the {what}; give --out", input.display());
    }
    let file_name = |p: &Path| p.file_name().map_or_else(|| p.display().to_string(), |n| n.to_string_lossy().into());
    let recordings = args.log.iter().filter(|p| is_recording(p)).count();
    let (title, named, scene, note) = match (recordings, args.log.as_slice()) {
        (0, _) => {
            if !args.robot.is_empty() {
                anyhow::bail!("--robot picks robots of a recording; to draw some robots' CSV logs, name those logs");
            }
            let logs = args.log.iter().map(|p| RunLog::read(p)).collect::<Result<Vec<_>, _>>()?;
            let named: Vec<(String, RunLog)> =
                args.log.iter().zip(logs).map(|(p, l)| (robot_log::robot_name_of(p), l)).collect();
            let title = args.log.iter().map(|p| file_name(p)).collect::<Vec<_>>().join(", ");
            (title, named, scene(args, summary_base(args)?)?, None)
        }
        (1, [recording]) => {
            let run = RecordedRun::read(recording, &args.robot)?;
            let (lab, obstacles) = track::lab_and_obstacles(&run.start);
            let base = Base { lab: Some(lab), obstacles, checkpoints: run.start.checkpoints.clone() };
            let mut title = file_name(recording);
            if !args.robot.is_empty() {
                let names: Vec<&str> = run.robots.iter().map(|(n, _)| n.as_str()).collect();
                title = format!("{title}: {}", names.join(", "));
            }
            let note = run.truncated.map(|t| format!("{}: {t}", recording.display()));
            (title, run.robots, scene(args, base)?, note)
        }
        _ => anyhow::bail!("give one recording (.mcap) or the CSV logs of one run, not both nor several recordings"),
    };
    let logs = named.iter().map(|(n, l)| (n.clone(), l)).collect();
    let svg = draw::render(&draw::Figure { title, logs, scene: &scene })?;
    std::fs::write(&out, svg).with_context(|| format!("{}: cannot write the SVG", out.display()))?;
    Ok((out, note))
}

/// The map a run's files give, before the command line has its say.
#[derive(Debug, Default)]
struct Base {
    lab: Option<world::map::Lab>,
    obstacles: Vec<Obstacle>,
    checkpoints: Vec<Checkpoint>,
}

/// The map of the summary.json beside the first log (its lab loaded only when `--lab` does
/// not replace it).
fn summary_base(args: &PlotArgs) -> anyhow::Result<Base> {
    let dir = args.first_log()?.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let summary_path = dir.join(SUMMARY_FILE);
    let summary = if !args.no_summary && summary_path.is_file() {
        SummaryScene::read(&summary_path)?
    } else {
        SummaryScene::default()
    };
    let lab = match (&args.lab, &summary.lab) {
        (None, Some(spec)) => {
            Some(load_lab(spec, Some(dir)).with_context(|| format!("lab of {}", summary_path.display()))?)
        }
        _ => None,
    };
    Ok(Base {
        lab,
        obstacles: summary.obstacles.unwrap_or_default(),
        checkpoints: summary.checkpoints.unwrap_or_default(),
    })
}

/// The map under the trajectory: the command line first, then what the run's files say.
fn scene(args: &PlotArgs, base: Base) -> anyhow::Result<Scene> {
    let lab = match &args.lab {
        Some(spec) => Some(load_lab(spec, None)?),
        None => base.lab,
    };
    let obstacles = if args.obstacle.is_empty() {
        base.obstacles
    } else {
        args.obstacle
            .iter()
            .map(|s| Obstacle::parse(s).map_err(|e| anyhow::anyhow!("--obstacle {e}")))
            .collect::<anyhow::Result<_>>()?
    };
    let checkpoints = if args.checkpoint.is_empty() {
        base.checkpoints
    } else {
        args.checkpoint
            .iter()
            .map(|s| Checkpoint::parse(s).map_err(|e| anyhow::anyhow!("--checkpoint {e}")))
            .collect::<anyhow::Result<_>>()?
    };
    Ok(Scene { lab, obstacles, checkpoints })
}

/// Loads a lab spec; a relative file named by a summary is looked for beside it too.
fn load_lab(spec: &str, beside: Option<&Path>) -> anyhow::Result<world::map::Lab> {
    let relative = Path::new(spec);
    let spec = match beside {
        Some(dir)
            if !spec.starts_with(world::map::builtin::PREFIX)
                && relative.is_relative()
                && !relative.exists()
                && dir.join(relative).is_file() =>
        {
            dir.join(relative).to_string_lossy().into_owned()
        }
        _ => spec.to_owned(),
    };
    world::map::builtin::load_lab_spec(&spec).map_err(|e| anyhow::anyhow!("{spec}:{e}"))
}
