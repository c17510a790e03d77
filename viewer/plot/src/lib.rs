//! `iwsim plot`: a run log's trajectory over the map (thesis Fig. 7.6) and its speed over time
//! (Figs. 7.3–7.4), as one SVG; several logs of one run (several robots) in one figure, a
//! colour each.
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
//! The map comes from `--lab`, `--obstacle` and `--checkpoint`, or else from the
//! `summary.json` that `iwsim run` leaves beside its logs; with neither, the trajectory is
//! drawn alone.

#![warn(missing_docs)]

pub mod draw;
pub mod log;
pub mod scene;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context as _;

use crate::log::RunLog;
use crate::scene::{Checkpoint, Obstacle, Scene, SummaryScene};

/// Name of the run summary read from the log's directory.
pub const SUMMARY_FILE: &str = "summary.json";

/// Options of `iwsim plot`.
#[derive(Debug, clap::Args, Clone)]
pub struct PlotArgs {
    /// The CSV log of a robot (`iwsim run` and the agents write one per robot); several logs of
    /// one run are drawn together, a colour each.
    #[arg(required = true, num_args = 1.., value_name = "LOG")]
    pub log: Vec<PathBuf>,
    /// The SVG to write [default: the log's path with `.svg`; for several logs,
    /// `trajectories.svg` beside the first].
    #[arg(long, value_name = "FILE.svg")]
    pub out: Option<PathBuf>,
    /// Lab drawn under the trajectory: builtin:liacc, builtin:thesis, builtin:maze or a lab
    /// file [default: the `lab` of summary.json beside the log, else none].
    #[arg(long)]
    pub lab: Option<String>,
    /// A scenario obstacle X0,Y0,X1,Y1 (metres), height H (default 1.0 m). Repeatable;
    /// replaces the obstacles of summary.json.
    #[arg(long, value_name = "X0,Y0,X1,Y1[,H]", allow_hyphen_values = true)]
    pub obstacle: Vec<String>,
    /// A scenario checkpoint X,Y (metres) with radius R (default 0.5 m). Repeatable; replaces
    /// the checkpoints of summary.json.
    #[arg(long, value_name = "X,Y[,R]", allow_hyphen_values = true)]
    pub checkpoint: Vec<String>,
    /// Ignore the summary.json beside the log.
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

    /// The first log (the one whose directory may hold a summary.json).
    fn first_log(&self) -> anyhow::Result<&Path> {
        self.log.first().map(PathBuf::as_path).context("no log given")
    }
}

/// Reads the log and the map, draws the SVG, writes it, and prints the path written.
pub fn run(args: &PlotArgs) -> anyhow::Result<ExitCode> {
    let out = plot(args)?;
    println!("{}", out.display());
    Ok(ExitCode::SUCCESS)
}

/// What [`run`] does, without printing: returns the path written.
pub fn plot(args: &PlotArgs) -> anyhow::Result<PathBuf> {
    let out = args.out_path();
    if let Some(log) = args.log.iter().find(|l| **l == out) {
        anyhow::bail!("{}: the SVG would overwrite the log; give --out", log.display());
    }
    let logs = args.log.iter().map(|p| RunLog::read(p)).collect::<Result<Vec<_>, _>>()?;
    let scene = scene(args)?;
    let file_name = |p: &Path| p.file_name().map_or_else(|| p.display().to_string(), |n| n.to_string_lossy().into());
    let title = args.log.iter().map(|p| file_name(p)).collect::<Vec<_>>().join(", ");
    let named = args.log.iter().zip(&logs).map(|(p, l)| (records::log::robot_name_of(p), l)).collect();
    let svg = draw::render(&draw::Figure { title, logs: named, scene: &scene })?;
    std::fs::write(&out, svg).with_context(|| format!("{}: cannot write the SVG", out.display()))?;
    Ok(out)
}

/// The map under the trajectory: the command line first, then summary.json beside the log.
fn scene(args: &PlotArgs) -> anyhow::Result<Scene> {
    let dir = args.first_log()?.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let summary_path = dir.join(SUMMARY_FILE);
    let summary = if !args.no_summary && summary_path.is_file() {
        SummaryScene::read(&summary_path)?
    } else {
        SummaryScene::default()
    };
    let lab = match (&args.lab, &summary.lab) {
        (Some(spec), _) => Some(load_lab(spec, None)?),
        (None, Some(spec)) => {
            Some(load_lab(spec, Some(dir)).with_context(|| format!("lab of {}", summary_path.display()))?)
        }
        (None, None) => None,
    };
    let obstacles = if args.obstacle.is_empty() {
        summary.obstacles.unwrap_or_default()
    } else {
        args.obstacle
            .iter()
            .map(|s| Obstacle::parse(s).map_err(|e| anyhow::anyhow!("--obstacle {e}")))
            .collect::<anyhow::Result<_>>()?
    };
    let checkpoints = if args.checkpoint.is_empty() {
        summary.checkpoints.unwrap_or_default()
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
