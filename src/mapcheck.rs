//! `iwsim map check FILE`: a summary of a lab, grid or parameters file, or its first error with
//! line and column.

use std::process::ExitCode;

use world::World;
use world::map::builtin;
use world::map::xml::{MapFile, parse_any, read_text};

/// Checks one file (or `builtin:NAME`) and prints what it holds; exit code 1 when it is bad.
pub fn check(spec: &str) -> anyhow::Result<ExitCode> {
    let text = match spec.strip_prefix(builtin::PREFIX) {
        Some(name) => match builtin::lab_xml(name) {
            Some(xml) => xml.to_owned(),
            None => {
                agent_sdk::report!("{spec}: unknown built-in map; known: {}", builtin::NAMES.join(", "));
                return Ok(ExitCode::FAILURE);
            }
        },
        None => match read_text(std::path::Path::new(spec)) {
            Ok(t) => t,
            Err(err) => {
                agent_sdk::report!("{}", err.in_file(spec));
                return Ok(ExitCode::FAILURE);
            }
        },
    };
    match parse_any(&text) {
        Ok(file) => {
            print!("{}", summary(spec, &file));
            if let MapFile::Lab(lab) = &file {
                // The world model has its own checks (beacon count, triangulation): run them
                // too, so a lab that passes here loads in the hub.
                if let Err(err) = World::new(lab, world::map::Params::default(), 0) {
                    agent_sdk::report!("{spec}: the lab parses but the world refuses it: {err}");
                    return Ok(ExitCode::FAILURE);
                }
            }
            Ok(ExitCode::SUCCESS)
        }
        Err(err) => {
            agent_sdk::report!("{}", err.in_file(spec));
            Ok(ExitCode::FAILURE)
        }
    }
}

/// The text `map check` prints for a file that loaded.
pub fn summary(spec: &str, file: &MapFile) -> String {
    match file {
        MapFile::Lab(lab) => {
            let corners: usize = lab.walls.iter().map(|w| w.corners.len()).sum();
            let mut s = format!(
                "{spec}: lab \"{}\", {} m x {} m\n  walls: {} ({} corners)\n  beacons: {}\n  targets: {}\n",
                lab.name,
                lab.width_m,
                lab.height_m,
                lab.walls.len(),
                corners,
                lab.beacons.len(),
                lab.targets.len()
            );
            for (i, b) in lab.beacons.iter().enumerate() {
                s += &format!("    beacon {i}: ({}, {}) height {} m\n", b.pos.x, b.pos.y, b.height_m);
            }
            for (i, t) in lab.targets.iter().enumerate() {
                s += &format!("    target {i}: ({}, {}) radius {} m\n", t.pos.x, t.pos.y, t.radius_m);
            }
            if let Some(grid) = spec.strip_prefix(builtin::PREFIX).and_then(builtin::map).map(|m| m.grid) {
                s += &format!("  grid (built in): {} start poses\n", grid.poses.len());
            }
            s
        }
        MapFile::Grid(grid) => {
            let mut s = format!("{spec}: grid, {} start poses\n", grid.poses.len());
            for (i, p) in grid.poses.iter().enumerate() {
                s += &format!("    {}: ({}, {}) heading {} deg\n", i + 1, p.pos.x, p.pos.y, p.heading_deg);
            }
            s
        }
        MapFile::Params(p) => format!(
            "{spec}: parameters\n  cycle {} ms, run length {} ticks{}\n  sensors: compass {}, gps {}, beacon {}\n  noise: proximity {} m, compass {} deg, beacon {} deg, gps {} m / {} deg, motors {} %, encoder slip {} % a tick\n  latency (ticks): proximity {}, compass {}, beacon {}, ground {}, collision {}, gps {}\n",
            p.cycle_ms,
            p.sim_time_ticks,
            if p.sim_time_ticks == 0 { " (no limit)" } else { "" },
            on(p.sensors.compass),
            on(p.sensors.gps),
            on(p.sensors.beacon),
            p.noise.proximity_m,
            p.noise.compass_deg,
            p.noise.beacon_deg,
            p.noise.gps_pos_m,
            p.noise.gps_heading_deg,
            p.noise.motor_frac * 100.0,
            p.noise.encoder_slip_frac * 100.0,
            p.latency.proximity,
            p.latency.compass,
            p.latency.beacon,
            p.latency.ground,
            p.latency.collision,
            p.latency.gps,
        ),
    }
}

fn on(b: bool) -> &'static str {
    if b { "on" } else { "off" }
}
