//! Mixed reality in the viewer (issue 13, item 6): physical chairs registered the way a chair
//! adapter registers them, pushed from this test through `agent_sdk`, shown by `iwsim view` in
//! a real headless Chromium. The screenshot must show the real and the virtual reading in their
//! two colours at their distances, and the chair's true pose (the ghost) where the test bench
//! put it, and nothing of the kind beside a chair that reports no true pose.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use agent_sdk::{Agent, Wait};
use bench_harness::browser::Browser;
use ipc_types::{
    ACT_GHOST, ACT_REAL, ActionBlock, ChairState, MAX_PROXIMITY, REG_CHAIR, REG_HAS_POSE, RobotKind, RobotRegistration,
    SensorMode, SensorSpec,
};
use viewer::frame;

use super::common::{Proc, assert_no_shared_memory_left, session, text};

const W: u32 = 1200;
const H: u32 = 600;

/// The thesis example map (28 m × 14 m) fitted to a W × H page with a metre of margin, y up,
/// as the page projects it.
const SCALE: f64 = 37.5;
const OX: f64 = (W as f64 - 28.0 * SCALE) / 2.0;
const OY: f64 = (H as f64 + 14.0 * SCALE) / 2.0;

fn px(x: f64, y: f64) -> (f64, f64) {
    (OX + x * SCALE, OY - y * SCALE)
}

/// A chair the test bench reports: its odometry pose, its real readings, and its true pose
/// when the bench knows it. West of the map's first wall (x 11.5, y 2.5–11.5), facing it.
#[derive(Clone, Copy)]
struct BenchChair {
    name: &'static str,
    mode: SensorMode,
    pose: [f64; 3],
    ghost: Option<[f64; 3]>,
}

/// The front sensor's apex is 0.5 m ahead of the pose, 2.0 m short of the wall: the virtual
/// reading is 2.0 m, the real one (furniture the simulator does not have) 0.5 m.
const REAL_FRONT_M: f32 = 0.5;
const VIRTUAL_FRONT_M: f64 = 2.0;

/// With a true pose 1 m from the odometry pose, up and back (0.6, 0.8).
const GHOSTED: BenchChair =
    BenchChair { name: "bench-a", mode: SensorMode::Augmented, pose: [9.0, 4.0, 0.0], ghost: Some([8.4, 4.8, 0.0]) };
/// The same without a true pose, 5.5 m to the north.
const PLAIN: BenchChair = BenchChair { name: "bench-b", mode: SensorMode::Real, pose: [9.0, 9.5, 0.0], ghost: None };

/// A 1 m × 1 m chair (COM 0.5) with a front sensor and a right one, 30° cones, 4 m range.
fn registration(c: &BenchChair) -> RobotRegistration {
    let mut reg = RobotRegistration::new(c.name);
    reg.kind = RobotKind::Real as u32;
    reg.flags |= REG_CHAIR | REG_HAS_POSE | c.mode.reg_flags();
    reg.pose = c.pose;
    reg.sensor_count = 2;
    reg.sensors[0] = SensorSpec { x_m: 0.5, y_m: 0.0, angle_deg: 0.0, cone_deg: 30.0, range_m: 4.0 };
    reg.sensors[1] = SensorSpec { x_m: 0.0, y_m: -0.5, angle_deg: -90.0, cone_deg: 30.0, range_m: 4.0 };
    reg
}

/// What the bench reports each tick: the odometry pose, the real readings (front 0.5 m, right
/// no echo) and the true pose when it has one.
fn report(id: u32, c: &BenchChair) -> ActionBlock {
    let mut b = ActionBlock::pose(id, c.pose[0], c.pose[1], c.pose[2]);
    b.flags |= ACT_REAL;
    b.real_m = [f32::NAN; MAX_PROXIMITY];
    b.real_m[0] = REAL_FRONT_M;
    b.real_m[1] = f32::INFINITY;
    if let Some(g) = c.ghost {
        b.flags |= ACT_GHOST;
        b.ghost = g;
    }
    b
}

/// The test bench: an agent on a thread of its own (iceoryx2 ports stay on the thread that
/// made them) registering the chairs as their adapter would and reporting them every tick,
/// until the run ends or it is told to stop.
struct Bench {
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<Result<(), String>>>,
}

impl Bench {
    fn start(s: &str, chairs: &[BenchChair]) -> Self {
        let (s, chairs, stop) = (s.to_owned(), chairs.to_vec(), Arc::new(AtomicBool::new(false)));
        let flag = stop.clone();
        let handle = std::thread::spawn(move || -> Result<(), String> {
            let mut agent = Agent::connect_within(&s, "bench", Duration::from_secs(20)).map_err(|e| e.to_string())?;
            let mut ids = Vec::new();
            for c in &chairs {
                ids.push(agent.register(&registration(c)).map_err(|e| format!("{}: {e}", c.name))?);
            }
            agent.ready().map_err(|e| e.to_string())?;
            let blocks: Vec<ActionBlock> = ids.iter().zip(&chairs).map(|(&id, c)| report(id, c)).collect();
            while !flag.load(Ordering::SeqCst) {
                match agent.wait_tick(Wait::Blocking).map_err(|e| e.to_string())? {
                    Some(t) => agent.send(t.tick, &blocks).map_err(|e| e.to_string())?,
                    None => break,
                }
            }
            agent.close();
            Ok(())
        });
        Self { stop, handle: Some(handle) }
    }

    /// Waits (up to 15 s) for the bench to leave, after the run ended or it was told to stop.
    fn finish(mut self) {
        self.stop.store(true, Ordering::SeqCst);
        let handle = self.handle.take().expect("running");
        let deadline = Instant::now() + Duration::from_secs(15);
        while !handle.is_finished() {
            assert!(Instant::now() < deadline, "the bench did not leave within 15 s");
            std::thread::sleep(Duration::from_millis(5));
        }
        handle.join().expect("the bench did not panic").expect("the bench ran");
    }
}

impl Drop for Bench {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
    }
}

/// A decoded screenshot.
struct Shot {
    w: usize,
    h: usize,
    rgb: Vec<[u8; 3]>,
}

impl Shot {
    fn take(b: &mut Browser, save_as: &str) -> Self {
        let png_bytes = b.screenshot_png().expect("screenshot");
        // Kept for a human to look at when a check fails.
        let _ = std::fs::write(std::env::temp_dir().join(save_as), &png_bytes);
        let mut dec = png::Decoder::new(std::io::Cursor::new(png_bytes));
        dec.set_transformations(png::Transformations::EXPAND);
        let mut reader = dec.read_info().expect("a PNG");
        let mut buf = vec![0; reader.output_buffer_size().expect("size")];
        let info = reader.next_frame(&mut buf).expect("a frame");
        let channels = info.color_type.samples();
        let rgb =
            buf[..info.buffer_size()].chunks(channels).map(|p| [p[0], p[1 % channels], p[2 % channels]]).collect();
        Self { w: info.width as usize, h: info.height as usize, rgb }
    }

    /// The pixels in the screen rectangle (x0, y0)–(x1, y1), with their positions.
    fn pixels(&self, x0: f64, y0: f64, x1: f64, y1: f64) -> impl Iterator<Item = (f64, f64, [u8; 3])> + '_ {
        let (x0, x1) = (x0.max(0.0).round() as usize, (x1.round() as usize).min(self.w - 1));
        let (y0, y1) = (y0.max(0.0).round() as usize, (y1.round() as usize).min(self.h - 1));
        (y0..=y1).flat_map(move |y| (x0..=x1).map(move |x| (x as f64, y as f64, self.rgb[y * self.w + x])))
    }
}

fn near(got: [u8; 3], want: [u8; 3], tol: i32) -> bool {
    got.iter().zip(want).all(|(&g, w)| (g as i32 - w as i32).abs() <= tol)
}

/// The page's colours for a chair's real and virtual readings (their arcs) and its ghost.
const REAL_ARC: [u8; 3] = [0xff, 0x60, 0x00];
const VIRTUAL_ARC: [u8; 3] = [0x00, 0x40, 0xff];

/// Magenta-tinted: the ghost's fill over the floor, its outline and its drift line.
fn ghostly(p: [u8; 3]) -> bool {
    let [r, g, b] = p.map(i32::from);
    r > g + 40 && b > g + 40 && (r - b).abs() < 40
}

/// Distances (metres) from `apex` of the pixels of colour `want` in front of it: the arc of
/// one reading of the front sensor.
fn arc_distances(shot: &Shot, apex: (f64, f64), want: [u8; 3]) -> Vec<f64> {
    let (ax, ay) = px(apex.0, apex.1);
    // ±0.7 m holds a 30° cone's arc at 2 m (±0.54 m) and leaves out the other chair's
    // side cone, whose 4 m arc ends 1 m above the front sensor of the chair below it.
    shot.pixels(ax, ay - 0.7 * SCALE, ax + 2.5 * SCALE, ay + 0.7 * SCALE)
        .filter(|&(_, _, p)| near(p, want, 40))
        .map(|(x, y, _)| (x - ax).hypot(y - ay) / SCALE)
        .collect()
}

/// The share of pixels in `chair`'s ghost footprint (shrunk by 4 px), offset from its pose as
/// `GHOSTED`'s ghost is, that look like a ghost.
fn ghost_share(shot: &Shot, chair: &BenchChair) -> f64 {
    let g = GHOSTED.ghost.expect("a ghost");
    let (gx, gy) = (chair.pose[0] + g[0] - GHOSTED.pose[0], chair.pose[1] + g[1] - GHOSTED.pose[1]);
    let (x0, y0) = px(gx - 0.5, gy + 0.5);
    let (x1, y1) = px(gx + 0.5, gy - 0.5);
    let all: Vec<bool> = shot.pixels(x0 + 4.0, y0 + 4.0, x1 - 4.0, y1 - 4.0).map(|(_, _, p)| ghostly(p)).collect();
    all.iter().filter(|&&g| g).count() as f64 / all.len().max(1) as f64
}

#[test]
fn the_2d_view_shows_real_and_virtual_readings_and_the_ghost_of_a_chairs_true_pose() {
    let s = session("mixv");
    let hub = Proc::spawn(&[
        "hub",
        "--session",
        &s,
        "--lab",
        "builtin:thesis",
        "--cycle-ms",
        "20",
        "--no-noise",
        "--real",
        "bench-a",
        "--real",
        "bench-b",
    ]);
    let bench = Bench::start(&s, &[GHOSTED, PLAIN]);
    let mut view = Proc::spawn(&["view", "--session", &s, "--http", "127.0.0.1:0"]);
    // The viewer says `open http://ADDR/`; what follows the marker is the address.
    let url = format!("http://{}", view.announced("open http://", Duration::from_secs(20)));

    let mut b = Browser::launch(W, H).expect("Chromium starts (install Debian's chromium)");
    b.navigate(&url).expect("page loads");
    // Both chairs with their readings in the page's frame, their names known, and the panel
    // written from them.
    b.wait_for(
        "(() => { const f = window.iwsim.frame; return f && f.chairs.length === 2 && window.iwsim.roster.size === 2 \
         && f.chairs.every((c) => c.real[0] !== null && c.virtual[0] !== null) \
         && document.getElementById('chairs').textContent.includes('bench-b'); })()",
        Duration::from_secs(30),
    )
    .expect("the page gets both chairs");
    let chairs = b
        .eval(
            "JSON.stringify(window.iwsim.frame.chairs.map((c) => [window.iwsim.names.get(c.id), c.mode, c.ghost, c.real[0], c.real[1], c.virtual[0]]))",
        )
        .expect("chairs");
    let chairs: serde_json::Value = serde_json::from_str(chairs.as_str().expect("a string")).expect("JSON");
    for (c, want) in chairs.as_array().expect("an array").iter().zip([&GHOSTED, &PLAIN]) {
        assert_eq!(c[0], want.name, "{chairs}");
        assert_eq!(c[1], ["virtual", "real", "augmented"][want.mode as usize], "{chairs}");
        match want.ghost {
            Some(g) => {
                let got: Vec<f64> =
                    c[2].as_array().expect("a ghost").iter().map(|v| v.as_f64().expect("number")).collect();
                assert!(got.iter().zip(g).all(|(a, b)| (a - b).abs() < 1e-5), "{chairs}");
            }
            None => assert!(c[2].is_null(), "{chairs}"),
        }
        assert_eq!(c[3].as_f64(), Some(REAL_FRONT_M as f64), "real front reading: {chairs}");
        assert!(c[4].is_null(), "no echo draws nothing: {chairs}");
        let virt = c[5].as_f64().expect("a virtual reading");
        assert!((virt - VIRTUAL_FRONT_M).abs() < 0.01, "virtual front reading {virt}: {chairs}");
    }
    let panel = b.eval("document.getElementById('chairs').textContent").expect("panel");
    let panel = panel.as_str().unwrap_or_default();
    assert!(panel.contains("bench-a · augmented · drift 1.00 m"), "{panel}");
    assert!(panel.contains("bench-b · real · no true pose"), "{panel}");
    assert!(panel.contains("real") && panel.contains("virtual") && panel.contains("true pose"), "legend: {panel}");

    // A few more draws, so the screenshot shows the frame just checked.
    let draws = b.eval("window.iwsim.draws").expect("draws").as_u64().expect("a number");
    b.wait_for(&format!("window.iwsim.draws > {draws} + 3"), Duration::from_secs(10)).expect("the page draws");
    let shot = Shot::take(&mut b, "iwsim-e2e-mixed-2d.png");

    for c in [&GHOSTED, &PLAIN] {
        let apex = (c.pose[0] + 0.5, c.pose[1]);
        // Each reading's arc in its own colour, at its own distance from the sensor.
        for (what, colour, want) in [("real", REAL_ARC, REAL_FRONT_M as f64), ("virtual", VIRTUAL_ARC, VIRTUAL_FRONT_M)]
        {
            let d = arc_distances(&shot, apex, colour);
            assert!(d.len() >= 8, "{}: only {} {what} pixels ahead", c.name, d.len());
            let off = d.iter().map(|d| (d - want).abs()).fold(0.0, f64::max);
            assert!(off < 4.0 / SCALE, "{}: a {what} pixel {off:.3} m off the {want} m arc", c.name);
        }
    }
    // The ghost where the true pose is; nothing like it beside the chair without one.
    let with = ghost_share(&shot, &GHOSTED);
    let without = ghost_share(&shot, &PLAIN);
    assert!(with > 0.6, "the ghost covers only {:.0}% of its footprint", with * 100.0);
    assert!(without < 0.01, "{:.1}% ghost-coloured where no true pose was sent", without * 100.0);

    drop(b);
    assert_eq!(agent_sdk::control(&s, ipc_types::Command::Stop, 0).expect("hub answers").status, 0);
    bench.finish();
    for p in [hub, view] {
        let out = p.wait(Duration::from_secs(15));
        assert!(out.status.success(), "{}", text(&out.stderr));
    }
    assert_no_shared_memory_left(&s);
}

#[test]
fn the_pages_decoder_reads_the_chairs_the_viewer_encodes() {
    // The page's own JavaScript, run by node on a frame made here with one chair.
    let h = ipc_types::WorldHeader { tick: 5, robot_count: 1, ..Default::default() };
    let robot = ipc_types::RobotState {
        id: 3,
        kind: RobotKind::Real as u32,
        flags: 0,
        collision_count: 0,
        x_m: 9.0,
        y_m: 4.0,
        heading_deg: 0.0,
        width_m: 1.0,
        height_m: 1.0,
        com: 0.5,
        agent_id: 1,
        motor_out: [0.0; 2],
        proximity_m: [0.5; MAX_PROXIMITY],
        standing: Default::default(),
    };
    let mut real_m = [f32::NAN; MAX_PROXIMITY];
    (real_m[0], real_m[1]) = (0.5, f32::INFINITY);
    let mut virtual_m = [f32::NAN; MAX_PROXIMITY];
    (virtual_m[0], virtual_m[1]) = (2.0, 3.5);
    let chair = ChairState {
        robot_id: 3,
        sensor_mode: SensorMode::Augmented as u32,
        flags: ipc_types::CHAIR_GHOST | ipc_types::CHAIR_LINK_UP,
        controller: 0,
        ghost: [8.4, 4.8, 90.0],
        real_m,
        virtual_m,
    };
    let bytes = frame::encode_with_chairs(&h, &[robot], &[chair]);
    let bin = std::env::temp_dir().join(format!("iwsim-mixed-frame-{}.bin", std::process::id()));
    std::fs::write(&bin, &bytes).expect("write");
    let script = format!(
        "const {{decodeFrame, drift, ghostOf}} = require({:?}); const b = require('fs').readFileSync({:?}); \
         const f = decodeFrame(b.buffer.slice(b.byteOffset, b.byteOffset + b.length)); \
         const c = f.chairs[0], r = f.robots[0], g = ghostOf(r, c); \
         console.log(JSON.stringify([f.robots.length, f.chairs.length, c.id, c.mode, c.flags, c.real.slice(0, 3), c.virtual.slice(0, 3), \
           Math.round(drift(r, c) * 1000), [g.x, g.y, g.heading, g.width].map((v) => Math.round(v * 1000)), drift(r, null)]));",
        concat!(env!("CARGO_MANIFEST_DIR"), "/viewer/static/app.js"),
        bin.to_str().expect("utf-8")
    );
    let out = std::process::Command::new("node").arg("-e").arg(script).output().expect("node runs");
    let _ = std::fs::remove_file(&bin);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let got: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let want = serde_json::json!([
        1,
        1,
        3,
        "augmented",
        6,
        [0.5, null, null],
        [2, 3.5, null],
        1000,
        [8400, 4800, 90000, 1000],
        null
    ]);
    assert_eq!(got, want);
}
