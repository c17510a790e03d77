//! End-to-end tests: the `iwsim` binary in real processes, talking over real shared memory.

mod architecture;
mod browser;
mod chairs;
mod challenge;
mod ciberrato;
mod cli;
mod common;
mod docs;
mod hardening;
mod hub;
mod maps;
mod mixed_view;
mod python;
mod replay;
mod robots;
mod ros2;
mod runner;
mod scenarios;
mod serial;
mod serve;
mod teleop;
mod udp;
mod view;
mod zenoh;
