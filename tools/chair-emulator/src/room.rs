//! The emulator's room: a floor plan (a Ciber-Rato lab) plus furniture the simulator's map need
//! not have, some of it dark (IR beams get no echo from it).

use std::fmt;

use world::map::{Lab, MapLoadError, Wall, builtin};

/// Height given to every box, metres (only beacons care about wall heights; a chair's room has
/// none, so any positive height does).
pub const BOX_HEIGHT_M: f64 = 1.0;

/// The command-line form of a box, as errors name it.
const BOX_FORM: &str = "a box NAME,X0,Y0,X1,Y1[,dark]";

/// A piece of furniture: an axis-aligned box in the room, solid to the chair and to sonars.
///
/// On the command line `NAME,X0,Y0,X1,Y1[,dark]` (metres), which is also what
/// [`Display`](fmt::Display) writes.
#[derive(Debug, Clone, PartialEq)]
pub struct RoomBox {
    /// Label, for messages.
    pub name: String,
    /// Lower-left x, metres.
    pub x0: f64,
    /// Lower-left y, metres.
    pub y0: f64,
    /// Upper-right x, metres.
    pub x1: f64,
    /// Upper-right y, metres.
    pub y1: f64,
    /// A dark or soft surface: IR beams that meet it first get no echo (the thesis: real IR and
    /// sonar sensors miss black or rough surfaces). Sonars still see it.
    pub dark: bool,
}

impl RoomBox {
    /// Parses `NAME,X0,Y0,X1,Y1[,dark]`; the box must not be empty or upside down.
    ///
    /// ```
    /// use chair_emulator::RoomBox;
    /// let b = RoomBox::parse("table,17,6.1,17.6,6.4,dark")?;
    /// assert!(b.dark);
    /// assert_eq!(b.to_string(), "table,17,6.1,17.6,6.4,dark");
    /// assert!(RoomBox::parse("t,3,2,1,4").is_err());
    /// # Ok::<(), String>(())
    /// ```
    pub fn parse(spec: &str) -> Result<RoomBox, String> {
        let parts: Vec<&str> = spec.split(',').map(str::trim).collect();
        let (dark, numbers) = match parts.as_slice() {
            [_, rest @ .., "dark"] => (true, rest),
            [_, rest @ ..] => (false, rest),
            [] => (false, &[][..]),
        };
        let name = parts.first().copied().unwrap_or_default();
        if name.is_empty() || name.parse::<f64>().is_ok() {
            return Err(format!("{spec:?}: {BOX_FORM} starts with a name"));
        }
        if numbers.len() != 4 {
            return Err(format!("{spec:?}: {BOX_FORM} has 4 numbers, got {}", numbers.len()));
        }
        let mut v = [0.0; 4];
        for (slot, text) in v.iter_mut().zip(numbers) {
            *slot = text
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("{spec:?}: {text:?} is not a finite number ({BOX_FORM})"))?;
        }
        let [x0, y0, x1, y1] = v;
        if !(x0 < x1 && y0 < y1) {
            return Err(format!("{spec:?}: want X0 < X1 and Y0 < Y1 ({BOX_FORM})"));
        }
        Ok(RoomBox { name: name.to_owned(), x0, y0, x1, y1, dark })
    }
}

/// The command-line form, `NAME,X0,Y0,X1,Y1[,dark]`.
impl fmt::Display for RoomBox {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{},{},{},{},{}", self.name, self.x0, self.y0, self.x1, self.y1)?;
        if self.dark { write!(f, ",dark") } else { Ok(()) }
    }
}

/// Why a room could not be put together.
#[derive(Debug, thiserror::Error)]
pub enum RoomBuildError {
    /// The floor plan did not load (the message names the file, line and column).
    #[error("--lab {message}")]
    Lab {
        /// The error, shown with its file's name.
        message: String,
        /// The error itself.
        #[source]
        source: Box<MapLoadError>,
    },
    /// A box reaches outside the room.
    #[error("--box {spec}: outside the {width} x {height} m room")]
    BoxOutside {
        /// The box in its command-line form.
        spec: String,
        /// Room width, metres.
        width: f64,
        /// Room height, metres.
        height: f64,
    },
}

/// The room the emulated chair drives in.
#[derive(Debug, Clone, PartialEq)]
pub struct Room {
    /// The floor plan: walls only.
    pub lab: Lab,
    /// Furniture on top of it.
    pub boxes: Vec<RoomBox>,
}

impl Room {
    /// A room on the floor plan `lab_spec` (`builtin:NAME` or a lab XML file) with `boxes`,
    /// each of which must lie inside the plan's rectangle.
    pub fn load(lab_spec: &str, boxes: Vec<RoomBox>) -> Result<Room, RoomBuildError> {
        let lab = builtin::load_lab_spec(lab_spec).map_err(|source| RoomBuildError::Lab {
            message: source.in_file(lab_spec).to_string(),
            source: Box::new(source),
        })?;
        Room::new(lab, boxes)
    }

    /// A room on `lab` with `boxes`, each of which must lie inside the lab's rectangle.
    pub fn new(lab: Lab, boxes: Vec<RoomBox>) -> Result<Room, RoomBuildError> {
        for b in &boxes {
            if !(b.x0 >= 0.0 && b.y0 >= 0.0 && b.x1 <= lab.width_m && b.y1 <= lab.height_m) {
                return Err(RoomBuildError::BoxOutside {
                    spec: b.to_string(),
                    width: lab.width_m,
                    height: lab.height_m,
                });
            }
        }
        Ok(Room { lab, boxes })
    }

    /// The lab as the world model takes it: the plan's walls, then the boxes as walls, as the
    /// hub adds a scenario's obstacles. `with_dark: false` leaves the dark boxes out (what an
    /// IR beam sees).
    pub fn lab(&self, with_dark: bool) -> Lab {
        let mut lab = self.lab.clone();
        for b in self.boxes.iter().filter(|b| with_dark || !b.dark) {
            lab.walls.push(Wall::rectangle(b.x0, b.y0, b.x1, b.y1, BOX_HEIGHT_M));
        }
        lab
    }

    /// Whether any box is dark.
    pub fn has_dark(&self) -> bool {
        self.boxes.iter().any(|b| b.dark)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boxes_read_with_and_without_dark_and_junk_is_named() {
        let b = RoomBox::parse("A, 17, 6.1, 17.6, 6.4").expect("valid");
        assert_eq!(b, RoomBox { name: "A".into(), x0: 17.0, y0: 6.1, x1: 17.6, y1: 6.4, dark: false });
        assert!(RoomBox::parse("B,1,2,3,4,dark").expect("valid").dark);
        for (bad, says) in [
            ("1,2,3,4", "starts with a name"),
            ("A,1,2,3", "has 4 numbers, got 3"),
            ("A,1,2,3,4,5", "has 4 numbers, got 5"),
            ("A,1,x,3,4", "\"x\" is not a finite number"),
            ("A,1,2,3,inf", "\"inf\" is not a finite number"),
            ("A,3,2,1,4", "want X0 < X1"),
            ("", "starts with a name"),
        ] {
            let e = RoomBox::parse(bad).expect_err(bad);
            assert!(e.contains(says), "{bad}: {e}");
        }
    }

    #[test]
    fn dark_boxes_are_left_out_of_the_lab_the_ir_beams_see() {
        let boxes = vec![RoomBox::parse("A,1,1,2,2").expect("valid"), RoomBox::parse("B,3,3,4,4,dark").expect("valid")];
        let room = Room::load("builtin:liacc", boxes).expect("inside");
        let plan = room.lab.walls.len();
        assert_eq!(room.lab(true).walls.len(), plan + 2);
        assert_eq!(room.lab(false).walls.len(), plan + 1);
        assert!(room.has_dark());
    }

    #[test]
    fn a_box_outside_the_room_or_an_unknown_plan_is_refused() {
        let far = RoomBox::parse("far,40,1,50,2").expect("valid");
        let e = Room::load("builtin:liacc", vec![far]).expect_err("outside");
        assert_eq!(e.to_string(), "--box far,40,1,50,2: outside the 44 x 17.75 m room");
        let e = Room::load("builtin:nowhere", vec![]).expect_err("unknown");
        assert!(matches!(e, RoomBuildError::Lab { .. }), "{e}");
    }
}
