//! `iwsim bench viewer`: how the live viewer keeps up with many chairs, measured in a real
//! headless Chromium, and what a viewer with a page attached costs the hub's lock-step.

use std::process::{Child, ExitCode};
use std::time::Duration;

use crate::browser::Browser;
use anyhow::Context as _;
use run_records::outcome::HubOutcome;

use crate::args::BenchViewerArgs;
use crate::{finish, spawn_self};

/// Frame and draw rates of the page for one view.
#[derive(Debug, Clone, PartialEq)]
pub struct PageRate {
    /// `2d`, `3d free` or `3d first`.
    pub view: &'static str,
    /// Animation frames the page drew per second.
    pub draws_per_s: f64,
    /// World frames the page received and decoded per second.
    pub frames_per_s: f64,
    /// Mean milliseconds of page script per drawn frame (drawing, or 3D update and render).
    pub draw_ms: f64,
}

/// An empty square lab with one long wall, big enough for `robots` chairs 1.25 m apart in
/// rows of ten.
fn write_lab(dir: &std::path::Path, robots: usize) -> anyhow::Result<(std::path::PathBuf, f64)> {
    let side = (robots.div_ceil(10) as f64 * 1.25 + 10.0).max(30.0);
    let lab = dir.join("lab.xml");
    std::fs::write(
        &lab,
        format!(
            "<Lab Name=\"viewer bench\" Width=\"{side}\" Height=\"{side}\">\n  <Wall Height=\"2.5\"><Corner X=\"20\" Y=\"1\"/><Corner X=\"21\" Y=\"1\"/><Corner X=\"21\" Y=\"{}\"/><Corner X=\"20\" Y=\"{}\"/></Wall>\n</Lab>\n",
            side - 1.0,
            side - 1.0
        ),
    )?;
    Ok((lab, side))
}

fn s(x: &str) -> String {
    x.to_owned()
}

fn chairs(session: &str, robots: usize) -> anyhow::Result<Child> {
    spawn_self(&[
        s("agent"),
        s("wheelchair"),
        s("--session"),
        s(session),
        s("--robots"),
        robots.to_string(),
        s("--pose"),
        s("3,3,90"),
        s("--spacing"),
        s("1.25"),
        s("--width"),
        s("0.9"),
        s("--height"),
        s("0.6"),
        s("--powers"),
        s("0.3,0.28"),
        s("--connect-timeout"),
        s("30"),
    ])
}

/// Starts `iwsim view` on a free port and returns it with its address.
fn viewer_process(session: &str) -> anyhow::Result<(Child, String)> {
    use std::io::BufRead;
    let mut v = spawn_self(&[
        s("view"),
        s("--session"),
        s(session),
        s("--http"),
        s("127.0.0.1:0"),
        s("--connect-timeout"),
        s("30"),
    ])?;
    let err = v.stderr.take().context("viewer stderr")?;
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(err).lines().map_while(Result::ok) {
            if let Some(rest) = line.split("open ").nth(1) {
                let _ = tx.send(rest.trim().to_owned());
            }
        }
    });
    let url = rx.recv_timeout(Duration::from_secs(30)).context("the viewer printed no address")?;
    Ok((v, url))
}

/// Loads `url` and waits until the page holds all `robots`.
fn open_page(b: &mut Browser, url: &str, robots: usize) -> anyhow::Result<()> {
    b.navigate(url)?;
    b.wait_for(
        &format!("window.iwsim.frame && window.iwsim.frame.robots.length === {robots} && window.iwsim.draws > 5"),
        Duration::from_secs(60),
    )?;
    Ok(())
}

/// Counts the page's draws and frames over `seconds` of real time.
fn measure_page(b: &mut Browser, view: &'static str, seconds: f64) -> anyhow::Result<PageRate> {
    let js = format!(
        "new Promise((ok) => {{ const p = window.iwsim, t0 = performance.now(), d0 = p.draws, f0 = p.frames, c0 = p.drawCostMs; \
         setTimeout(() => {{ const dt = (performance.now() - t0) / 1000, n = p.draws - d0; \
         ok([n / dt, (p.frames - f0) / dt, (p.drawCostMs - c0) / Math.max(n, 1)]); }}, {}); }})",
        (seconds * 1000.0) as u64
    );
    let v = b.eval(&js)?;
    let at = |k: usize| v[k].as_f64().unwrap_or(0.0);
    Ok(PageRate { view, draws_per_s: at(0), frames_per_s: at(1), draw_ms: at(2) })
}

/// The page's rates with `robots` chairs driving, the hub ticking 100 times a second.
pub fn measure_page_rates(robots: usize, seconds: f64) -> anyhow::Result<Vec<PageRate>> {
    let dir = std::env::temp_dir().join(format!("iwsim-bench-view-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let (lab, _) = write_lab(&dir, robots)?;
    let session = format!("bench-view-{}", std::process::id());
    let hub = spawn_self(&[
        s("hub"),
        s("--session"),
        session.clone(),
        s("--lab"),
        lab.display().to_string(),
        s("--cycle-ms"),
        s("10"),
        s("--no-noise"),
    ])?;
    let agent = chairs(&session, robots)?;
    let (view, url) = viewer_process(&session)?;
    let rates = (|| {
        let mut b = Browser::launch(1280, 720)?;
        let mut out = Vec::new();
        for (name, query) in
            [("2d", "?view=2d"), ("3d free", "?view=3d&camera=free"), ("3d first", "?view=3d&camera=first")]
        {
            open_page(&mut b, &format!("{url}{query}"), robots)?;
            out.push(measure_page(&mut b, name, seconds)?);
        }
        anyhow::Ok(out)
    })();
    let stopped = agent_sdk::control(&session, ipc_types::Command::Stop, 0);
    for (c, what) in [(hub, "hub"), (agent, "agent"), (view, "viewer")] {
        finish(c, what)?;
    }
    let _ = std::fs::remove_dir_all(&dir);
    stopped.context("stopping the hub")?;
    rates
}

/// What watches the hub in a hub-cost run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Watcher {
    /// Nothing.
    None,
    /// `iwsim view` with one WebSocket client taking every frame (a page on another machine).
    Viewer,
    /// `iwsim view` with the page open in headless Chromium on this machine.
    ViewerAndBrowser,
}

/// Drains a viewer's WebSocket on a thread until the viewer closes it.
fn drain_frames(url: &str) -> anyhow::Result<std::thread::JoinHandle<u64>> {
    let host = url.trim_start_matches("http://").trim_end_matches('/').to_owned();
    let (mut ws, _) = tungstenite::connect(format!("ws://{host}/ws")).context("connecting to the viewer")?;
    Ok(std::thread::spawn(move || {
        let mut frames = 0;
        while let Ok(m) = ws.read() {
            frames += m.is_binary() as u64;
        }
        frames
    }))
}

/// Lock-step ticks per second of one agent with `robots` chairs, watched by `watcher`. The
/// hub holds tick 0 until everything is attached, so every run times the same stepping.
pub fn measure_hub_cost(robots: usize, ticks: u64, watcher: Watcher) -> anyhow::Result<f64> {
    let with_viewer = watcher != Watcher::None;
    let dir = std::env::temp_dir().join(format!("iwsim-bench-viewcost-{}-{}", std::process::id(), with_viewer as u8));
    std::fs::create_dir_all(&dir)?;
    let (lab, _) = write_lab(&dir, robots)?;
    let session = format!("bench-viewcost-{}-{}", std::process::id(), with_viewer as u8);
    let hub = spawn_self(&[
        s("hub"),
        s("--session"),
        session.clone(),
        s("--lab"),
        lab.display().to_string(),
        s("--lockstep"),
        s("--start-on-command"),
        s("--ticks"),
        ticks.to_string(),
        s("--json"),
    ])?;
    let agent = chairs(&session, robots)?;
    let attached = (|| {
        let (mut page, mut view, mut drain) = (None, None, None);
        if with_viewer {
            let (v, url) = viewer_process(&session)?;
            view = Some(v);
            if watcher == Watcher::ViewerAndBrowser {
                let mut b = Browser::launch(1280, 720)?;
                open_page(&mut b, &url, robots)?;
                page = Some(b);
            } else {
                drain = Some(drain_frames(&url)?);
            }
        }
        {
            let mut obs = observer::Observer::connect_within(&session, "bench-observer", Duration::from_secs(30))?;
            let start = std::time::Instant::now();
            loop {
                if let Some((_, r)) = obs.try_world()?
                    && r.len() == robots
                {
                    break;
                }
                anyhow::ensure!(start.elapsed() < Duration::from_secs(60), "the chairs did not register");
                std::thread::sleep(Duration::from_millis(5));
            }
            obs.close();
        }
        agent_sdk::control(&session, ipc_types::Command::Start, 0)?;
        anyhow::Ok((view, page, drain))
    })();
    if attached.is_err() {
        let _ = agent_sdk::control(&session, ipc_types::Command::Stop, 0);
    }
    let out = finish(hub, "hub")?;
    finish(agent, "agent")?;
    let (view, page, drain) = attached?;
    drop(page);
    if let Some(v) = view {
        finish(v, "viewer")?;
    }
    if let Some(d) = drain {
        let frames = d.join().map_err(|_| anyhow::anyhow!("the frame reader panicked"))?;
        anyhow::ensure!(frames > 0, "the viewer sent no frames");
    }
    let _ = std::fs::remove_dir_all(&dir);
    let hub_out = HubOutcome::from_stdout(&out).context("reading how the hub's run ended")?;
    Ok(hub_out.ticks as f64 / hub_out.run_s.max(1e-9))
}

/// `iwsim bench viewer`.
pub fn run(args: &BenchViewerArgs) -> anyhow::Result<ExitCode> {
    let rates = measure_page_rates(args.robots, args.seconds)?;
    let bare = measure_hub_cost(args.robots, args.ticks, Watcher::None)?;
    let viewed = measure_hub_cost(args.robots, args.ticks, Watcher::Viewer)?;
    let browsed = measure_hub_cost(args.robots, args.ticks, Watcher::ViewerAndBrowser)?;
    if args.json {
        let pages: Vec<String> = rates
            .iter()
            .map(|r| {
                format!(
                    "{{\"view\":\"{}\",\"draws_per_s\":{:.1},\"frames_per_s\":{:.1},\"draw_ms\":{:.2}}}",
                    r.view, r.draws_per_s, r.frames_per_s, r.draw_ms
                )
            })
            .collect();
        println!(
            "{{\"robots\":{},\"pages\":[{}],\"hub_ticks_per_s_without_viewer\":{bare:.1},\"hub_ticks_per_s_with_viewer\":{viewed:.1},\"hub_ticks_per_s_with_viewer_and_browser\":{browsed:.1},\"ratio_viewer\":{:.3},\"ratio_viewer_and_browser\":{:.3}}}",
            args.robots,
            pages.join(","),
            viewed / bare.max(1e-9),
            browsed / bare.max(1e-9)
        );
    } else {
        println!("viewer page in headless Chromium (software rendering), {} chairs, hub at 100 ticks/s:", args.robots);
        for r in &rates {
            println!(
                "  {:<9} {:5.1} draws/s, {:5.1} world frames/s, {:5.2} ms of script per draw",
                r.view, r.draws_per_s, r.frames_per_s, r.draw_ms
            );
        }
        println!("hub lock-step, 1 agent x {} chairs, {} ticks:", args.robots, args.ticks);
        println!("  no viewer                               {bare:7.0} ticks/s");
        println!("  viewer streaming every frame to a client {viewed:7.0} ticks/s ({:.3}x)", viewed / bare.max(1e-9));
        println!("  viewer and Chromium on the same 2 cores  {browsed:7.0} ticks/s ({:.3}x)", browsed / bare.max(1e-9));
    }
    Ok(ExitCode::SUCCESS)
}
