//! `iwsim agent teleop` driven as a person would: its stdin, stdout and stderr are the slave
//! side of a real pseudo-terminal (its controlling terminal), keys are written to the master,
//! the screen is read back from the master, and the chair's motion is read from the hub's world
//! through an SDK observer.

use std::io::{Read as _, Write as _};
use std::process::Command;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use ::teleop::term::local_modes;
use ::teleop::view::TERMINAL_SIZE;
use agent_sdk::control;
use ipc_types::{Command as Cmd, RobotState, WorldHeader};
use observer::Observer;
use os::pty::Pty;

use super::common::{Proc, assert_no_shared_memory_left, robot_named, session, text};

/// Everything the teleop has written to its terminal, collected by a thread draining the
/// master (a pseudo-terminal whose master is not read blocks its writer once full).
struct Terminal {
    bytes: Arc<Mutex<Vec<u8>>>,
}

impl Terminal {
    fn read(pty: &Pty) -> Self {
        let mut master = pty.master().expect("master");
        let bytes = Arc::new(Mutex::new(Vec::new()));
        let sink = Arc::clone(&bytes);
        // Ends when every slave descriptor is closed (the read fails with EIO).
        std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            while let Ok(n @ 1..) = master.read(&mut buf) {
                sink.lock().expect("not poisoned").extend_from_slice(&buf[..n]);
            }
        });
        Self { bytes }
    }

    fn text(&self) -> String {
        text(&self.bytes.lock().expect("not poisoned"))
    }

    /// The last frame: what follows the last cursor-home sequence.
    fn last_frame(&self) -> String {
        let all = self.text();
        all.rsplit("\x1b[H").next().unwrap_or_default().to_owned()
    }

    /// Waits until the last frame satisfies `ok`; returns it.
    fn wait_for(&self, what: &str, timeout: Duration, ok: impl Fn(&str) -> bool) -> String {
        let start = Instant::now();
        loop {
            let frame = self.last_frame();
            if ok(&frame) {
                return frame;
            }
            assert!(start.elapsed() < timeout, "the screen never showed {what} within {timeout:?}:\n{frame}");
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

/// The first proximity reading shown on a frame, if the frame has one.
fn first_proximity(frame: &str) -> Option<f64> {
    let line = frame.lines().find(|l| l.trim_start().starts_with("prox 0 "))?;
    line.trim_start().strip_prefix("prox 0")?.split_whitespace().next()?.parse().ok()
}

/// The hub's world as an observer sees it, kept up to date while waiting.
struct World {
    observer: Observer,
    latest: Option<(WorldHeader, Vec<RobotState>)>,
}

impl World {
    /// Waits until the chair named `chair1` satisfies `ok`; returns the tick and its state.
    fn wait_chair(
        &mut self,
        what: &str,
        timeout: Duration,
        ok: impl Fn(&WorldHeader, &RobotState) -> bool,
    ) -> (WorldHeader, RobotState) {
        let start = Instant::now();
        loop {
            if let Some(w) = self.observer.try_world().expect("world snapshot") {
                self.latest = Some(w);
            }
            let observer = &mut self.observer;
            let chair =
                self.latest.as_ref().and_then(|(h, robots)| robot_named(observer, robots, "chair1").map(|r| (*h, r)));
            if let Some((h, r)) = chair
                && ok(&h, &r)
            {
                return (h, r);
            }
            assert!(start.elapsed() < timeout, "{what} did not happen within {timeout:?}; last chair state {chair:?}");
            std::thread::sleep(Duration::from_millis(2));
        }
    }
}

#[test]
fn teleop_drives_a_chair_from_a_pseudo_terminal_and_restores_the_terminal_on_quit() {
    let s = session("teleop");
    let hub = Proc::spawn(&["hub", "--session", &s, "--cycle-ms", "20", "--no-noise"]);

    let pty = Pty::open(Some(TERMINAL_SIZE)).expect("a pseudo-terminal");
    let teleop = spawn_teleop(&s, &pty);
    let screen = Terminal::read(&pty);
    let mut master = pty.master().expect("master");
    let mut press = |keys: &[u8]| master.write_all(keys).expect("keys reach the terminal");

    let mut world = World {
        observer: Observer::connect_within(&s, "teleop-observer", Duration::from_secs(20)).expect("hub comes up"),
        latest: None,
    };
    let (_, start) = world.wait_chair("the chair's arrival", Duration::from_secs(20), |_, _| true);
    assert_eq!((start.x_m, start.y_m, start.heading_deg), (10.0, 6.1, 0.0));

    // The screen shows the sensor readings, and the terminal is in raw mode while it runs.
    let frame = screen.wait_for("a proximity reading", Duration::from_secs(20), |f| {
        f.contains("proximity (4 sensors") && first_proximity(f).is_some_and(|d| d > 0.0 && d <= 3.0)
    });
    assert!(frame.contains("encoders") && frame.contains("space stop"), "{frame}");
    let raw = local_modes(pty.slave()).expect("termios");
    assert!(!raw.canonical && !raw.echo, "the teleop switched its terminal to raw input: {raw:?}");

    // Five Up presses as `w`: half power forward, +x.
    press(b"wwwww");
    world.wait_chair("driving 0.3 m forward", Duration::from_secs(20), |_, r| r.x_m > start.x_m + 0.3);
    screen.wait_for("the speed", Duration::from_secs(5), |f| f.contains("speed +0.50"));

    // Space stops it: once the motor filter has settled, x stays put for 10 ticks and more.
    press(b" ");
    let (settled, at) = world.wait_chair("the motors settling", Duration::from_secs(20), |_, r| {
        r.motor_out[0].abs() < 1e-3 && r.motor_out[1].abs() < 1e-3
    });
    let (_, later) = world.wait_chair("ten more ticks", Duration::from_secs(20), |h, _| h.tick >= settled.tick + 10);
    assert!((later.x_m - at.x_m).abs() < 1e-3, "the chair crept from x {} to {}", at.x_m, later.x_m);
    assert!(later.x_m > start.x_m + 0.3);

    // Left arrows, in both encodings (normal and application cursor mode): a turn to the left
    // on the spot, so the heading grows.
    press(b"\x1b[D\x1bOD");
    press(b"\x1b[");
    press(b"D");
    let frame = screen.wait_for("three left steps", Duration::from_secs(5), |f| f.contains("turn +0.30"));
    assert!(frame.contains("power left -0.30 right +0.30"), "{frame}");
    world.wait_chair("a turn to the left", Duration::from_secs(20), |_, r| r.heading_deg > at.heading_deg + 10.0);

    // `q` leaves cleanly and gives the terminal back in its original mode.
    press(b"q");
    let out = teleop.wait(Duration::from_secs(10));
    assert!(out.status.success(), "teleop failed: {:?}\n{}", out.status, screen.text());
    let restored = local_modes(pty.slave()).expect("termios");
    assert!(restored.canonical && restored.echo, "terminal left in raw mode: {restored:?}");
    let all = screen.text();
    assert!(all.contains("left by the driver"), "{all}");
    assert!(all.contains("\x1b[?25h"), "the cursor is shown again");

    world.observer.close();
    assert_eq!(control(&s, Cmd::Stop, 0).expect("hub answers").status, 0);
    let out = hub.wait(Duration::from_secs(10));
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_no_shared_memory_left(&s);
}

#[test]
fn teleop_exits_with_a_message_and_a_restored_terminal_when_its_hub_is_killed() {
    let s = session("teleop-hub-dies");
    let mut hub = Proc::spawn(&["hub", "--session", &s, "--cycle-ms", "20"]);
    let pty = Pty::open(Some(TERMINAL_SIZE)).expect("a pseudo-terminal");
    let teleop = spawn_teleop(&s, &pty);
    let screen = Terminal::read(&pty);
    screen.wait_for("a running tick", Duration::from_secs(20), |f| f.contains("run running"));
    assert!(!local_modes(pty.slave()).expect("termios").canonical, "raw while running");

    hub.kill9();
    let out = teleop.wait(Duration::from_secs(10));
    assert!(!out.status.success(), "a lost hub is an error");
    // The process has exited, but the reader thread may still be draining the pty.
    let deadline = Instant::now() + Duration::from_secs(10);
    let all = loop {
        let all = screen.text();
        if (all.contains("lost its hub") && all.contains("has exited")) || Instant::now() > deadline {
            break all;
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    assert!(all.contains("lost its hub") && all.contains("has exited"), "{all}");
    let restored = local_modes(pty.slave()).expect("termios");
    assert!(restored.canonical && restored.echo, "terminal left in raw mode: {restored:?}");

    // A killed hub leaves its files; a new hub in the session clears them and removes its own.
    let again = Proc::spawn(&["hub", "--session", &s, "--cycle-ms", "5", "--ticks", "2"]);
    assert!(again.wait(Duration::from_secs(20)).status.success());
    assert_no_shared_memory_left(&s);
}

/// Starts `iwsim agent teleop` in session `s` on the slave side of `pty`, as its controlling
/// terminal.
fn spawn_teleop(s: &str, pty: &Pty) -> Proc {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_iwsim"));
    cmd.args(["agent", "teleop", "--session", s, "--pose", "10,6.1,0", "--connect-timeout", "20"])
        .env("RUST_LOG", "warn");
    pty.attach(&mut cmd).expect("stdio on the slave");
    Proc(Some(cmd.spawn().expect("iwsim starts")))
}
