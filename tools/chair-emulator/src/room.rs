//! The emulator's room: a floor plan (a Ciber-Rato lab) plus furniture the simulator's map need
//! not have, some of it dark (IR beams get no echo from it).

use world::map::{Lab, MapLoadError, Wall, builtin};

/// Height given to every box, metres (only beacons care about wall heights; a chair's room has
/// none, so any positive height does).
pub const BOX_HEIGHT_M: f64 = 1.0;

pub use places::RoomBox;

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
