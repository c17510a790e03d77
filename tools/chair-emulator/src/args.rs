//! The command line of `iwsim chair-emulator`.

use std::path::PathBuf;

use sim_model::PoseDeg;

use crate::board::{BoardConfig, Imperfections};
use crate::driver::{EmulatorConfig, EmulatorError, PortChoice};
use crate::room::{Room, RoomBox};

/// Options of `iwsim chair-emulator`.
///
/// ```text
/// iwsim chair-emulator --link /tmp/chair --box table,17,6.1,17.6,6.4,dark --truth truth.jsonl
/// ```
/// prints `chair-emulator: /dev/pts/N` and serves a chair at (10, 6.1) on the LIACC floor, with a
/// dark table IR beams do not see, until interrupted.
#[derive(Debug, Clone, clap::Args)]
#[command(after_help = "Faults for test benches: SIGUSR1 cuts the board's transmit line (it still receives \
and acts; the host hears nothing) and a second SIGUSR1 mends it; SIGUSR2 sends the host one burst of garbage \
and corrupt frames. SIGINT/SIGTERM stop the emulator and remove --link.")]
pub struct EmulatorArgs {
    /// The room's floor plan: `builtin:NAME` or a Ciber-Rato lab XML file.
    #[arg(long, value_name = "builtin:NAME|FILE", default_value = "builtin:liacc")]
    pub lab: String,
    /// Furniture in the room that the simulator's map need not have: a box from (X0,Y0) to
    /// (X1,Y1) in metres, solid to the chair and to sonars. `dark`: a dark or soft surface from
    /// which IR beams get no echo. Repeatable.
    #[arg(long = "box", value_name = "NAME,X0,Y0,X1,Y1[,dark]", value_parser = RoomBox::parse, allow_hyphen_values = true)]
    pub boxes: Vec<RoomBox>,
    /// The chair's true start pose X,Y,DEG in metres and degrees.
    #[arg(long, value_name = "X,Y,DEG", value_parser = places::args::pose, default_value = "10,6.1,0", allow_hyphen_values = true)]
    pub pose: PoseDeg,
    /// Talk on this serial device instead of a new pseudo-terminal (raw, 8N1, at --baud).
    #[arg(long, value_name = "PATH", conflicts_with = "link")]
    pub port: Option<PathBuf>,
    /// Also make a symlink PATH to the pseudo-terminal (replaced if it exists, removed on exit),
    /// so a host can open one stable path across emulator restarts.
    #[arg(long, value_name = "PATH")]
    pub link: Option<PathBuf>,
    /// The line's baud rate: every byte written takes the time 10 bits take at this rate (8N1);
    /// 0 sends as fast as the port takes bytes.
    #[arg(long, default_value_t = 115_200)]
    pub baud: u32,
    /// Advance the board's clock only on the host's SimStep frames (deterministic tests);
    /// otherwise it follows the monotonic clock.
    #[arg(long)]
    pub stepped: bool,
    /// Fixes every random draw (wheel slip, sensor noise).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The right motor is this fraction weaker than the left, in [0, 1).
    #[arg(long, default_value_t = Imperfections::REAL_CHAIR.asymmetry)]
    pub asymmetry: f64,
    /// Wheel slip: encoder counts off by this fraction (1σ) per 100 ms of driving.
    #[arg(long, default_value_t = Imperfections::REAL_CHAIR.slip)]
    pub slip: f64,
    /// The chance a sonar reading gets no echo, in [0, 1].
    #[arg(long, default_value_t = Imperfections::REAL_CHAIR.sonar_dropout)]
    pub sonar_dropout: f64,
    /// The chance a sonar reading is a spurious short echo, in [0, 1].
    #[arg(long, default_value_t = Imperfections::REAL_CHAIR.sonar_spike)]
    pub sonar_spike: f64,
    /// Gaussian noise on every range reading, metres (1σ).
    #[arg(long, value_name = "M", default_value_t = Imperfections::REAL_CHAIR.range_noise_m)]
    pub range_noise: f64,
    /// An ideal chair: every imperfection above off (whatever they say).
    #[arg(long)]
    pub ideal: bool,
    /// Every Sample carries 8 sonar and 8 IR readings (the largest frame; the ids the chair has
    /// no sensor for read no echo), for measuring the link.
    #[arg(long)]
    pub full_frames: bool,
    /// Write the ground truth to this file, one JSON object per line: the true pose every
    /// physics step and events (motors_zero with its reason, frame_dropped, hello, estop),
    /// stamped with CLOCK_MONOTONIC nanoseconds.
    #[arg(long, value_name = "FILE")]
    pub truth: Option<PathBuf>,
}

impl EmulatorArgs {
    /// The configuration these options describe (loads the floor plan).
    pub fn config(&self) -> Result<EmulatorConfig, EmulatorError> {
        let room = Room::load(&self.lab, self.boxes.clone())?;
        let imperfections = if self.ideal {
            Imperfections::NONE
        } else {
            Imperfections {
                asymmetry: self.asymmetry,
                slip: self.slip,
                sonar_dropout: self.sonar_dropout,
                sonar_spike: self.sonar_spike,
                range_noise_m: self.range_noise,
            }
        };
        let board = BoardConfig {
            pose: self.pose,
            seed: self.seed,
            stepped: self.stepped,
            imperfections,
            full_frames: self.full_frames,
        };
        Ok(EmulatorConfig {
            room,
            board,
            port: self.port.clone().map_or(PortChoice::Pty, PortChoice::Device),
            link: self.link.clone(),
            baud: self.baud,
            truth: self.truth.clone(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        args: EmulatorArgs,
    }

    fn parse(args: &[&str]) -> Result<EmulatorArgs, clap::Error> {
        Cli::try_parse_from(std::iter::once("chair-emulator").chain(args.iter().copied())).map(|c| c.args)
    }

    #[test]
    fn defaults_are_a_real_chair_on_the_liacc_floor_on_a_pty() {
        let a = parse(&[]).expect("defaults");
        let cfg = a.config().expect("loads");
        assert_eq!(cfg.board.imperfections, Imperfections::REAL_CHAIR);
        assert_eq!(cfg.board.pose, [10.0, 6.1, 0.0]);
        assert_eq!((cfg.port, cfg.baud, cfg.board.stepped), (PortChoice::Pty, 115_200, false));
        assert_eq!(cfg.room.lab.name, world::map::builtin::map("liacc").expect("built in").lab.name);
    }

    #[test]
    fn every_option_reaches_the_configuration() {
        let a = parse(&[
            "--box",
            "A,17,6.1,17.6,6.4",
            "--box",
            "B,20,5,21,6,dark",
            "--pose",
            "12,-0,-90",
            "--link",
            "/tmp/x",
            "--baud",
            "0",
            "--stepped",
            "--seed",
            "9",
            "--ideal",
            "--full-frames",
            "--truth",
            "t.jsonl",
        ])
        .expect("valid");
        let cfg = a.config().expect("loads");
        assert_eq!(cfg.room.boxes.len(), 2);
        assert!(cfg.room.boxes[1].dark);
        assert_eq!(cfg.board.pose, [12.0, 0.0, -90.0]);
        assert_eq!(cfg.board.imperfections, Imperfections::NONE);
        assert!(cfg.board.stepped && cfg.board.full_frames);
        assert_eq!((cfg.baud, cfg.board.seed), (0, 9));
        assert_eq!(cfg.link, Some(PathBuf::from("/tmp/x")));
        assert_eq!(cfg.truth, Some(PathBuf::from("t.jsonl")));
    }

    #[test]
    fn bad_values_are_refused_with_what_is_wrong() {
        let e = parse(&["--pose", "1,2"]).expect_err("two numbers");
        assert!(e.to_string().contains("is not a pose X,Y,DIR: expected 3 numbers, got 2"), "{e}");
        let e = parse(&["--box", "1,2,3,4"]).expect_err("no name");
        assert!(e.to_string().contains("starts with a name"), "{e}");
        let e = parse(&["--port", "/dev/ttyS0", "--link", "/tmp/x"]).expect_err("conflict");
        assert_eq!(e.kind(), clap::error::ErrorKind::ArgumentConflict);
        let e = parse(&["--box", "far,40,1,50,2"]).expect("parses").config().expect_err("outside");
        assert!(e.to_string().contains("outside the 44 x 17.75 m room"), "{e}");
    }
}
