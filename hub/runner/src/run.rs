//! `iwsim run`: a scenario as real processes — the hub, every agent and (unless headless) the
//! viewer — then a summary read back from the agents' per-robot logs.
//!
//! The logs are the record: each agent writes one CSV line per robot per tick, so the summary
//! (checkpoints reached, contacts, times, speeds) is exact whatever the tick rate, and the same
//! seed in lock-step gives the same summary, bit for bit.

use std::fmt::Write as _;
use std::io::{BufRead, IsTerminal, Write as _};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitCode, Stdio};
use std::time::{Duration, Instant};

use agent_sdk::log::LogTable;
use anyhow::Context as _;
use records::outcome::HubOutcome;
pub use records::summary::{RobotSummary, RunSummary};

use crate::args::RunArgs;
use crate::scenario::{Scenario, option_flags};

/// Reads a robot's log and measures what the summary reports.
pub fn summarise_log(path: &Path, route: &[usize], scenario: &Scenario) -> anyhow::Result<RobotSummary> {
    let t = LogTable::read(path)?;
    let col = |n: &str| t.column(n);
    let (ct, cx, cy, ch, cc) = (col("time_s")?, col("x_m")?, col("y_m")?, col("heading_deg")?, col("contacts")?);
    let mut s = RobotSummary {
        name: records::log::robot_name_of(path),
        log: path.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default(),
        route: route.to_vec(),
        checkpoints_reached: 0,
        checkpoints_total: route.len(),
        reached_at_s: Vec::new(),
        time_s: None,
        collisions: 0,
        ticks: t.rows.len(),
        distance_m: 0.0,
        top_speed_mps: 0.0,
        rise_time_s: 0.0,
        final_pose: [0.0; 3],
    };
    let mut speeds: Vec<(f64, f64)> = Vec::new();
    let mut last: Option<&Vec<f64>> = None;
    for row in &t.rows {
        if let Some(&n) = route.get(s.checkpoints_reached)
            && scenario.checkpoints[n - 1].contains(row[cx], row[cy])
        {
            s.checkpoints_reached += 1;
            s.reached_at_s.push(row[ct]);
        }
        if let Some(prev) = last {
            let d = (row[cx] - prev[cx]).hypot(row[cy] - prev[cy]);
            let dt = row[ct] - prev[ct];
            s.distance_m += d;
            if dt > 0.0 {
                speeds.push((row[ct], d / dt));
            }
        }
        s.collisions = row[cc] as u64;
        s.final_pose = [row[cx], row[cy], row[ch]];
        last = Some(row);
    }
    s.time_s = s.reached_at_s.last().copied();
    s.top_speed_mps = speeds.iter().map(|&(_, v)| v).fold(0.0, f64::max);
    let first = |f: f64| speeds.iter().find(|&&(_, v)| v >= f * s.top_speed_mps).map(|&(t, _)| t);
    if let (Some(t10), Some(t90)) = (first(0.1), first(0.9)) {
        s.rise_time_s = t90 - t10;
    }
    Ok(s)
}

/// Checks a run against the scenario's expectations.
fn check(scenario: &Scenario, robots: &[RobotSummary]) -> Vec<String> {
    let mut failures = Vec::new();
    if let Some(max) = scenario.expect.max_collisions {
        for r in robots.iter().filter(|r| r.collisions > max) {
            failures.push(format!("{}: {} contacts (at most {max} expected)", r.name, r.collisions));
        }
    }
    let within = |v: f64, [lo, hi]: [f64; 2]| (lo..=hi).contains(&v);
    for (name, e) in &scenario.expect.robots {
        let Some(r) = robots.iter().find(|r| &r.name == name) else {
            failures.push(format!("{name}: no log (did its agent start?)"));
            continue;
        };
        if e.route && r.checkpoints_reached < r.checkpoints_total {
            failures.push(format!("{name}: reached {} of {} checkpoints", r.checkpoints_reached, r.checkpoints_total));
        }
        for (what, value, range) in [
            ("top speed", r.top_speed_mps, e.top_speed_mps),
            ("rise time", r.rise_time_s, e.rise_time_s),
            ("final heading", r.final_pose[2], e.final_heading_deg),
            ("final x", r.final_pose[0], e.final_x_m),
        ] {
            if let Some(range) = range
                && !within(value, range)
            {
                failures.push(format!("{name}: {what} {value:.4} outside [{}, {}]", range[0], range[1]));
            }
        }
    }
    failures
}

fn iwsim() -> anyhow::Result<PathBuf> {
    std::env::current_exe().context("finding the iwsim executable")
}

/// A child that is killed if the run is abandoned.
struct Kid {
    child: Option<Child>,
    what: String,
}

impl Kid {
    /// Starts `iwsim ARGS`; only the hub's stdout (its JSON summary) is kept.
    fn spawn(args: &[String], what: &str, keep_stdout: bool) -> anyhow::Result<Self> {
        let child = Command::new(iwsim()?)
            .args(args)
            .stdin(Stdio::null())
            .stderr(Stdio::piped())
            .stdout(if keep_stdout { Stdio::piped() } else { Stdio::null() })
            .spawn()
            .with_context(|| format!("starting the {what}"))?;
        Ok(Self { child: Some(child), what: what.to_owned() })
    }

    /// Copies the child's stderr, line by line, to `sink` (prefixed, unless the line already
    /// starts with the prefix's word, as agents' lines do: `navigator chair1: …`), on a thread.
    fn forward_stderr(&mut self, prefix: String, echo: bool, sink: std::sync::mpsc::Sender<String>) {
        let Some(err) = self.child.as_mut().and_then(|c| c.stderr.take()) else { return };
        std::thread::spawn(move || {
            let word = prefix.trim_end_matches(": ").to_owned();
            for line in std::io::BufReader::new(err).lines().map_while(Result::ok) {
                let line = if !word.is_empty() && line.starts_with(&word) { line } else { format!("{prefix}{line}") };
                if echo {
                    eprintln!("{line}");
                }
                let _ = sink.send(line);
            }
        });
    }

    /// Waits up to `timeout` for the child to exit; returns its stdout (if piped).
    fn wait(mut self, timeout: Duration) -> anyhow::Result<String> {
        let mut child = self.child.take().context("already waited")?;
        let start = Instant::now();
        loop {
            if let Some(status) = child.try_wait()? {
                let mut out = String::new();
                if let Some(mut so) = child.stdout.take() {
                    use std::io::Read as _;
                    let _ = so.read_to_string(&mut out);
                }
                anyhow::ensure!(status.success(), "the {} exited with {status}", self.what);
                return Ok(out);
            }
            if start.elapsed() > timeout {
                let _ = child.kill();
                let _ = child.wait();
                anyhow::bail!("the {} did not exit within {timeout:?} after the run ended; killed it", self.what);
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

impl Drop for Kid {
    fn drop(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// How to run a scenario once.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Lock-step (as fast as the agents allow) instead of real time.
    pub lockstep: bool,
    /// No viewer.
    pub headless: bool,
    /// Where the viewer serves.
    pub http: std::net::SocketAddr,
    /// Let the viewer's page control the run.
    pub allow_control: bool,
    /// Print progress and the agents' messages.
    pub verbose: bool,
}

/// Runs `scenario` once with `seed`, writing logs and `summary.json` into `out`.
pub fn run_once(scenario: &Scenario, seed: u64, out: &Path, opts: &RunOptions) -> anyhow::Result<RunSummary> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    for e in std::fs::read_dir(out)?.flatten() {
        if e.path().extension().is_some_and(|x| x == "csv") {
            std::fs::remove_file(e.path())?;
        }
    }
    let session = format!("run-{}-{seed}-{}", std::process::id(), crate::run::unique());
    let ticks = scenario.ticks();
    let s = |x: &str| x.to_owned();
    let mut hub_args = vec![
        s("hub"),
        s("--session"),
        session.clone(),
        s("--lab"),
        scenario.lab_spec(),
        s("--cycle-ms"),
        scenario.cycle_ms.to_string(),
        s("--seed"),
        seed.to_string(),
        s("--ticks"),
        ticks.to_string(),
        s("--wait-agents"),
        scenario.agents.len().to_string(),
        s("--json"),
    ];
    if let Some(g) = scenario.grid_spec() {
        hub_args.extend([s("--grid"), g]);
    }
    if opts.lockstep {
        hub_args.extend([s("--lockstep"), s("--deadline-ms"), s("5000")]);
    }
    if !scenario.noise {
        hub_args.push(s("--no-noise"));
    }
    for o in &scenario.obstacles {
        hub_args.extend([s("--obstacle"), o.to_string()]);
    }
    for c in &scenario.checkpoints {
        hub_args.extend([s("--checkpoint"), c.to_string()]);
    }
    let started = Instant::now();
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    let mut hub = Kid::spawn(&hub_args, "hub", true)?;
    hub.forward_stderr(s("hub: "), false, tx.clone());
    let mut agents = Vec::new();
    for (k, a) in scenario.agents.iter().enumerate() {
        let mut args = vec![
            s("agent"),
            a.kind.clone(),
            s("--session"),
            session.clone(),
            s("--connect-timeout"),
            s("30"),
            s("--log"),
            out.display().to_string(),
        ];
        if let Some(cfg) = &a.config {
            let path = out.join(format!("agent{}-{}.toml", k + 1, a.kind));
            std::fs::write(&path, toml::to_string(cfg).context("writing an agent's config")?)?;
            args.extend([s("--config"), path.display().to_string()]);
        }
        args.extend(option_flags(&a.options).map_err(|e| anyhow::anyhow!("agent {} ({}): {e}", k + 1, a.kind))?);
        let mut kid = Kid::spawn(&args, &format!("agent {} ({})", k + 1, a.kind), false)?;
        kid.forward_stderr(format!("{}: ", a.kind), opts.verbose, tx.clone());
        agents.push(kid);
    }
    let mut viewer = None;
    if !opts.headless {
        let mut args = vec![s("view"), s("--session"), session.clone(), s("--http"), opts.http.to_string()];
        if opts.allow_control {
            args.push(s("--allow-control"));
        }
        let mut v = Kid::spawn(&args, "viewer", false)?;
        let (vtx, vrx) = std::sync::mpsc::channel();
        v.forward_stderr(String::new(), false, vtx);
        match vrx.recv_timeout(Duration::from_secs(20)) {
            Ok(line) if line.contains("open http") => {
                eprintln!("{line}");
                viewer = Some(v);
            }
            Ok(line) => eprintln!("iwsim run: the viewer did not start ({line}); going on headless"),
            Err(_) => eprintln!("iwsim run: the viewer did not start; going on headless"),
        }
    }
    drop(tx);
    // Progress: every few seconds on long runs, from the world the hub publishes.
    let (stop_progress, stopped) = std::sync::mpsc::channel::<()>();
    let progress = opts.verbose.then(|| {
        let session = session.clone();
        std::thread::spawn(move || progress_loop(&session, ticks, &stopped))
    });
    let hub_out = hub.wait(Duration::from_secs(24 * 3600));
    drop(stop_progress);
    let agent_results: Vec<anyhow::Result<String>> =
        agents.into_iter().map(|a| a.wait(Duration::from_secs(20))).collect();
    if let Some(v) = viewer {
        let _ = v.wait(Duration::from_secs(10));
    }
    if let Some(p) = progress {
        let _ = p.join();
    }
    let messages: Vec<String> = rx.try_iter().collect();
    let hub_out =
        hub_out.with_context(|| format!("the run failed; what the processes said:\n{}", messages.join("\n")))?;
    // An agent that fails (a navigator that did not arrive exits 1) fails the run's outcome,
    // not the runner: the summary still says what happened.
    let agent_failures: Vec<String> =
        agent_results.into_iter().filter_map(|r| r.err().map(|e| e.to_string())).collect();
    let hub_outcome = HubOutcome::from_stdout(&hub_out).context("reading how the hub's run ended")?;
    let mut robots = Vec::new();
    let mut logs: Vec<PathBuf> = std::fs::read_dir(out)?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "csv"))
        .collect();
    logs.sort();
    for log in logs {
        let name = records::log::robot_name_of(&log);
        let route = scenario.routes.get(&name).cloned().unwrap_or_default();
        robots.push(summarise_log(&log, &route, scenario)?);
    }
    let mut failures = check(scenario, &robots);
    failures.extend(agent_failures);
    let summary = RunSummary {
        scenario: scenario.name.clone(),
        seed,
        ticks: hub_outcome.ticks,
        state_hash: hub_outcome.state_hash,
        wall_s: started.elapsed().as_secs_f64(),
        passed: failures.is_empty(),
        failures,
        lab: scenario.lab_spec(),
        obstacles: scenario.obstacles.clone(),
        checkpoints: scenario.checkpoints.clone(),
        robots,
    };
    std::fs::write(out.join("summary.json"), summary.to_json())?;
    Ok(summary)
}

/// A number unique within this process, for session names.
pub fn unique() -> u32 {
    use std::sync::atomic::{AtomicU32, Ordering};
    static N: AtomicU32 = AtomicU32::new(0);
    N.fetch_add(1, Ordering::Relaxed)
}

/// Prints how far the run is every two seconds until the hub ends it or `stop` is dropped
/// (a fast lock-step run may end before the observer sees its last snapshot).
fn progress_loop(session: &str, ticks: u64, stop: &std::sync::mpsc::Receiver<()>) {
    let Ok(obs) = agent_sdk::Observer::connect_within(session, "iwsim-run-progress", Duration::from_secs(30)) else {
        return;
    };
    let tty = std::io::stderr().is_terminal();
    let mut last_print = Instant::now();
    let mut last_tick = 0;
    loop {
        match obs.try_world() {
            Ok(Some((h, _))) => {
                last_tick = h.tick;
                if h.run_state == ipc_types::RunState::Finished as u32 {
                    break;
                }
            }
            Ok(None) => {}
            Err(_) => break,
        }
        if last_print.elapsed() >= Duration::from_secs(2) {
            let pct = 100.0 * last_tick as f64 / ticks.max(1) as f64;
            if tty {
                eprint!("\r  tick {last_tick} / {ticks} ({pct:.0} %)   ");
            } else {
                eprintln!("  tick {last_tick} / {ticks} ({pct:.0} %)");
            }
            last_print = Instant::now();
        }
        if let Err(std::sync::mpsc::RecvTimeoutError::Disconnected) = stop.recv_timeout(Duration::from_millis(50)) {
            break;
        }
    }
    if tty {
        eprint!("\r{:40}\r", "");
    }
    obs.close();
}

/// Prints a run's summary table.
pub fn print_summary(s: &RunSummary, out: &Path) {
    println!(
        "scenario {} seed {}: {} ticks, state hash {}, {:.1} s wall clock",
        s.scenario, s.seed, s.ticks, s.state_hash, s.wall_s
    );
    println!(
        "  {:<10} {:>11} {:>9} {:>10} {:>9} {:>10} {:>9}",
        "robot", "checkpoints", "time s", "contacts", "driven m", "top m/s", "rise s"
    );
    for r in &s.robots {
        println!(
            "  {:<10} {:>11} {:>9} {:>10} {:>9.2} {:>10.3} {:>9.1}",
            r.name,
            format!("{}/{}", r.checkpoints_reached, r.checkpoints_total),
            r.reached_at_s.last().map_or("-".to_owned(), |t| format!("{t:.1}")),
            r.collisions,
            r.distance_m,
            r.top_speed_mps,
            r.rise_time_s
        );
    }
    if s.passed {
        println!("  expected outcome: PASS");
    } else {
        for f in &s.failures {
            println!("  FAIL: {f}");
        }
    }
    println!("  logs and summary.json in {}", out.display());
}

/// Parses `A..B` (inclusive).
pub fn parse_seeds(text: &str) -> Result<std::ops::RangeInclusive<u64>, String> {
    let (a, b) = text.split_once("..").ok_or_else(|| format!("--seeds {text}: expected A..B, e.g. 1..20"))?;
    let a: u64 = a.trim().parse().map_err(|_| format!("--seeds {text}: {a:?} is not a number"))?;
    let b: u64 =
        b.trim().trim_start_matches('=').parse().map_err(|_| format!("--seeds {text}: {b:?} is not a number"))?;
    if a > b {
        return Err(format!("--seeds {text}: the first seed is after the last"));
    }
    Ok(a..=b)
}

/// `iwsim run`.
pub fn run(args: &RunArgs) -> anyhow::Result<ExitCode> {
    let scenario = Scenario::load(&args.scenario)?;
    let out = args.out.clone().unwrap_or_else(|| PathBuf::from(format!("runs/{}", scenario.name)));
    let opts = RunOptions {
        lockstep: args.lockstep,
        headless: args.headless || args.seeds.is_some(),
        http: args.http,
        allow_control: args.allow_control,
        verbose: !args.quiet,
    };
    let Some(seeds) = &args.seeds else {
        let seed = args.seed.unwrap_or(scenario.seed);
        eprintln!(
            "iwsim run: {} ({}), seed {seed}, {} s simulated in {}",
            scenario.name,
            scenario.description,
            scenario.seconds,
            if opts.lockstep { "lock-step" } else { "real time" }
        );
        let s = run_once(&scenario, seed, &out, &opts)?;
        print_summary(&s, &out);
        return Ok(if s.passed { ExitCode::SUCCESS } else { ExitCode::FAILURE });
    };
    let seeds = parse_seeds(seeds).map_err(anyhow::Error::msg)?;
    let mut table = String::new();
    let mut all = Vec::new();
    let _ = writeln!(
        table,
        "  {:>6} {:>6} {:>11} {:>10} {:>9}  state hash",
        "seed", "pass", "checkpoints", "contacts", "time s"
    );
    for seed in seeds {
        let dir = out.join(format!("seed-{seed}"));
        let s = run_once(&scenario, seed, &dir, &RunOptions { verbose: false, ..opts.clone() })?;
        let reached: usize = s.robots.iter().map(|r| r.checkpoints_reached).sum();
        let total: usize = s.robots.iter().map(|r| r.checkpoints_total).sum();
        let contacts: u64 = s.robots.iter().map(|r| r.collisions).sum();
        let time = s.robots.iter().filter_map(|r| r.reached_at_s.last().copied()).fold(f64::NAN, f64::max);
        let line = format!(
            "  {:>6} {:>6} {:>11} {:>10} {:>9}  {}",
            seed,
            if s.passed { "yes" } else { "NO" },
            format!("{reached}/{total}"),
            contacts,
            if time.is_nan() { "-".into() } else { format!("{time:.1}") },
            s.state_hash
        );
        if !args.quiet {
            eprintln!("{line}");
        }
        table += &line;
        table.push('\n');
        all.push(s);
    }
    let passed = all.iter().filter(|s| s.passed).count();
    // A run's time is its last robot's arrival, as in the table's rows.
    let times: Vec<f64> = all
        .iter()
        .map(|s| s.robots.iter().filter_map(|r| r.reached_at_s.last().copied()).fold(f64::NAN, f64::max))
        .filter(|t| !t.is_nan())
        .collect();
    let contacts: u64 = all.iter().flat_map(|s| s.robots.iter().map(|r| r.collisions)).sum();
    println!(
        "scenario {}: {} runs, {}",
        scenario.name,
        all.len(),
        if opts.lockstep { "lock-step" } else { "real time" }
    );
    print!("{table}");
    println!(
        "  success rate {passed}/{} ({:.0} %), mean time {}, collisions {contacts} in all",
        all.len(),
        100.0 * passed as f64 / all.len().max(1) as f64,
        if times.is_empty() {
            "-".to_owned()
        } else {
            format!("{:.1} s", times.iter().sum::<f64>() / times.len() as f64)
        }
    );
    for s in all.iter().filter(|s| !s.passed) {
        for f in &s.failures {
            println!("  seed {}: {f}", s.seed);
        }
    }
    println!("  logs in {}/seed-*/", out.display());
    let _ = std::io::stdout().flush();
    Ok(if passed == all.len() { ExitCode::SUCCESS } else { ExitCode::FAILURE })
}
