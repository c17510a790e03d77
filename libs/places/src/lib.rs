//! A scenario's places: static obstacles (boxes) and checkpoints (circles), one type each for
//! every form they are written in — the command line (`--obstacle X0,Y0,X1,Y1[,H]`,
//! `--checkpoint X,Y[,R]`), a scenario's TOML tables and the arrays of `summary.json` — with
//! their checks and one error type.
//!
//! ```
//! use places::{Checkpoint, Obstacle};
//!
//! let o = Obstacle::parse("17,6.1,17.6,6.4")?;
//! assert_eq!(o.height, 1.0);
//! assert_eq!(o.to_string(), "17,6.1,17.6,6.4,1");
//! let c: Checkpoint = serde_json::from_str("[10, 6.1]")?;
//! assert_eq!(c, Checkpoint::parse("10,6.1,0.5")?);
//! assert!(Obstacle::parse("3,2,1,4").is_err());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![warn(missing_docs)]

pub mod args;
pub mod files;
mod room;

pub use room::RoomBox;

use std::fmt;

use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};
use serde::ser::{SerializeTuple, Serializer};
use serde::{Deserialize, Serialize};

/// Height of an obstacle that does not give one, metres.
pub const DEFAULT_OBSTACLE_HEIGHT_M: f64 = 1.0;
/// Radius of a checkpoint that does not give one, metres.
pub const DEFAULT_CHECKPOINT_RADIUS_M: f64 = 0.5;

/// The command-line form of an obstacle, as errors name it.
const OBSTACLE_FORM: &str = "an obstacle X0,Y0,X1,Y1[,H]";
/// The command-line form of a checkpoint, as errors name it.
const CHECKPOINT_FORM: &str = "a checkpoint X,Y[,R]";

/// A static obstacle: an axis-aligned box, sensed and collided with like a wall.
///
/// In a scenario it is a table (`name`, `x0`, `y0`, `x1`, `y1`, `height`); in `summary.json`
/// the array `[X0, Y0, X1, Y1, H]` (the name is not kept); on the command line `X0,Y0,X1,Y1[,H]`,
/// which is also what [`Display`](fmt::Display) writes.
#[derive(Debug, Clone, PartialEq)]
pub struct Obstacle {
    /// Label (empty when none is given).
    pub name: String,
    /// Lower-left x, metres.
    pub x0: f64,
    /// Lower-left y, metres.
    pub y0: f64,
    /// Upper-right x, metres.
    pub x1: f64,
    /// Upper-right y, metres.
    pub y1: f64,
    /// Height, metres.
    pub height: f64,
}

/// A checkpoint: a circle a route passes through.
///
/// In a scenario it is a table (`x`, `y`, `radius`); in `summary.json` the array `[X, Y, R]`;
/// on the command line `X,Y[,R]`, which is also what [`Display`](fmt::Display) writes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Checkpoint {
    /// Centre x, metres.
    pub x: f64,
    /// Centre y, metres.
    pub y: f64,
    /// Reached within this distance of the centre, metres.
    pub radius: f64,
}

/// Why an obstacle or a checkpoint is refused. The messages quote the place in its
/// command-line form; callers say where it came from (`--obstacle`, a file's line).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlaceError {
    /// The text is not the form's list of finite numbers (the message names the form, what
    /// was given and what is wrong).
    #[error("{0}")]
    Numbers(String),
    /// The box is empty or upside down, its height is not positive, or a number is not finite.
    #[error("{}: want X0 < X1, Y0 < Y1 and a positive height H (X0,Y0,X1,Y1,H)", label(.0))]
    Box(Obstacle),
    /// The radius is not positive, or a number is not finite.
    #[error("{:?}: want finite X, Y and a positive radius R (X,Y,R)", .0.to_string())]
    Circle(Checkpoint),
    /// The box reaches outside the lab.
    #[error("{}: outside the {width} x {height} m lab", label(.obstacle))]
    OutsideLab {
        /// The obstacle.
        obstacle: Obstacle,
        /// Lab width, metres.
        width: f64,
        /// Lab height, metres.
        height: f64,
    },
}

/// An obstacle as errors quote it: its name, if it has one, and its command-line form.
fn label(o: &Obstacle) -> String {
    if o.name.is_empty() { format!("{:?}", o.to_string()) } else { format!("{} {:?}", o.name, o.to_string()) }
}

impl Obstacle {
    /// A box without a name.
    pub fn new(x0: f64, y0: f64, x1: f64, y1: f64, height: f64) -> Self {
        Self { name: String::new(), x0, y0, x1, y1, height }
    }

    /// Parses and checks `X0,Y0,X1,Y1[,H]` (H defaults to [`DEFAULT_OBSTACLE_HEIGHT_M`]).
    pub fn parse(spec: &str) -> Result<Self, PlaceError> {
        let [x0, y0, x1, y1, h] = crate::args::fixed::<5>(spec, OBSTACLE_FORM, Some(DEFAULT_OBSTACLE_HEIGHT_M))
            .map_err(PlaceError::Numbers)?;
        Self::new(x0, y0, x1, y1, h).checked()
    }

    /// Itself, if it is a box: X0 < X1, Y0 < Y1, a positive height, every number finite.
    pub fn checked(self) -> Result<Self, PlaceError> {
        let finite = [self.x0, self.y0, self.x1, self.y1, self.height].iter().all(|v| v.is_finite());
        if finite && self.x0 < self.x1 && self.y0 < self.y1 && self.height > 0.0 {
            Ok(self)
        } else {
            Err(PlaceError::Box(self))
        }
    }

    /// Checks that the box lies inside a lab of `width` × `height` metres (edges included).
    pub fn check_inside(&self, width: f64, height: f64) -> Result<(), PlaceError> {
        if self.x0 >= 0.0 && self.y0 >= 0.0 && self.x1 <= width && self.y1 <= height {
            Ok(())
        } else {
            Err(PlaceError::OutsideLab { obstacle: self.clone(), width, height })
        }
    }
}

impl Checkpoint {
    /// Parses and checks `X,Y[,R]` (R defaults to [`DEFAULT_CHECKPOINT_RADIUS_M`]).
    pub fn parse(spec: &str) -> Result<Self, PlaceError> {
        let [x, y, radius] = crate::args::fixed::<3>(spec, CHECKPOINT_FORM, Some(DEFAULT_CHECKPOINT_RADIUS_M))
            .map_err(PlaceError::Numbers)?;
        Self { x, y, radius }.checked()
    }

    /// Itself, if its numbers are finite and its radius positive.
    pub fn checked(self) -> Result<Self, PlaceError> {
        if self.x.is_finite() && self.y.is_finite() && self.radius.is_finite() && self.radius > 0.0 {
            Ok(self)
        } else {
            Err(PlaceError::Circle(self))
        }
    }

    /// Whether a point is within the radius of the centre.
    pub fn contains(&self, x: f64, y: f64) -> bool {
        (x - self.x).hypot(y - self.y) <= self.radius
    }
}

/// The command-line form, `X0,Y0,X1,Y1,H`: what `iwsim hub --obstacle` reads back.
impl fmt::Display for Obstacle {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{},{},{},{},{}", self.x0, self.y0, self.x1, self.y1, self.height)
    }
}

/// The command-line form, `X,Y,R`: what `iwsim hub --checkpoint` reads back.
impl fmt::Display for Checkpoint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{},{},{}", self.x, self.y, self.radius)
    }
}

fn default_height() -> f64 {
    DEFAULT_OBSTACLE_HEIGHT_M
}
fn default_radius() -> f64 {
    DEFAULT_CHECKPOINT_RADIUS_M
}

/// An obstacle's table in a scenario file.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ObstacleTable {
    #[serde(default)]
    name: String,
    x0: f64,
    y0: f64,
    x1: f64,
    y1: f64,
    #[serde(default = "default_height")]
    height: f64,
}

/// A checkpoint's table in a scenario file.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CheckpointTable {
    x: f64,
    y: f64,
    #[serde(default = "default_radius")]
    radius: f64,
}

/// Reads `min` to `N` numbers of an array; the missing last one is `last_default`.
fn numbers<'de, A: SeqAccess<'de>, const N: usize>(
    mut seq: A,
    min: usize,
    last_default: f64,
    expecting: &'static str,
) -> Result<[f64; N], A::Error> {
    let mut out = [last_default; N];
    let mut n = 0;
    while let Some(v) = seq.next_element::<f64>()? {
        if n == N {
            return Err(de::Error::invalid_length(n + 1, &expecting));
        }
        out[n] = v;
        n += 1;
    }
    if n < min {
        return Err(de::Error::invalid_length(n, &expecting));
    }
    Ok(out)
}

/// Obstacles are written as `[X0, Y0, X1, Y1, H]` (summary.json); see [`Obstacle`].
impl Serialize for Obstacle {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut t = serializer.serialize_tuple(5)?;
        for v in [self.x0, self.y0, self.x1, self.y1, self.height] {
            t.serialize_element(&v)?;
        }
        t.end()
    }
}

/// Obstacles are read from a table (a scenario) or an array of 4 or 5 numbers (summary.json),
/// and checked as [`Obstacle::checked`] does.
impl<'de> Deserialize<'de> for Obstacle {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct V;
        const EXPECTING: &str = "an obstacle: a table {x0, y0, x1, y1[, height, name]} or [X0, Y0, X1, Y1[, H]]";
        impl<'de> Visitor<'de> for V {
            type Value = Obstacle;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(EXPECTING)
            }
            fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<Obstacle, A::Error> {
                let [x0, y0, x1, y1, h] = numbers::<A, 5>(seq, 4, DEFAULT_OBSTACLE_HEIGHT_M, "4 or 5 numbers")?;
                Obstacle::new(x0, y0, x1, y1, h).checked().map_err(de::Error::custom)
            }
            fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Obstacle, A::Error> {
                let t = ObstacleTable::deserialize(de::value::MapAccessDeserializer::new(map))?;
                let o = Obstacle { name: t.name, x0: t.x0, y0: t.y0, x1: t.x1, y1: t.y1, height: t.height };
                o.checked().map_err(de::Error::custom)
            }
        }
        deserializer.deserialize_any(V)
    }
}

/// Checkpoints are written as `[X, Y, R]` (summary.json); see [`Checkpoint`].
impl Serialize for Checkpoint {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut t = serializer.serialize_tuple(3)?;
        for v in [self.x, self.y, self.radius] {
            t.serialize_element(&v)?;
        }
        t.end()
    }
}

/// Checkpoints are read from a table (a scenario) or an array of 2 or 3 numbers
/// (summary.json), and checked as [`Checkpoint::checked`] does.
impl<'de> Deserialize<'de> for Checkpoint {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct V;
        const EXPECTING: &str = "a checkpoint: a table {x, y[, radius]} or [X, Y[, R]]";
        impl<'de> Visitor<'de> for V {
            type Value = Checkpoint;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(EXPECTING)
            }
            fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<Checkpoint, A::Error> {
                let [x, y, radius] = numbers::<A, 3>(seq, 2, DEFAULT_CHECKPOINT_RADIUS_M, "2 or 3 numbers")?;
                Checkpoint { x, y, radius }.checked().map_err(de::Error::custom)
            }
            fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Checkpoint, A::Error> {
                let t = CheckpointTable::deserialize(de::value::MapAccessDeserializer::new(map))?;
                Checkpoint { x: t.x, y: t.y, radius: t.radius }.checked().map_err(de::Error::custom)
            }
        }
        deserializer.deserialize_any(V)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn command_line_forms_parse_with_their_defaults() {
        assert_eq!(Obstacle::parse("1,2,3,4"), Ok(Obstacle::new(1.0, 2.0, 3.0, 4.0, DEFAULT_OBSTACLE_HEIGHT_M)));
        assert_eq!(Obstacle::parse("1, 2, 3, 4, 0.3").map(|o| o.height), Ok(0.3));
        assert_eq!(Checkpoint::parse("-1, 2"), Ok(Checkpoint { x: -1.0, y: 2.0, radius: DEFAULT_CHECKPOINT_RADIUS_M }));
        assert_eq!(Checkpoint::parse("1, 2, 0.75").map(|c| c.radius), Ok(0.75));
    }

    #[test]
    fn bad_command_line_forms_say_what_is_wrong() {
        for (bad, says) in [
            ("1,2,3", "\"1,2,3\" is not an obstacle X0,Y0,X1,Y1[,H]: expected 4 to 5 numbers, got 3"),
            ("1,2,x,4", "\"1,2,x,4\" is not an obstacle X0,Y0,X1,Y1[,H]: expected comma-separated finite numbers"),
            ("3,2,1,4", "\"3,2,1,4,1\": want X0 < X1, Y0 < Y1 and a positive height H (X0,Y0,X1,Y1,H)"),
            ("1,2,3,4,0", "\"1,2,3,4,0\": want X0 < X1"),
        ] {
            let e = Obstacle::parse(bad).expect_err(bad).to_string();
            assert!(e.starts_with(says), "{bad}: {e}");
        }
        assert!(matches!(Obstacle::parse("1,2,3"), Err(PlaceError::Numbers(_))));
        assert!(matches!(Obstacle::parse("3,2,1,4"), Err(PlaceError::Box(o)) if o.x0 == 3.0));
        assert!(matches!(Checkpoint::parse("1,nan"), Err(PlaceError::Numbers(m)) if m.contains("finite")));
        assert_eq!(
            Checkpoint::parse("1,2,-1").map_err(|e| e.to_string()),
            Err("\"1,2,-1\": want finite X, Y and a positive radius R (X,Y,R)".to_owned())
        );
    }

    #[test]
    fn an_obstacle_must_lie_inside_the_lab() {
        let o = Obstacle::parse("40,1,45,2").expect("a box");
        assert_eq!(o.check_inside(50.0, 10.0), Ok(()));
        let e = o.check_inside(44.0, 17.75).expect_err("outside");
        assert_eq!(e.to_string(), "\"40,1,45,2,1\": outside the 44 x 17.75 m lab");
        assert!(Obstacle::parse("-1,1,2,2").expect("a box").check_inside(44.0, 17.75).is_err());
    }

    #[test]
    fn the_display_form_parses_back_to_the_same_place() {
        let o = Obstacle::parse("17,6.1,17.6,6.4,0.25").expect("a box");
        assert_eq!(Obstacle::parse(&o.to_string()), Ok(o));
        let c = Checkpoint::parse("10,-6.1,0.3").expect("a circle");
        assert_eq!(Checkpoint::parse(&c.to_string()), Ok(c));
    }

    #[test]
    fn summary_arrays_round_trip_and_take_defaults() {
        let o = Obstacle::new(17.0, 6.1, 17.6, 6.4, 1.0);
        assert_eq!(serde_json::to_string(&o).expect("json"), "[17.0,6.1,17.6,6.4,1.0]");
        assert_eq!(serde_json::from_str::<Obstacle>("[17,6.1,17.6,6.4]").expect("four"), o);
        let c = Checkpoint { x: 10.0, y: 6.1, radius: 0.5 };
        assert_eq!(serde_json::to_string(&c).expect("json"), "[10.0,6.1,0.5]");
        assert_eq!(serde_json::from_str::<Checkpoint>("[10,6.1]").expect("two"), c);
        for bad in ["[1,2,3]", "[1,2,3,4,5,6]", "[3,2,1,4]", "[1,2,\"x\",4]", "{\"x0\":1}"] {
            assert!(serde_json::from_str::<Obstacle>(bad).is_err(), "{bad}");
        }
        let e = serde_json::from_str::<Checkpoint>("[1,2,0]").expect_err("radius 0").to_string();
        assert!(e.contains("positive radius"), "{e}");
    }

    #[test]
    fn tables_read_with_defaults_and_refuse_unknown_keys() {
        #[derive(Deserialize)]
        struct File {
            obstacles: Vec<Obstacle>,
            checkpoints: Vec<Checkpoint>,
        }
        let f: File = serde_json::from_str(
            r#"{"obstacles":[{"name":"A","x0":17,"y0":6.1,"x1":17.6,"y1":6.4}],"checkpoints":[{"x":1,"y":2}]}"#,
        )
        .expect("tables");
        assert_eq!(f.obstacles[0].name, "A");
        assert_eq!(f.obstacles[0].height, DEFAULT_OBSTACLE_HEIGHT_M);
        assert_eq!(f.checkpoints[0].radius, DEFAULT_CHECKPOINT_RADIUS_M);
        let e = serde_json::from_str::<Checkpoint>(r#"{"x":1,"y":2,"r":3}"#).expect_err("r").to_string();
        assert!(e.contains("unknown field `r`"), "{e}");
        let e = serde_json::from_str::<Obstacle>(r#"{"x0":3,"y0":2,"x1":1,"y1":4}"#).expect_err("upside down");
        assert!(e.to_string().contains("want X0 < X1"), "{e}");
    }
}
