//! The viewer's page in a real headless Chromium (Debian's `chromium`), driven over the
//! DevTools protocol: screenshots are decoded and checked pixel by pixel at the positions the
//! hub's world projects to, and the page's own buttons are clicked.

use std::net::SocketAddr;
use std::time::Duration;

use bench_harness::browser::Browser;

use super::common::{Proc, session, text};

const W: u32 = 1200;
const H: u32 = 600;

/// The scenario every test here shows: the LIACC floor, checkpoint 1 and the thesis's
/// obstacle A, and one 1 × 1 m chair at checkpoint 1 facing down the corridor (+x).
const OBSTACLE_A: [f64; 4] = [17.0, 6.1, 17.6, 6.4];
const CHAIR: [f64; 3] = [10.0, 6.1, 0.0];

struct Run {
    s: String,
    procs: Vec<Proc>,
    addr: SocketAddr,
}

impl Run {
    /// A hub (held before tick 0 unless `running`, so poses stay exactly as registered), one
    /// chair, and the viewer.
    fn start(tag: &str, running: bool, view_args: &[&str]) -> Self {
        let s = session(tag);
        let obstacle = format!("{},{},{},{}", OBSTACLE_A[0], OBSTACLE_A[1], OBSTACLE_A[2], OBSTACLE_A[3]);
        let mut hub_args = vec![
            "hub",
            "--session",
            &s,
            "--cycle-ms",
            "20",
            "--no-noise",
            "--obstacle",
            &obstacle,
            "--checkpoint",
            "10,6.1",
        ];
        if !running {
            hub_args.push("--start-on-command");
        }
        let hub = Proc::spawn(&hub_args);
        let pose = format!("{},{},{}", CHAIR[0], CHAIR[1], CHAIR[2]);
        let agent = Proc::spawn(&[
            "agent",
            "wheelchair",
            "--session",
            &s,
            "--robots",
            "1",
            "--pose",
            &pose,
            "--powers",
            "0.1,0.1",
        ]);
        let mut args = vec!["view", "--session", &s, "--http", "127.0.0.1:0"];
        args.extend_from_slice(view_args);
        let mut view = Proc::spawn(&args);
        let url = view.announced("open http://", Duration::from_secs(20));
        let addr = url.trim_end_matches('/').parse().expect("address");
        Self { s, procs: vec![hub, agent, view], addr }
    }

    fn url(&self, query: &str) -> String {
        format!("http://{}/{query}", self.addr)
    }

    fn stop(self) {
        assert_eq!(agent_sdk::control(&self.s, ipc_types::Command::Stop, 0).expect("hub answers").status, 0);
        for p in self.procs {
            let out = p.wait(Duration::from_secs(15));
            assert!(out.status.success(), "{}", text(&out.stderr));
        }
        let prefix = format!("iwsim_{}_", self.s);
        let left: Vec<String> = std::fs::read_dir("/dev/shm")
            .expect("/dev/shm")
            .filter_map(Result::ok)
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with(&prefix))
            .collect();
        assert!(left.is_empty(), "left in /dev/shm: {left:?}");
    }
}

/// A decoded screenshot.
struct Shot {
    w: usize,
    h: usize,
    rgba: Vec<u8>,
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
        let rgba = buf[..info.buffer_size()]
            .chunks(channels)
            .flat_map(|p| [p[0], p[1 % channels], p[2 % channels], 255])
            .collect();
        Self { w: info.width as usize, h: info.height as usize, rgba }
    }

    fn at(&self, x: f64, y: f64) -> [u8; 3] {
        let (x, y) = (x.round() as usize, y.round() as usize);
        assert!(x < self.w && y < self.h, "({x}, {y}) is off the {}x{} screenshot", self.w, self.h);
        let o = 4 * (y * self.w + x);
        [self.rgba[o], self.rgba[o + 1], self.rgba[o + 2]]
    }

    fn distinct_colours(&self) -> usize {
        let mut set: Vec<u32> = self.rgba.chunks(4).map(|p| u32::from_le_bytes([p[0], p[1], p[2], 0])).collect();
        set.sort_unstable();
        set.dedup();
        set.len()
    }
}

fn near(got: [u8; 3], want: [u8; 3], tol: i32) -> bool {
    got.iter().zip(want).all(|(&g, w)| (g as i32 - w as i32).abs() <= tol)
}

const WALL: [u8; 3] = [0x20, 0x40, 0x7a];
const OBSTACLE: [u8; 3] = [0xd0, 0x70, 0x20];
const CHAIR_GREEN: [u8; 3] = [0x20, 0xa0, 0x40];
const OUTSIDE: [u8; 3] = [0xf4, 0xf4, 0xf0];

#[test]
fn the_2d_view_draws_the_walls_obstacles_and_chair_where_the_world_has_them() {
    let run = Run::start("br2d", false, &[]);
    let mut b = Browser::launch(W, H).expect("Chromium starts (install Debian's chromium)");
    b.navigate(&run.url("")).expect("page loads");
    b.wait_for(
        "window.iwsim.map && window.iwsim.frame && window.iwsim.frame.robots.length === 1 && window.iwsim.draws > 3",
        Duration::from_secs(20),
    )
    .expect("the page gets the map and the chair");
    let shot = Shot::take(&mut b, "iwsim-e2e-2d.png");

    // The page fits the lab with a metre of margin and y up; project exactly as it must.
    let map = world::map::builtin::map("liacc").expect("built-in map");
    let (lw, lh) = (map.lab.width_m, map.lab.height_m);
    let scale = (W as f64 / (lw + 2.0)).min(H as f64 / (lh + 2.0));
    let (ox, oy) = ((W as f64 - lw * scale) / 2.0, (H as f64 + lh * scale) / 2.0);
    let px = |x: f64, y: f64| (ox + x * scale, oy - y * scale);

    // Every wall thick enough to hold a pixel is wall-blue at its centre (skipping the
    // overlay panels along the top and bottom edges).
    let mut checked = 0;
    for w in &map.lab.walls {
        let (xs, ys): (Vec<f64>, Vec<f64>) = w.corners.iter().map(|c| (c.x, c.y)).unzip();
        let (x0, x1) = (xs.iter().copied().fold(f64::MAX, f64::min), xs.iter().copied().fold(f64::MIN, f64::max));
        let (y0, y1) = (ys.iter().copied().fold(f64::MAX, f64::min), ys.iter().copied().fold(f64::MIN, f64::max));
        if w.corners.len() != 4 || (x1 - x0).min(y1 - y0) * scale < 4.0 {
            continue;
        }
        let (sx, sy) = px((x0 + x1) / 2.0, (y0 + y1) / 2.0);
        if !(70.0..H as f64 - 50.0).contains(&sy) {
            continue;
        }
        let got = shot.at(sx, sy);
        assert!(near(got, WALL, 10), "wall centre ({sx:.0},{sy:.0}) is {got:?}, want {WALL:?}");
        checked += 1;
    }
    assert!(checked >= 5, "only {checked} walls checked");
    let (sx, sy) = px((OBSTACLE_A[0] + OBSTACLE_A[2]) / 2.0, (OBSTACLE_A[1] + OBSTACLE_A[3]) / 2.0);
    assert!(near(shot.at(sx, sy), OBSTACLE, 10), "obstacle A is {:?}", shot.at(sx, sy));
    // The chair spans x 9.5–10.5, y 5.6–6.6 (COM 0.5); its quarters are green, the floor a
    // metre behind it is not.
    for (dx, dy) in [(-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.3)] {
        let (sx, sy) = px(CHAIR[0] + dx, CHAIR[1] + dy);
        assert!(near(shot.at(sx, sy), CHAIR_GREEN, 10), "chair at ({sx:.0},{sy:.0}) is {:?}", shot.at(sx, sy));
    }
    let (sx, sy) = px(CHAIR[0] - 1.5, CHAIR[1]);
    assert!(!near(shot.at(sx, sy), CHAIR_GREEN, 40), "no chair behind it");
    // Outside the lab is the page's background.
    assert!(near(shot.at(ox / 2.0, H as f64 / 2.0), OUTSIDE, 3), "{:?}", shot.at(ox / 2.0, H as f64 / 2.0));
    // Its front cone (60°, reading to the obstacle ahead or the corridor's end) is drawn: a
    // point half a metre ahead of the front edge is tinted, not plain floor.
    let (sx, sy) = px(CHAIR[0] + 1.0, CHAIR[1]);
    let cone = shot.at(sx, sy);
    assert!(cone[2] < 230 && cone[0] > 200, "front cone at ({sx:.0},{sy:.0}) is {cone:?}");
    drop(b);
    run.stop();
}

#[test]
fn the_3d_first_person_view_looks_down_the_corridor_at_obstacle_a() {
    let run = Run::start("br3d", false, &[]);
    let mut b = Browser::launch(W, H).expect("Chromium starts");
    b.navigate(&run.url("?view=3d&camera=first&chair=1")).expect("page loads");
    b.wait_for(
        "window.iwsim.view3d && window.iwsim.map && window.iwsim.frame && window.iwsim.frame.robots.length === 1 && window.iwsim.draws > 5",
        Duration::from_secs(30),
    )
    .expect("the 3D view renders");
    let shot = Shot::take(&mut b, "iwsim-e2e-3d-first.png");
    assert!(shot.distinct_colours() > 200, "a 3D scene, not a blank canvas: {} colours", shot.distinct_colours());

    // The camera: eye 1.2 m up at the chair's front edge (x 10.5), level, 75° vertical field
    // of view. Obstacle A's near face is 6.5 m ahead, from the centre line to 0.3 m left,
    // from the floor to 1.0 m: project its middle.
    let f = (H as f64 / 2.0) / (75f64.to_radians() / 2.0).tan();
    let (d, left, up) = (OBSTACLE_A[0] - (CHAIR[0] + 0.5), 0.15, 0.5 - 1.2);
    let (sx, sy) = (W as f64 / 2.0 - f * left / d, H as f64 / 2.0 - f * up / d);
    // Lit, so only the hue is fixed: strongly orange.
    let orange = |p: [u8; 3]| p[0] > 120 && p[0] as i32 - p[2] as i32 > 60;
    let got = shot.at(sx, sy);
    assert!(orange(got), "obstacle A at ({sx:.0},{sy:.0}) is {got:?}");
    // Down that column the orange runs from the top face's far edge (1.0 m, 7.1 m ahead) to
    // the near face's foot on the floor (6.5 m ahead), to within a few pixels.
    let rows: Vec<usize> = (0..shot.h).filter(|&y| orange(shot.at(sx, y as f64))).collect();
    let (top, bottom) = (H as f64 / 2.0 + f * 0.2 / (d + 0.6), H as f64 / 2.0 + f * 1.2 / d);
    let (first, last) = (rows[0] as f64, rows[rows.len() - 1] as f64);
    assert!(
        (first - top).abs() <= 3.0 && (last - bottom).abs() <= 3.0,
        "obstacle rows {first}..{last}, projected {top:.1}..{bottom:.1}"
    );
    // The corridor walls (y 5.5 and 6.7 around a chair at y 6.1) fill both sides at eye
    // level, blue; the floor fills the bottom middle, light.
    for x in [10.0, W as f64 - 10.0] {
        let got = shot.at(x, H as f64 / 2.0);
        assert!(got[2] as i32 - got[0] as i32 > 40, "side wall at ({x}, {}) is {got:?}", H / 2);
    }
    let floor = shot.at(W as f64 / 2.0, H as f64 - 60.0);
    assert!(floor.iter().all(|&c| c > 170), "floor is {floor:?}");
    drop(b);
    run.stop();
}

#[test]
fn the_pages_pause_button_pauses_the_run_only_with_allow_control() {
    for allow in [false, true] {
        let run = Run::start("brctl", true, if allow { &["--allow-control"] } else { &[] });
        let mut b = Browser::launch(W, H).expect("Chromium starts");
        b.navigate(&run.url("")).expect("page loads");
        b.wait_for("window.iwsim.frame && window.iwsim.frame.runState === 1", Duration::from_secs(20))
            .expect("running");
        b.click("button[data-cmd=pause]").expect("click");
        let said = b
            .wait_for("document.getElementById('status').textContent", Duration::from_secs(10))
            .expect("the page reports the answer");
        let said = said.as_str().unwrap_or_default().to_owned();
        if allow {
            assert_eq!(said, "pause: done");
            b.wait_for("window.iwsim.frame.runState === 2", Duration::from_secs(10)).expect("the run pauses");
            let t0 = b.eval("window.iwsim.frame.tick").expect("tick");
            // While paused, Step moves the run one tick.
            b.click("button[data-cmd=step]").expect("click");
            b.wait_for(&format!("window.iwsim.frame.tick === {t0} + 1"), Duration::from_secs(10)).expect("one step");
        } else {
            assert!(said.contains("control is off"), "{said}");
            let t0 = b.eval("window.iwsim.frame.tick").expect("tick").as_u64().expect("a number");
            // The run goes on: 20 more ticks, still running.
            b.wait_for(&format!("window.iwsim.frame.tick > {t0} + 20"), Duration::from_secs(10))
                .expect("the run goes on");
            assert_eq!(b.eval("window.iwsim.frame.runState").expect("state"), 1);
        }
        drop(b);
        run.stop();
    }
}
