//! The worlds shipped inside the binary, and `builtin:NAME`-or-path map specs.
//!
//! - `liacc`: the LIACC floor at FEUP from the thesis, Annex D (44 m × 17.75 m, 23 walls), the
//!   default world. Its grid starts with checkpoint 1 of the thesis slalom, (10.0, 6.1).
//! - `thesis`: the thesis's example map, Annex A (28 m × 14 m, one beacon, one target, two
//!   walls, one of them L-shaped).
//! - `maze`: a 28 m × 14 m maze of 2 m cells in Ciber-Rato's `<Row Pos Pattern>` shorthand,
//!   with one beacon and one target.
//! - `ward`: a hospital ward of iwsim's own (40 m × 14 m): a 2 m corridor with eight rooms on
//!   each side, each through a 1 m doorway; for many chairs sharing one building.
//!
//! The XML files live in `hub/world/maps/`; they are compiled in, so the binary needs no data files.

use std::path::Path;

use super::xml::{parse_grid, parse_grid_for, parse_lab, read_text};
use super::{Grid, Lab, Map, MapLoadError};

/// Names of the built-in maps; the first is the default world.
pub const NAMES: &[&str] = &["liacc", "thesis", "maze", "ward"];

/// Prefix that names a built-in map in a spec, as in `builtin:liacc`.
pub const PREFIX: &str = "builtin:";

const LIACC_LAB: &str = include_str!("../../maps/liacc-lab.xml");
const LIACC_GRID: &str = include_str!("../../maps/liacc-grid.xml");
const THESIS_LAB: &str = include_str!("../../maps/thesis-lab.xml");
const THESIS_GRID: &str = include_str!("../../maps/thesis-grid.xml");
const MAZE_LAB: &str = include_str!("../../maps/maze-lab.xml");
const MAZE_GRID: &str = include_str!("../../maps/maze-grid.xml");
const WARD_LAB: &str = include_str!("../../maps/ward-lab.xml");
const WARD_GRID: &str = include_str!("../../maps/ward-grid.xml");

/// The lab XML of a built-in map.
pub fn lab_xml(name: &str) -> Option<&'static str> {
    match name {
        "liacc" => Some(LIACC_LAB),
        "thesis" => Some(THESIS_LAB),
        "maze" => Some(MAZE_LAB),
        "ward" => Some(WARD_LAB),
        _ => None,
    }
}

/// The grid XML of a built-in map.
pub fn grid_xml(name: &str) -> Option<&'static str> {
    match name {
        "liacc" => Some(LIACC_GRID),
        "thesis" => Some(THESIS_GRID),
        "maze" => Some(MAZE_GRID),
        "ward" => Some(WARD_GRID),
        _ => None,
    }
}

/// A built-in map, lab and grid parsed; `None` for an unknown name.
pub fn map(name: &str) -> Option<Map> {
    let parsed = (|| -> Result<Map, MapLoadError> {
        let lab = parse_lab(lab_xml(name).ok_or_else(|| unknown(name))?)?;
        let grid = parse_grid(grid_xml(name).ok_or_else(|| unknown(name))?)?;
        Ok(Map { lab, grid })
    })();
    match parsed {
        Ok(map) => Some(map),
        Err(MapLoadError::UnknownBuiltin { .. }) => None,
        Err(err) => {
            // The shipped files are tested to parse; this is only reachable by a broken build.
            tracing::error!("built-in map {name:?} does not load: {err}");
            None
        }
    }
}

/// Loads a lab from `builtin:NAME` or from a file path.
pub fn load_lab_spec(spec: &str) -> Result<Lab, MapLoadError> {
    match spec.strip_prefix(PREFIX) {
        Some(name) => parse_lab(lab_xml(name).ok_or_else(|| unknown(name))?),
        None => parse_lab(&read_text(Path::new(spec))?),
    }
}

/// Loads a start grid for `lab` from `builtin:NAME` or from a file path; every position must
/// lie inside the lab.
pub fn load_grid_spec(spec: &str, lab: &Lab) -> Result<Grid, MapLoadError> {
    match spec.strip_prefix(PREFIX) {
        Some(name) => parse_grid_for(grid_xml(name).ok_or_else(|| unknown(name))?, lab),
        None => parse_grid_for(&read_text(Path::new(spec))?, lab),
    }
}

fn unknown(name: &str) -> MapLoadError {
    MapLoadError::UnknownBuiltin { name: name.to_owned(), known: NAMES.join(", ") }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::Wall;
    use crate::map::pattern::CELL_M;

    fn load(name: &str) -> Map {
        match map(name) {
            Some(map) => map,
            None => panic!("built-in map {name} does not load: {:?}", lab_xml(name).map(parse_lab)),
        }
    }

    /// (min x, min y, max x, max y) of a wall.
    fn bbox(wall: &Wall) -> (f64, f64, f64, f64) {
        wall.corners
            .iter()
            .fold((f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY), |(x0, y0, x1, y1), c| {
                (x0.min(c.x), y0.min(c.y), x1.max(c.x), y1.max(c.y))
            })
    }

    /// Walls whose bounding box overlaps the open rectangle (x0, y0)–(x1, y1), by index.
    fn walls_touching(lab: &Lab, x0: f64, y0: f64, x1: f64, y1: f64) -> Vec<usize> {
        lab.walls
            .iter()
            .enumerate()
            .filter(|(_, wall)| {
                let (wx0, wy0, wx1, wy1) = bbox(wall);
                wx0 < x1 && x0 < wx1 && wy0 < y1 && y0 < wy1
            })
            .map(|(i, _)| i)
            .collect()
    }

    /// The 1 m × 1 m chair at a start pose with heading 0, as (x0, y0, x1, y1).
    fn unit_square(x: f64, y: f64) -> (f64, f64, f64, f64) {
        (x - 0.5, y - 0.5, x + 0.5, y + 0.5)
    }

    fn assert_poses_inside_lab(map: &Map) {
        for pose in &map.grid.poses {
            let (x0, y0, x1, y1) = unit_square(pose.pos.x, pose.pos.y);
            assert!(
                x0 >= 0.0 && y0 >= 0.0 && x1 <= map.lab.width_m && y1 <= map.lab.height_m,
                "{pose:?} sticks out of the lab"
            );
        }
    }

    #[test]
    fn every_builtin_map_loads_with_walls_and_start_poses() {
        for name in NAMES {
            let map = load(name);
            assert!(!map.lab.walls.is_empty(), "{name}");
            assert!(map.grid.poses.len() >= 3, "{name}");
        }
    }

    #[test]
    fn an_unknown_name_has_no_map_and_no_xml() {
        assert!(map("atlantis").is_none());
        assert!(lab_xml("atlantis").is_none());
        assert!(grid_xml("atlantis").is_none());
    }

    #[test]
    fn liacc_is_thesis_annex_d_with_its_23_walls() {
        let lab = load("liacc").lab;
        assert_eq!(lab.name, "IW_LIACC");
        assert_eq!((lab.width_m, lab.height_m), (44.0, 17.75));
        assert_eq!(lab.walls.len(), 23);
        assert!(lab.walls.iter().all(|w| w.corners.len() == 4 && w.height_m == 2.5));
        assert!(lab.beacons.is_empty() && lab.targets.is_empty());
        // First and last walls as printed in Annex D.
        assert_eq!(bbox(&lab.walls[0]), (9.37, 0.0, 9.519, 5.4));
        assert_eq!(bbox(&lab.walls[22]), (32.69, 7.21, 32.84, 11.75));
        // The long corridor of the slalom: its south wall (10.4159–32.84, 4.9903–5.1304).
        assert_eq!(bbox(&lab.walls[2]), (10.4159, 4.9903, 32.84, 5.1304));
    }

    #[test]
    fn liacc_grid_starts_at_checkpoint_one_of_the_slalom() {
        let grid = load("liacc").grid;
        assert_eq!(grid.poses[0].pos, nalgebra::Point2::new(10.0, 6.1));
        assert_eq!(grid.poses[0].heading_deg, 0.0);
        assert!(grid.poses.len() >= 6);
    }

    #[test]
    fn liacc_start_poses_leave_a_unit_chair_clear_of_every_wall() {
        let map = load("liacc");
        assert_poses_inside_lab(&map);
        for (k, pose) in map.grid.poses.iter().enumerate() {
            let (x0, y0, x1, y1) = unit_square(pose.pos.x, pose.pos.y);
            let hits = walls_touching(&map.lab, x0, y0, x1, y1);
            if k == 0 {
                // Checkpoint 1 is the thesis's own (10.0, 6.1): a 1 m chair there grazes the
                // jamb of Annex D's 4th wall (x 9.37–9.519, y 6.59–7.66) by 19 mm × 10 mm.
                // Pin that down so that any other overlap fails.
                assert_eq!(hits, [3], "checkpoint 1 touches {hits:?}");
                let (_, wy0, wx1, _) = bbox(&map.lab.walls[3]);
                assert!(wx1 - x0 < 0.02 && y1 - wy0 < 0.011);
            } else {
                assert!(hits.is_empty(), "start pose {} {pose:?} touches walls {hits:?}", k + 1);
            }
        }
    }

    #[test]
    fn thesis_map_is_annex_a() {
        let map = load("thesis");
        let lab = &map.lab;
        assert_eq!(lab.name, "ThesisExampleMap");
        assert_eq!((lab.width_m, lab.height_m), (28.0, 14.0));
        assert_eq!(lab.walls.len(), 2);
        assert_eq!(lab.walls[0].corners.len(), 4);
        assert_eq!(lab.walls[0].height_m, 2.5);
        assert_eq!(lab.walls[1].corners.len(), 6, "the L-shaped wall");
        assert_eq!(lab.walls[1].height_m, 1.0);
        assert_eq!(bbox(&lab.walls[1]), (16.5, 5.5, 21.0, 10.0));
        assert_eq!(lab.beacons.len(), 1);
        assert_eq!(lab.beacons[0].pos, nalgebra::Point2::new(25.0, 7.0));
        assert_eq!(lab.beacons[0].height_m, 30.0);
        assert_eq!(lab.targets.len(), 1);
        assert_eq!(lab.targets[0].radius_m, 1.5);
    }

    #[test]
    fn thesis_start_poses_leave_a_unit_chair_clear_of_every_wall() {
        let map = load("thesis");
        assert_poses_inside_lab(&map);
        for pose in &map.grid.poses {
            let (x0, y0, x1, y1) = unit_square(pose.pos.x, pose.pos.y);
            assert_eq!(walls_touching(&map.lab, x0, y0, x1, y1), Vec::<usize>::new(), "{pose:?}");
        }
    }

    /// Cell count of the maze: 14 × 7 cells of 2 m.
    const MAZE_COLS: usize = 14;
    const MAZE_ROWS: usize = 7;

    /// Whether a 1 m wide chair can drive straight between the centres of two neighbouring
    /// cells without its footprint touching a wall.
    fn passage_open(lab: &Lab, (i, j): (usize, usize), (k, l): (usize, usize)) -> bool {
        let centre = |c: usize| CELL_M * c as f64 + CELL_M / 2.0;
        let (ax, ay, bx, by) = (centre(i), centre(j), centre(k), centre(l));
        let (x0, y0, x1, y1) = if ay == by {
            (ax.min(bx), ay - 0.5, ax.max(bx), ay + 0.5)
        } else {
            (ax - 0.5, ay.min(by), ax + 0.5, ay.max(by))
        };
        walls_touching(lab, x0, y0, x1, y1).is_empty()
    }

    #[test]
    fn maze_is_28_by_14_with_one_beacon_and_one_target() {
        let lab = load("maze").lab;
        assert_eq!((lab.width_m, lab.height_m), (28.0, 14.0));
        assert_eq!(lab.beacons.len(), 1);
        assert_eq!(lab.targets.len(), 1);
        assert!(lab.walls.len() > 20);
    }

    #[test]
    fn every_maze_cell_is_reachable_from_the_first_start_cell() {
        let map = load("maze");
        let start = map.grid.poses[0].pos;
        let start = ((start.x / CELL_M) as usize, (start.y / CELL_M) as usize);
        let mut seen = [[false; MAZE_ROWS]; MAZE_COLS];
        let mut todo = vec![start];
        seen[start.0][start.1] = true;
        let mut reached = 1;
        while let Some((i, j)) = todo.pop() {
            let mut next = Vec::new();
            if i + 1 < MAZE_COLS {
                next.push((i + 1, j));
            }
            if i > 0 {
                next.push((i - 1, j));
            }
            if j + 1 < MAZE_ROWS {
                next.push((i, j + 1));
            }
            if j > 0 {
                next.push((i, j - 1));
            }
            for (k, l) in next {
                if !seen[k][l] && passage_open(&map.lab, (i, j), (k, l)) {
                    seen[k][l] = true;
                    reached += 1;
                    todo.push((k, l));
                }
            }
        }
        assert_eq!(reached, MAZE_COLS * MAZE_ROWS, "unreached cells: {seen:?}");
    }

    #[test]
    fn maze_is_a_maze_not_an_open_floor() {
        let lab = load("maze").lab;
        let mut closed = 0;
        for i in 0..MAZE_COLS {
            for j in 0..MAZE_ROWS {
                if i + 1 < MAZE_COLS && !passage_open(&lab, (i, j), (i + 1, j)) {
                    closed += 1;
                }
                if j + 1 < MAZE_ROWS && !passage_open(&lab, (i, j), (i, j + 1)) {
                    closed += 1;
                }
            }
        }
        // 13·7 + 14·6 = 175 inner boundaries; a spanning tree opens 97 of them, and the maze
        // opens twelve more.
        assert_eq!(closed, 175 - 97 - 12);
    }

    #[test]
    fn maze_start_cells_beacon_and_target_sit_at_cell_centres_clear_of_walls() {
        let map = load("maze");
        assert_poses_inside_lab(&map);
        let points = map
            .grid
            .poses
            .iter()
            .map(|p| p.pos)
            .chain(map.lab.beacons.iter().map(|b| b.pos))
            .chain(map.lab.targets.iter().map(|t| t.pos));
        for p in points {
            assert_eq!(((p.x - 1.0) % CELL_M, (p.y - 1.0) % CELL_M), (0.0, 0.0), "{p:?}");
            let (x0, y0, x1, y1) = unit_square(p.x, p.y);
            assert!(walls_touching(&map.lab, x0, y0, x1, y1).is_empty(), "{p:?}");
        }
    }

    #[test]
    fn specs_name_a_builtin_or_a_file() {
        let lab = load_lab_spec("builtin:thesis").expect("built in");
        assert_eq!(lab.name, "ThesisExampleMap");
        let grid = load_grid_spec("builtin:maze", &lab).expect("built in");
        assert_eq!(grid.poses.len(), 4);

        let dir = std::env::temp_dir().join(format!("iwsim-map-spec-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let file = dir.join("lab.xml");
        std::fs::write(&file, THESIS_LAB).expect("write temp file");
        let from_file = load_lab_spec(file.to_str().expect("utf-8 temp path"));
        std::fs::remove_dir_all(&dir).expect("clean up");
        assert_eq!(from_file.expect("file loads"), lab);
    }

    #[test]
    fn an_unknown_builtin_spec_lists_the_known_names() {
        let err = load_lab_spec("builtin:atlantis").expect_err("no such map");
        assert!(matches!(&err, MapLoadError::UnknownBuiltin { name, .. } if name == "atlantis"));
        assert!(err.to_string().contains("liacc, thesis, maze"), "{err}");
        assert!(matches!(load_grid_spec("builtin:", &load("liacc").lab), Err(MapLoadError::UnknownBuiltin { .. })));
    }

    #[test]
    fn a_missing_file_spec_is_an_io_error_naming_the_file() {
        let err = load_grid_spec("/nonexistent/iwsim/grid.xml", &load("liacc").lab).expect_err("no such file");
        assert!(matches!(&err, MapLoadError::Io { path, .. } if path.ends_with("grid.xml")));
        assert!(err.to_string().contains("/nonexistent/iwsim/grid.xml"), "{err}");
    }
}
