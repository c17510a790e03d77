//! `iwsim bench traffic`: many navigators sharing the ward in lock-step, run as a user runs them
//! (`iwsim run` of the ward with `N` chairs, each navigator its own process, the hub recording),
//! so the load is the real one: planning, traffic messages, waiting at doorways.
//!
//! Per crowd size, the median of `--runs` runs (seeds 1, 2, …) with min and max of:
//! - **ticks/s** over the run (from the hub's first step to its last), and in the run's
//!   slowest second, read by an observer of the session (the hub's tick every 20 ms);
//! - **CPU per tick** of the hub and of each navigator (user + system time, every thread, over
//!   the run's ticks), from the run's `summary.json`, where the runner writes each process's
//!   resource use as it reaps it: exact even for a run shorter than a sampling interval;
//! - **how the traffic went**, from the run's `summary.json` (judged from its recording):
//!   chairs arrived, contacts of any kind, deadlocks.
//!
//! The runs of the sizes are interleaved (round 1 of every size, then round 2, …) so that the
//! machine's drifting load weighs on each alike.

use runner::signals::Signals;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode, Stdio};
use std::time::{Duration, Instant};

use anyhow::Context as _;

use crate::args::BenchTrafficArgs;
use crate::repeat::{Spread, interleaved};

/// How often the run's tick is looked at.
const SAMPLE_EVERY: Duration = Duration::from_millis(20);
/// The window of the slowest-second figure.
const WINDOW_S: f64 = 1.0;

/// What one run measured.
#[derive(Debug, Clone, PartialEq)]
pub struct TrafficRun {
    /// Ticks the run stepped (its summary's).
    pub ticks: u64,
    /// Ticks per second from the first step to the last.
    pub ticks_per_s: f64,
    /// Ticks per second in the slowest [`WINDOW_S`] of the run (`None`: shorter than that).
    pub slowest_window_ticks_per_s: Option<f64>,
    /// The hub's CPU per tick, microseconds.
    pub hub_us_per_tick: f64,
    /// One navigator's CPU per tick, microseconds (their mean).
    pub navigator_us_per_tick: f64,
    /// Navigator processes seen.
    pub navigators: usize,
    /// Chairs that arrived, of those in the run.
    pub arrived: u64,
    /// Chairs in the run.
    pub chairs: u64,
    /// Contacts of any kind (chair, wall, obstacle).
    pub contacts: u64,
    /// Deadlocks the judge found.
    pub deadlocks: u64,
}

/// Ticks per second between the first sample past tick 0 and the last sample whose tick moved,
/// and the lowest rate over any [`WINDOW_S`] between them. `samples`: (seconds, tick), in time
/// order.
pub fn tick_rates(samples: &[(f64, u64)]) -> Option<(f64, Option<f64>)> {
    let first = samples.iter().position(|&(_, t)| t >= 1)?;
    let last_tick = samples.last()?.1;
    let last = samples.iter().position(|&(_, t)| t == last_tick)?;
    let (t0, k0) = samples[first];
    let (t1, k1) = samples[last];
    if t1 <= t0 {
        return None;
    }
    let overall = (k1 - k0) as f64 / (t1 - t0);
    let mut slowest: Option<f64> = None;
    let mut j = first;
    for i in first..=last {
        let (ti, ki) = samples[i];
        while j <= last && samples[j].0 - ti < WINDOW_S {
            j += 1;
        }
        if j > last {
            break;
        }
        let (tj, kj) = samples[j];
        let rate = (kj - ki) as f64 / (tj - ti);
        slowest = Some(slowest.map_or(rate, |s: f64| s.min(rate)));
    }
    Some((overall, slowest))
}

/// The scenario file of one run: the ward with `chairs` navigators, `seconds` long, as
/// `builtin:ward` has them (keeping right).
fn scenario(chairs: usize, seconds: f64) -> String {
    format!(
        "# Written by iwsim bench traffic.\nname = \"traffic-{chairs}\"\nlab = \"builtin:ward\"\nseconds = {seconds}\n\
         cycle_ms = 100\nnoise = true\n\n[crowd]\nchairs = {chairs}\noptions = {{ keep-right = 2.0 }}\n"
    )
}

/// Runs the ward once with `chairs` navigators on `seed`, in `dir`, and measures it.
fn measure(chairs: usize, seed: u64, seconds: f64, dir: &Path, signals: &Signals) -> anyhow::Result<TrafficRun> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let file = dir.join("scenario.toml");
    std::fs::write(&file, scenario(chairs, seconds)).with_context(|| format!("writing {}", file.display()))?;
    let out = dir.join("out");
    let session = format!("bench-traffic-{}-{chairs}-{seed}", std::process::id());
    let stderr_path = dir.join("run.stderr");
    let stderr = std::fs::File::create(&stderr_path).with_context(|| format!("creating {}", stderr_path.display()))?;
    let exe = std::env::current_exe().context("finding the iwsim binary")?;
    let mut cmd = Command::new(exe);
    cmd.arg("run").arg(&file).args(["--lockstep", "--headless", "--quiet", "--seed", &seed.to_string()]);
    cmd.arg("--out").arg(&out).args(["--session", &session]).stdout(Stdio::null()).stderr(stderr);
    runner::signals::die_with_parent(&mut cmd);
    runner::signals::unblock_in_child(&mut cmd);
    let mut child = cmd.spawn().context("starting iwsim run")?;
    let start = Instant::now();
    let mut timeline: Vec<(f64, u64)> = Vec::new();
    let mut observer: Option<observer::Observer> = None;
    let status = loop {
        if observer.is_none() {
            observer = observer::Observer::connect_within(&session, "bench-traffic", Duration::ZERO).ok();
        }
        if let Some(o) = &mut observer {
            match o.try_with_world(|h, _| h.tick) {
                Ok(Some(tick)) => timeline.push((start.elapsed().as_secs_f64(), tick)),
                Ok(None) => {}
                // The hub ended: the last tick is already in the timeline.
                Err(_) => observer = None,
            }
        }
        if let Some(status) = child.try_wait().context("waiting for iwsim run")? {
            break status;
        }
        // Ctrl-C or SIGTERM: the run is told likewise (it stops its hub and agents and
        // removes their shared memory) and waited for, and the bench ends.
        if let Some(signal) = signals.wait(SAMPLE_EVERY) {
            drop(observer);
            runner::signals::send(&child, signal.forwarded());
            let _ = child.wait();
            anyhow::bail!("interrupted by {} during the {chairs}-chair run of seed {seed}", signal.name());
        }
    };
    drop(observer);
    let summary_path = out.join("summary.json");
    let text = std::fs::read_to_string(&summary_path).with_context(|| {
        let said = std::fs::read_to_string(&stderr_path).unwrap_or_default();
        format!("iwsim run ({status}) wrote no {}: {said}", summary_path.display())
    })?;
    let summary: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("reading {}", summary_path.display()))?;
    let ticks = summary["ticks"].as_u64().unwrap_or(0).max(1);
    let (ticks_per_s, slowest_window_ticks_per_s) = tick_rates(&timeline).unwrap_or((0.0, None));
    // The runner names its processes `hub` and `agent K (KIND)`.
    let cpu: BTreeMap<String, f64> = serde_json::from_value(summary["cpu_s"].clone())
        .with_context(|| format!("{} states no CPU time per process", summary_path.display()))?;
    let navigators: Vec<f64> = cpu.iter().filter(|(k, _)| k.ends_with("(navigator)")).map(|(_, &v)| v).collect();
    let hub_s = *cpu.get("hub").with_context(|| format!("{} states no CPU time of the hub", summary_path.display()))?;
    let traffic = &summary["traffic"];
    let n = |key: &str| traffic[key].as_u64().unwrap_or(0);
    Ok(TrafficRun {
        ticks,
        ticks_per_s,
        slowest_window_ticks_per_s,
        hub_us_per_tick: hub_s * 1e6 / ticks as f64,
        navigator_us_per_tick: navigators.iter().sum::<f64>() * 1e6 / ticks as f64 / navigators.len().max(1) as f64,
        navigators: navigators.len(),
        arrived: n("arrived"),
        chairs: n("chairs"),
        contacts: n("contacts_chair") + n("contacts_wall") + n("contacts_obstacle"),
        deadlocks: n("deadlocks"),
    })
}

/// The machine's CPU model, as `/proc/cpuinfo` names it, and its cores.
pub fn cpu_model() -> String {
    let model = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find_map(|l| l.strip_prefix("model name").map(|m| m.trim_start_matches([' ', '\t', ':']).to_owned()))
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    format!("{model}, {cores} cores")
}

fn spread(values: impl Iterator<Item = f64>) -> Spread {
    let v: Vec<f64> = values.collect();
    Spread::of(&v).unwrap_or(Spread { median: 0.0, min: 0.0, max: 0.0, runs: 0 })
}

fn spread_json(s: &Spread) -> serde_json::Value {
    serde_json::json!({ "median": s.median, "min": s.min, "max": s.max, "runs": s.runs })
}

/// `iwsim bench traffic`.
pub fn run(args: &BenchTrafficArgs) -> anyhow::Result<ExitCode> {
    let root: PathBuf = std::env::temp_dir().join(format!("iwsim-bench-traffic-{}", std::process::id()));
    let sizes = &args.chairs;
    if !args.json {
        println!(
            "iwsim bench traffic: the ward in lock-step, {} simulated s a run, seeds 1..={} (median [min–max] of {} runs)",
            args.seconds, args.runs, args.runs
        );
        println!("CPU: {}", cpu_model());
    }
    // The runs' observer is an iceoryx2 node, whose handlers would take SIGINT and SIGTERM
    // and let the bench run on: the signals wait in a signalfd that the sampling loop reads.
    let signals = Signals::install()?;
    let result = interleaved(args.runs, sizes.len(), |round, k| {
        let seed = round as u64 + 1;
        let r = measure(sizes[k], seed, args.seconds, &root.join(format!("n{}-seed{seed}", sizes[k])), &signals);
        if let (Ok(r), false) = (&r, args.json) {
            eprintln!(
                "  {} chairs, seed {seed}: {} ticks at {:.0} ticks/s, {}/{} arrived, {} contacts",
                sizes[k], r.ticks, r.ticks_per_s, r.arrived, r.chairs, r.contacts
            );
        }
        r
    });
    let _ = std::fs::remove_dir_all(&root);
    let runs = result?;
    let mut rows = Vec::new();
    for (k, rs) in runs.iter().enumerate() {
        let rate = spread(rs.iter().map(|r| r.ticks_per_s));
        let slowest = spread(rs.iter().filter_map(|r| r.slowest_window_ticks_per_s));
        let hub = spread(rs.iter().map(|r| r.hub_us_per_tick));
        let nav = spread(rs.iter().map(|r| r.navigator_us_per_tick));
        let arrived: u64 = rs.iter().map(|r| r.arrived).sum();
        let chairs: u64 = rs.iter().map(|r| r.chairs).sum();
        let contacts: u64 = rs.iter().map(|r| r.contacts).sum();
        let deadlocks: u64 = rs.iter().map(|r| r.deadlocks).sum();
        rows.push(serde_json::json!({
            "chairs": sizes[k],
            "ticks_per_s": spread_json(&rate),
            "slowest_second_ticks_per_s": spread_json(&slowest),
            "hub_cpu_us_per_tick": spread_json(&hub),
            "navigator_cpu_us_per_tick": spread_json(&nav),
            "arrived": arrived,
            "chairs_in_runs": chairs,
            "contacts": contacts,
            "deadlocks": deadlocks,
        }));
        if !args.json {
            let f = |s: &Spread| {
                if s.runs == 0 {
                    "— (no run lasted a second)".to_owned()
                } else {
                    format!("{:.0} [{:.0}–{:.0}]", s.median, s.min, s.max)
                }
            };
            println!(
                "{:>3} chairs: {} ticks/s, slowest second {} ticks/s; CPU per tick: hub {} µs, each navigator {} µs; \
                 arrived {arrived}/{chairs}, {contacts} contacts, {deadlocks} deadlocks",
                sizes[k],
                f(&rate),
                f(&slowest),
                f(&hub),
                f(&nav)
            );
        }
    }
    if args.json {
        let j = serde_json::json!({
            "cpu": cpu_model(),
            "seconds": args.seconds,
            "runs": args.runs,
            "sizes": rows,
        });
        println!("{j}");
    }
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_run_from_the_first_step_to_the_last_and_the_slowest_second_is_found() {
        // Tick 0 for half a second (the run starting), then 100 ticks/s for 2 s, 10 ticks/s
        // for 1 s, 100 ticks/s for 1 s, then the end (the last tick repeated).
        let mut s = vec![(0.0, 0), (0.5, 0)];
        let mut tick = 0;
        let mut t = 0.5;
        for rate in [100, 100, 10, 100] {
            for _ in 0..10 {
                t += 0.1;
                tick += rate / 10;
                s.push((t, tick));
            }
        }
        s.push((t + 0.5, tick));
        let (overall, slowest) = tick_rates(&s).expect("rates");
        assert!((overall - (310.0 - 10.0) / (4.5 - 0.6)).abs() < 1e-9, "{overall}");
        assert!((slowest.expect("a window") - 10.0).abs() < 1e-9, "{slowest:?}");
        assert_eq!(tick_rates(&[(0.0, 0), (1.0, 0)]), None, "no step");
    }
}
