//! Ciber-Rato's `<Row Pos Pattern>` maze shorthand, expanded into wall rectangles.
//!
//! A maze lab is a grid of 2 m × 2 m cells, three pattern characters per cell. Each `<Row>`
//! describes one band of the lab, bottom up by `Pos`:
//!
//! - a `|` at column `c` is a vertical wall at x = 2·(c+1)/3, from y = Pos to y = Pos + 2
//!   (it separates two cells of the cell row that starts at y = Pos);
//! - a run of `-` read at the columns that are multiples of 3 is a horizontal wall at
//!   y = Pos + 1, from the left edge of the run's first cell to the right edge of its last
//!   cell; on an even `Pos` (through the middles of cells) it is a line on the floor, of height
//!   0, whatever the row's height, as the real simulator makes it;
//! - a `/` or `\` at column `c` is a 45° wall from (2c/3, Pos) to (2c/3 + 2, Pos + 2), or from
//!   (2c/3, Pos + 2) to (2c/3 + 2, Pos): the diagonal paths of iris's line labs.
//!
//! Every wall is 0.2 m thick (±0.1 m about its centre line). Other characters (the `+` or `*`
//! some labs put at junctions) carry no wall. Line labs give their rows `Height="0"`, so all
//! their walls are lines (see [`crate::map::Wall`]).
//!
//! For a 28 m × 14 m lab (14 × 7 cells) the rows run from `Pos="0"` to `Pos="12"` and the
//! patterns are 41 characters long.

use super::Wall;

/// Side of one maze cell, metres (Ciber-Rato's `PATHCUBESIZE`).
pub const CELL_M: f64 = 2.0;

/// Half the thickness of a maze wall, metres.
pub const HALF_THICKNESS_M: f64 = 0.1;

/// Pattern characters per cell.
const COLUMNS_PER_CELL: usize = 3;

/// Expands one `<Row Pos Pattern>` into its walls, each a rectangle with corners
/// counter-clockwise, `height_m` tall. Walls come out left to right, the vertical ones first.
///
/// ```
/// let walls = world::map::pattern::expand_row(12, "           |", 4.0);
/// let xs: Vec<f64> = walls[0].corners.iter().map(|c| c.x).collect();
/// assert_eq!(xs, [7.9, 8.1, 8.1, 7.9]);
/// ```
pub fn expand_row(pos: i64, pattern: &str, height_m: f64) -> Vec<Wall> {
    let cells: Vec<char> = pattern.chars().collect();
    let y0 = pos as f64;
    let mut walls = Vec::new();

    for (column, _) in cells.iter().enumerate().filter(|(_, ch)| **ch == '|') {
        let x = CELL_M * (column as f64 + 1.0) / COLUMNS_PER_CELL as f64;
        walls.push(rectangle(x - HALF_THICKNESS_M, y0, x + HALF_THICKNESS_M, y0 + CELL_M, height_m));
    }
    for (column, &ch) in cells.iter().enumerate().filter(|(_, ch)| **ch == '/' || **ch == '\\') {
        let x0 = CELL_M * column as f64 / COLUMNS_PER_CELL as f64;
        let (from, to) = if ch == '/' { (y0, y0 + CELL_M) } else { (y0 + CELL_M, y0) };
        walls.push(bar(x0, from, x0 + CELL_M, to, height_m));
    }

    {
        let y = y0 + 1.0;
        // Through the middles of cells: a line on the floor.
        let height_m = if pos.rem_euclid(2) == 1 { height_m } else { 0.0 };
        let mut push_run = |first: usize, last: usize| {
            let x0 = CELL_M * (first / COLUMNS_PER_CELL) as f64;
            let x1 = CELL_M * (last / COLUMNS_PER_CELL + 1) as f64;
            walls.push(rectangle(x0, y - HALF_THICKNESS_M, x1, y + HALF_THICKNESS_M, height_m));
        };
        // (first column of the run, last column of the run that holds '-')
        let mut run: Option<(usize, usize)> = None;
        for (column, ch) in cells.iter().enumerate().step_by(COLUMNS_PER_CELL) {
            match (*ch == '-', run) {
                (true, None) => run = Some((column, column)),
                (true, Some((first, _))) => run = Some((first, column)),
                (false, Some((first, last))) => {
                    push_run(first, last);
                    run = None;
                }
                (false, None) => {}
            }
        }
        if let Some((first, last)) = run {
            push_run(first, last);
        }
    }
    walls
}

/// A wall [`HALF_THICKNESS_M`] either side of the segment (x0, y0)–(x1, y1), its corners
/// counter-clockwise.
fn bar(x0: f64, y0: f64, x1: f64, y1: f64, height_m: f64) -> Wall {
    let (dx, dy) = (x1 - x0, y1 - y0);
    let len = dx.hypot(dy);
    // The left normal, scaled to the half thickness.
    let (nx, ny) = (-dy / len * HALF_THICKNESS_M, dx / len * HALF_THICKNESS_M);
    let p = nalgebra::Point2::new;
    Wall { height_m, corners: vec![p(x0 - nx, y0 - ny), p(x1 - nx, y1 - ny), p(x1 + nx, y1 + ny), p(x0 + nx, y0 + ny)] }
}

fn rectangle(x0: f64, y0: f64, x1: f64, y1: f64, height_m: f64) -> Wall {
    Wall::rectangle(x0, y0, x1, y1, height_m)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// (x0, y0, x1, y1) of a rectangle wall, rounded to micrometres for comparison.
    fn bounds(wall: &Wall) -> (f64, f64, f64, f64) {
        let round = |v: f64| (v * 1e6).round() / 1e6;
        let xs = wall.corners.iter().map(|c| c.x);
        let ys = wall.corners.iter().map(|c| c.y);
        (
            round(xs.clone().fold(f64::INFINITY, f64::min)),
            round(ys.clone().fold(f64::INFINITY, f64::min)),
            round(xs.fold(f64::NEG_INFINITY, f64::max)),
            round(ys.fold(f64::NEG_INFINITY, f64::max)),
        )
    }

    fn signed_area(wall: &Wall) -> f64 {
        let c = &wall.corners;
        (0..c.len())
            .map(|i| {
                let (a, b) = (c[i], c[(i + 1) % c.len()]);
                a.x * b.y - b.x * a.y
            })
            .sum::<f64>()
            / 2.0
    }

    #[test]
    fn bar_at_column_11_of_row_12_is_the_wall_seen_on_the_real_c1_lab() {
        let walls = expand_row(12, "           |                             ", 4.0);
        assert_eq!(walls.len(), 1);
        assert_eq!(bounds(&walls[0]), (7.9, 12.0, 8.1, 14.0));
        assert_eq!(walls[0].height_m, 4.0);
    }

    #[test]
    fn every_bar_of_an_even_row_is_a_vertical_wall_two_metres_tall() {
        let walls = expand_row(0, "  |  |                                |  ", 1.5);
        let got: Vec<_> = walls.iter().map(bounds).collect();
        assert_eq!(got, [(1.9, 0.0, 2.1, 2.0), (3.9, 0.0, 4.1, 2.0), (25.9, 0.0, 26.1, 2.0)]);
        assert!(walls.iter().all(|w| w.height_m == 1.5));
    }

    #[test]
    fn dashes_in_an_odd_row_make_one_horizontal_wall_per_run_of_cells() {
        // Cells 0-1 walled, cell 2 open, cells 3 and 13 walled.
        let pattern = format!("--+--+  +--+{}--", " ".repeat(27));
        assert_eq!(pattern.chars().count(), 41);
        let walls = expand_row(3, &pattern, 4.0);
        let got: Vec<_> = walls.iter().map(bounds).collect();
        assert_eq!(got, [(0.0, 3.9, 4.0, 4.1), (6.0, 3.9, 8.0, 4.1), (26.0, 3.9, 28.0, 4.1)]);
    }

    #[test]
    fn a_full_row_of_dashes_spans_the_whole_lab() {
        let pattern = "-".repeat(41);
        let walls = expand_row(11, &pattern, 4.0);
        assert_eq!(walls.iter().map(bounds).collect::<Vec<_>>(), [(0.0, 11.9, 28.0, 12.1)]);
    }

    #[test]
    fn dashes_in_an_even_row_make_a_line_through_the_middles_of_cells() {
        let walls = expand_row(4, "--+--+--+--", 4.0);
        assert_eq!(walls.iter().map(bounds).collect::<Vec<_>>(), [(0.0, 4.9, 8.0, 5.1)]);
        assert_eq!(walls[0].height_m, 0.0, "a line on the floor, whatever the row's height");
    }

    #[test]
    fn only_dashes_at_multiples_of_three_start_or_end_a_run() {
        // Column 1 and 2 hold '-' but column 3 is a space: the run is cell 0 only.
        // Column 7 holds '-' but column 6 does not: no wall for cell 2.
        let walls = expand_row(1, "---    -  ", 4.0);
        assert_eq!(walls.iter().map(bounds).collect::<Vec<_>>(), [(0.0, 1.9, 2.0, 2.1)]);
    }

    #[test]
    fn junction_characters_make_no_wall() {
        assert!(expand_row(5, "  +  *     +", 4.0).is_empty());
        assert!(expand_row(6, "  +  *     +", 4.0).is_empty());
    }

    #[test]
    fn slashes_make_diagonal_walls_across_two_metres() {
        // Column 6: from x = 4; '/' rises to the right, '\' falls.
        let rising = expand_row(6, "      /", 0.0);
        let falling = expand_row(6, "      \\", 0.0);
        let k = 0.1 * std::f64::consts::FRAC_1_SQRT_2;
        let r = |v: f64| (v * 1e6).round() / 1e6;
        assert_eq!(bounds(&rising[0]), (r(4.0 - k), r(6.0 - k), r(6.0 + k), r(8.0 + k)));
        assert_eq!(bounds(&falling[0]), bounds(&rising[0]));
        // The rising bar holds (5, 7) and (4.1, 6.1) and not (5, 6.5); the falling bar (5, 7) and
        // (4.1, 7.9).
        let inside = |w: &Wall, x: f64, y: f64| {
            let c = &w.corners;
            (0..c.len()).all(|i| {
                let (a, b) = (c[i], c[(i + 1) % c.len()]);
                (b.x - a.x) * (y - a.y) - (b.y - a.y) * (x - a.x) >= 0.0
            })
        };
        assert!(inside(&rising[0], 5.0, 7.0) && inside(&rising[0], 4.1, 6.1) && !inside(&rising[0], 5.0, 6.5));
        assert!(inside(&falling[0], 5.0, 7.0) && inside(&falling[0], 4.1, 7.9) && !inside(&falling[0], 4.1, 6.1));
        assert!(signed_area(&rising[0]) > 0.0 && signed_area(&falling[0]) > 0.0);
    }

    #[test]
    fn a_row_with_bars_and_dashes_gives_both_kinds_of_wall() {
        let walls = expand_row(1, "--|", 4.0);
        let got: Vec<_> = walls.iter().map(bounds).collect();
        assert_eq!(got, [(1.9, 1.0, 2.1, 3.0), (0.0, 1.9, 2.0, 2.1)]);
    }

    #[test]
    fn expanded_walls_are_counter_clockwise() {
        let walls = expand_row(7, "--+  |--+--", 4.0);
        assert_eq!(walls.len(), 3);
        for wall in &walls {
            assert_eq!(wall.corners.len(), 4);
            assert!(signed_area(wall) > 0.0, "{wall:?}");
        }
    }

    #[test]
    fn an_empty_pattern_gives_no_walls() {
        assert!(expand_row(1, "", 4.0).is_empty());
        assert!(expand_row(2, "", 4.0).is_empty());
    }
}
