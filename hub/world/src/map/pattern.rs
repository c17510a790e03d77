//! Ciber-Rato's `<Row Pos Pattern>` maze shorthand, expanded into wall rectangles.
//!
//! A maze lab is a grid of 2 m × 2 m cells, three pattern characters per cell. Each `<Row>`
//! describes one band of the lab, bottom up by `Pos`:
//!
//! - a `|` at column `c` is a vertical wall at x = 2·(c+1)/3, from y = Pos to y = Pos + 2
//!   (it separates two cells of the cell row that starts at y = Pos);
//! - on an odd `Pos` only, a run of `-` read at the columns that are multiples of 3 is a
//!   horizontal wall at y = Pos + 1, from the left edge of the run's first cell to the right edge
//!   of its last cell.
//!
//! Every wall is 0.2 m thick (±0.1 m about its centre line). Other characters — the `+` or `*`
//! some labs put at junctions, and iris's diagonal `/` and `\` — carry no wall here.
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

    if pos.rem_euclid(2) == 1 {
        let y = y0 + 1.0;
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
    fn dashes_in_an_even_row_make_no_wall() {
        assert!(expand_row(4, "--+--+--+--", 4.0).is_empty());
    }

    #[test]
    fn only_dashes_at_multiples_of_three_start_or_end_a_run() {
        // Column 1 and 2 hold '-' but column 3 is a space: the run is cell 0 only.
        // Column 7 holds '-' but column 6 does not: no wall for cell 2.
        let walls = expand_row(1, "---    -  ", 4.0);
        assert_eq!(walls.iter().map(bounds).collect::<Vec<_>>(), [(0.0, 1.9, 2.0, 2.1)]);
    }

    #[test]
    fn junction_and_diagonal_characters_make_no_wall() {
        assert!(expand_row(5, "  +  *  /  \\  +", 4.0).is_empty());
        assert!(expand_row(6, "  +  *  /  \\  +", 4.0).is_empty());
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
