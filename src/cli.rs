//! The command line (clap derive). Subcommand names are the contract the docs and tests use.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

/// iwsim: a co-simulation hub for intelligent wheelchairs.
#[derive(Debug, Parser)]
#[command(name = "iwsim", version, about, long_about = None)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// Subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Runs the demo: chairs driving on the LIACC floor (headless for now), with a summary.
    Demo(DemoArgs),
    /// Map files: check a lab, grid or parameters file.
    Map {
        /// What to do with the map.
        #[command(subcommand)]
        command: MapCommand,
    },
    /// Benchmarks that print figures (add --json for machine-readable output).
    Bench {
        /// Which benchmark.
        #[command(subcommand)]
        command: BenchCommand,
    },
}

/// `iwsim map …`
#[derive(Debug, Subcommand)]
pub enum MapCommand {
    /// Validates a lab, grid or parameters XML file (or `builtin:NAME`): prints a summary, or
    /// the error with its line and column.
    Check {
        /// The file, or builtin:liacc, builtin:thesis, builtin:maze.
        file: String,
    },
}

/// `iwsim bench …`
#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// World model throughput: ticks per second of tiled LIACC floors with N chairs.
    World(BenchWorldArgs),
}

/// Options of `iwsim bench world`.
#[derive(Debug, Args, Clone)]
pub struct BenchWorldArgs {
    /// Number of chairs (ten per LIACC floor).
    #[arg(long, default_value_t = 1000)]
    pub robots: usize,
    /// Ticks to time.
    #[arg(long, default_value_t = 300)]
    pub ticks: u64,
    /// Ticks the chairs drive, untimed, before timing starts (100 = 10 simulated seconds).
    /// The load grows as chairs gather near walls and each other: after 6,000 ticks each
    /// chair has about twice as many edges in sensor range.
    #[arg(long, default_value_t = 100)]
    pub warmup: u64,
    /// Seed for placement and noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Options of `iwsim demo`.
#[derive(Debug, Args, Clone)]
pub struct DemoArgs {
    /// Simulated seconds to run.
    #[arg(long, default_value_t = 120.0)]
    pub seconds: f64,
    /// Seed for the world's noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Write a CSV log per chair into this directory.
    #[arg(long)]
    pub out: Option<PathBuf>,
}
