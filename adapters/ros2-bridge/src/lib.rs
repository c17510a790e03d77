//! `iwsim ros2`: every chair of a hub's session as the topics a ROS 2 mobile-base driver
//! offers, over Zenoh in rmw_zenoh's wire format, so that a ROS 2 node started with
//! `RMW_IMPLEMENTATION=rmw_zenoh_cpp` talks to it with no ROS 2 install on iwsim's side.

pub mod bridge;
pub mod cdr;
pub mod cli;
pub mod drive;
pub mod msgs;
pub mod names;
pub mod rihs;
