//! The iwsim world model: maps, rectangular differential-drive bodies with motors, collisions,
//! sensors, noise and robot-to-robot messages, stepped deterministically.
//!
//! The world is pure: it does no I/O, reads no clock and owns its only random generator, which
//! is seeded when the world is built. Time enters as the duration of each step.
//!
//! ```
//! use hub::map::builtin;
//! use hub::world::{Action, RobotSpec, World};
//!
//! let map = builtin::map("liacc").expect("built in");
//! let mut world = World::new(&map.lab, hub::map::Params::default(), 7).expect("valid lab");
//! let chair = world.add_robot(RobotSpec::at(10.0, 6.1, 0.0)).expect("free start");
//! for _ in 0..10 {
//!     world.step(&[Action::motors(chair, 1.0, 1.0)], 0.1);
//! }
//! assert!(world.robot(chair).expect("alive").pose.x > 10.0);
//! ```
#![warn(missing_docs)]

mod geom;
pub mod map;
pub mod math;
pub mod rng;
pub mod serve;
pub mod tiled;
pub mod world;
