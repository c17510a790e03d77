//! What the driver sees: a status block for a terminal, or one line for a log or pipe. Pure
//! text building; [`Screen`] adds the few plain ANSI sequences a terminal needs (cursor home,
//! clear to end of line), which every terminal and tmux understand without terminfo.

use std::fmt::Write as _;

use agent_sdk::Tick;
use ipc_types::{COLLISION, HAS_COMPASS, HAS_GPS, RunState, SensorBlock};

use crate::drive::Drive;

/// Rows and columns of the classic terminal the display is made to fit (and tests drive it
/// in).
pub const TERMINAL_SIZE: (u16, u16) = (24, 80);

/// Proximity bars are drawn against this distance (the hub's default sensor range).
pub const BAR_RANGE_M: f64 = 3.0;
/// Characters in a full proximity bar.
const BAR_WIDTH: usize = 20;

/// The key help, as shown under the status block.
pub const KEY_HELP: [&str; 2] = [
    "keys: Up/w faster  Down/s slower/reverse  Left/a Right/d steer",
    "      space stop  +/- step size  r resume after a stop  q or Ctrl-C quit",
];

/// Everything the display shows.
#[derive(Debug, Clone, Copy)]
pub struct Status<'a> {
    /// The robot's name.
    pub name: &'a str,
    /// The robot's id.
    pub robot_id: u32,
    /// The session.
    pub session: &'a str,
    /// The last tick, if one has come.
    pub tick: Option<Tick>,
    /// The robot's sensor block of that tick.
    pub block: Option<&'a SensorBlock>,
    /// The driver's command.
    pub drive: &'a Drive,
    /// What the last resume request (`r`) came to, if one was made.
    pub notice: Option<&'a str>,
}

fn run_state(s: RunState) -> &'static str {
    match s {
        RunState::Waiting => "waiting to start",
        RunState::Running => "running",
        RunState::Paused => "paused",
        RunState::Finished => "finished",
    }
}

/// A bar of `#` as long as the free distance `d` is, against [`BAR_RANGE_M`]; empty for a
/// missing (NaN) reading.
pub fn bar(d: f64) -> String {
    let filled = if d.is_nan() { 0 } else { ((d / BAR_RANGE_M).clamp(0.0, 1.0) * BAR_WIDTH as f64).round() as usize };
    format!("[{}{}]", "#".repeat(filled), ".".repeat(BAR_WIDTH - filled))
}

/// A right-aligned number, or a dash for a missing (NaN) reading.
fn num(v: f64, width: usize, decimals: usize) -> String {
    if v.is_finite() { format!("{v:>width$.decimals$}") } else { format!("{:>width$}", "-") }
}

/// The lines of the status block (no escape sequences, each under 80 columns).
pub fn screen_lines(s: &Status) -> Vec<String> {
    let mut lines = Vec::with_capacity(20);
    lines.push(format!("iwsim teleop: {} (robot {}) in session {}", s.name, s.robot_id, s.session));
    lines.push(match s.tick {
        Some(t) => format!("tick {:<8} time {:>9.2} s   run {}", t.tick, t.sim_time_s, run_state(t.run_state)),
        None => "waiting for the first tick".to_owned(),
    });
    let d = s.drive;
    let [l, r] = d.powers();
    lines.push(format!(
        "speed {:+.2}  turn {:+.2}  step {:.2}   power left {:+.2} right {:+.2}",
        d.speed(),
        d.turn(),
        d.step(),
        l,
        r
    ));
    match s.block {
        None => lines.push("no sensor readings yet".to_owned()),
        Some(b) => {
            // What the chair's own sensors say; where it truly is, the viewer shows.
            lines.push(format!("encoders left {:>10} right {:>10} ticks", b.encoder_ticks[0], b.encoder_ticks[1]));
            lines.push(if b.present & HAS_GPS != 0 {
                format!(
                    "gps      x {} m  y {} m  heading {} deg",
                    num(b.gps_x_m, 8, 3),
                    num(b.gps_y_m, 8, 3),
                    num(b.gps_heading_deg, 7, 1)
                )
            } else {
                "gps      off".to_owned()
            });
            lines.push(if b.present & HAS_COMPASS != 0 {
                format!("compass  {} deg", num(b.compass_deg, 7, 1))
            } else {
                "compass  off".to_owned()
            });
            let n = (b.proximity_count as usize).min(b.proximity_m.len());
            lines.push(format!("proximity ({n} sensors, metres; bar = free space up to {BAR_RANGE_M} m)"));
            for (k, &p) in b.proximity_m[..n].iter().enumerate() {
                lines.push(format!("  prox {k}  {} m  {}", num(p, 6, 3), bar(p)));
            }
            let hit = b.present & COLLISION != 0;
            lines.push(format!(
                "collision {}   contacts {}   encoders {} {}",
                if hit { "YES" } else { "no" },
                b.collision_count,
                b.encoder_ticks[0],
                b.encoder_ticks[1]
            ));
        }
    }
    if let Some(n) = s.notice {
        lines.push(n.to_owned());
    }
    lines.extend(KEY_HELP.iter().map(|s| s.to_string()));
    lines
}

/// The status as one line, for output that is not a terminal.
pub fn status_line(s: &Status) -> String {
    let mut line = match s.tick {
        Some(t) => format!("tick {} t {:.2}s {}", t.tick, t.sim_time_s, run_state(t.run_state)),
        None => "no tick yet".to_owned(),
    };
    let [l, r] = s.drive.powers();
    let _ = write!(line, " | speed {:+.2} turn {:+.2} power {:+.2} {:+.2}", s.drive.speed(), s.drive.turn(), l, r);
    if let Some(b) = s.block {
        let _ = write!(line, " | encoders {} {}", b.encoder_ticks[0], b.encoder_ticks[1]);
        if b.present & HAS_GPS != 0 {
            let _ = write!(line, " | gps {:.3} {:.3}", b.gps_x_m, b.gps_y_m);
        }
        if b.present & HAS_COMPASS != 0 {
            let _ = write!(line, " | compass {:.1}", b.compass_deg);
        }
        let n = (b.proximity_count as usize).min(b.proximity_m.len());
        line += " | proximity";
        for &p in &b.proximity_m[..n] {
            let _ = write!(line, " {p:.3}");
        }
        let _ = write!(
            line,
            " | collision {} contacts {}",
            if b.present & COLLISION != 0 { "yes" } else { "no" },
            b.collision_count
        );
    }
    if let Some(n) = s.notice {
        let _ = write!(line, " | {n}");
    }
    line
}

/// The status block drawn in place on a terminal.
#[derive(Debug, Default)]
pub struct Screen {
    drawn: bool,
}

/// Cursor to the top-left corner.
const HOME: &str = "\x1b[H";
/// Clear the whole screen.
const CLEAR: &str = "\x1b[2J";
/// Clear from the cursor to the end of the line.
const CLEAR_LINE: &str = "\x1b[K";
/// Clear from the cursor to the end of the screen.
const CLEAR_BELOW: &str = "\x1b[J";
/// Hide and show the cursor (it would flicker over the block).
const HIDE_CURSOR: &str = "\x1b[?25l";
const SHOW_CURSOR: &str = "\x1b[?25h";

impl Screen {
    /// The bytes that draw `lines` over the previous frame. The first frame clears the screen;
    /// later ones overwrite in place, clearing each line's tail, so nothing flickers and a
    /// stray log line is painted over. Lines end in `\r\n`, right whether or not the terminal
    /// translates newlines.
    pub fn frame(&mut self, lines: &[String]) -> String {
        let mut out = String::with_capacity(2048);
        if !self.drawn {
            out += HIDE_CURSOR;
            out += CLEAR;
            self.drawn = true;
        }
        out += HOME;
        for l in lines {
            out += l;
            out += CLEAR_LINE;
            out += "\r\n";
        }
        out += CLEAR_BELOW;
        out
    }

    /// The bytes that leave the terminal usable: the cursor shown again, below the block.
    pub fn finish(&mut self) -> &'static str {
        if std::mem::take(&mut self.drawn) { SHOW_CURSOR } else { "" }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::keys::Key;
    use ipc_types::{InboxEntry, MAX_BEACONS, MAX_INBOX_MESSAGES};

    fn block() -> SensorBlock {
        SensorBlock {
            tick: 42,
            robot_id: 3,
            present: HAS_COMPASS | COLLISION,
            proximity_m: [0.75, 3.0, 1.5, f64::NAN, 0.0, 0.0, 0.0, 0.0],
            compass_deg: 12.0,
            gps_x_m: 0.0,
            gps_y_m: 0.0,
            gps_heading_deg: 0.0,
            beacons_deg: [0.0; MAX_BEACONS],
            encoder_ticks: [1520, -37],
            collision_count: 2,
            ground: 0,
            proximity_count: 4,
            beacon_count: 0,
            inbox_count: 0,
            inbox_dropped: 0,
            inbox: [InboxEntry { from_id: 0, offset: 0, len: 0 }; MAX_INBOX_MESSAGES],
            inbox_bytes: [0; ipc_types::INBOX_BYTES],
            drive: [0.0; 2],
            drive_flags: 0,
            sensor_mode: 0,
            line_bits: 0,
            _reserved: 0,
            standing: Default::default(),
        }
    }

    fn status<'a>(b: Option<&'a SensorBlock>, d: &'a Drive) -> Status<'a> {
        Status {
            name: "chair1",
            robot_id: 3,
            session: "demo",
            tick: Some(Tick {
                tick: 42,
                sim_time_s: 4.2,
                run_state: RunState::Running,
                latency_ns: 0,
                lockstep: false,
            }),
            block: b,
            drive: d,
            notice: None,
        }
    }

    #[test]
    fn the_block_shows_every_reading_and_the_keys() {
        let b = block();
        let mut d = Drive::new();
        d.apply(Key::Faster);
        d.apply(Key::Left);
        let lines = screen_lines(&status(Some(&b), &d));
        let text = lines.join("\n");
        for want in [
            "chair1 (robot 3)",
            "tick 42",
            "running",
            "speed +0.10  turn +0.10",
            "power left +0.00 right +0.20",
            "encoders left       1520 right        -37 ticks",
            "gps      off",
            "compass     12.0 deg",
            "proximity (4 sensors",
            "prox 0   0.750 m  [#####...............]",
            "prox 1   3.000 m  [####################]",
            "prox 3       - m  [....................]",
            "collision YES   contacts 2",
            "space stop",
        ] {
            assert!(text.contains(want), "{want:?} missing in\n{text}");
        }
        assert!(lines.iter().all(|l| l.len() < 80 && !l.contains('\x1b')), "{text}");
        assert!(lines.len() <= TERMINAL_SIZE.0 as usize - 2, "fits a 24-line terminal");
    }

    #[test]
    fn the_block_says_when_nothing_has_arrived_yet() {
        let d = Drive::new();
        let mut s = status(None, &d);
        s.tick = None;
        let text = screen_lines(&s).join("\n");
        assert!(text.contains("waiting for the first tick") && text.contains("no sensor readings yet"), "{text}");
    }

    #[test]
    fn the_line_form_has_no_escapes_and_lists_the_readings() {
        let mut b = block();
        b.present |= HAS_GPS;
        (b.gps_x_m, b.gps_y_m) = (10.0, 6.0);
        let d = Drive::new();
        let line = status_line(&status(Some(&b), &d));
        assert_eq!(
            line,
            "tick 42 t 4.20s running | speed +0.00 turn +0.00 power +0.00 +0.00 | encoders 1520 -37 \
             | gps 10.000 6.000 | compass 12.0 | proximity 0.750 3.000 1.500 NaN | collision yes contacts 2"
        );
    }

    #[test]
    fn frames_clear_once_then_overwrite_in_place_and_finish_shows_the_cursor() {
        let mut s = Screen::default();
        let lines = vec!["a".to_owned(), "b".to_owned()];
        assert_eq!(s.frame(&lines), "\x1b[?25l\x1b[2J\x1b[Ha\x1b[K\r\nb\x1b[K\r\n\x1b[J");
        assert_eq!(s.frame(&lines), "\x1b[Ha\x1b[K\r\nb\x1b[K\r\n\x1b[J");
        assert_eq!(s.finish(), "\x1b[?25h");
        assert_eq!(s.finish(), "", "once");
    }

    #[test]
    fn bars_scale_with_the_free_distance() {
        assert_eq!(bar(0.0), format!("[{}]", ".".repeat(20)));
        assert_eq!(bar(1.5), format!("[{}{}]", "#".repeat(10), ".".repeat(10)));
        assert_eq!(bar(9.0), format!("[{}]", "#".repeat(20)));
        assert_eq!(bar(f64::INFINITY), format!("[{}]", "#".repeat(20)));
        assert_eq!(bar(f64::NAN), format!("[{}]", ".".repeat(20)), "a missing reading draws nothing");
    }
}
