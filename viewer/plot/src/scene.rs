//! What is drawn under the trajectory: the lab, the scenario's obstacles and checkpoints, read
//! from the command line or from the run's `summary.json`; and the window of the floor shown.

use std::path::{Path, PathBuf};

use world::map::Lab;

/// Height of an obstacle that does not give one, metres (as `iwsim hub --obstacle`).
pub const DEFAULT_OBSTACLE_HEIGHT_M: f64 = 1.0;
/// Radius of a checkpoint that does not give one, metres (as `iwsim hub --checkpoint`).
pub const DEFAULT_CHECKPOINT_RADIUS_M: f64 = 0.5;
/// Floor shown around the trajectory, metres.
pub const MARGIN_M: f64 = 1.5;

/// A scenario obstacle: an axis-aligned box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Obstacle {
    /// Lower-left corner x, metres.
    pub x0: f64,
    /// Lower-left corner y, metres.
    pub y0: f64,
    /// Upper-right corner x, metres.
    pub x1: f64,
    /// Upper-right corner y, metres.
    pub y1: f64,
    /// Height, metres.
    pub height_m: f64,
}

/// A scenario checkpoint: a circle the route passes through, in order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Checkpoint {
    /// Centre x, metres.
    pub x_m: f64,
    /// Centre y, metres.
    pub y_m: f64,
    /// Radius, metres.
    pub radius_m: f64,
}

/// Why an `X0,Y0,X1,Y1[,H]` or `X,Y[,R]` list is refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ScenarioParseError {
    /// An item is not a finite number.
    #[error("`{spec}`: item {item} is not a finite number")]
    NotANumber {
        /// The list as given.
        spec: String,
        /// The item, counting from 1.
        item: usize,
    },
    /// Too few or too many numbers.
    #[error("`{spec}`: {found} numbers, expected {expected}")]
    Count {
        /// The list as given.
        spec: String,
        /// How many were given.
        found: usize,
        /// What the list wants, in words.
        expected: &'static str,
    },
    /// The box is empty or upside down, or the height or radius not positive.
    #[error("`{spec}`: {what}")]
    Shape {
        /// The list as given.
        spec: String,
        /// What is wrong.
        what: &'static str,
    },
}

impl Obstacle {
    /// Parses `X0,Y0,X1,Y1[,H]` (the `--obstacle` syntax of `iwsim hub`).
    pub fn parse(spec: &str) -> Result<Self, ScenarioParseError> {
        let v = numbers(spec)?;
        Self::from_numbers(&v, spec)
    }

    fn from_numbers(v: &[f64], spec: &str) -> Result<Self, ScenarioParseError> {
        if !(4..=5).contains(&v.len()) {
            return Err(ScenarioParseError::Count {
                spec: spec.into(),
                found: v.len(),
                expected: "4 or 5 (X0,Y0,X1,Y1[,H])",
            });
        }
        let o = Self {
            x0: v[0],
            y0: v[1],
            x1: v[2],
            y1: v[3],
            height_m: v.get(4).copied().unwrap_or(DEFAULT_OBSTACLE_HEIGHT_M),
        };
        if !(o.x0 < o.x1 && o.y0 < o.y1 && o.height_m > 0.0) {
            return Err(ScenarioParseError::Shape {
                spec: spec.into(),
                what: "want X0 < X1, Y0 < Y1 and a positive height",
            });
        }
        Ok(o)
    }
}

impl Checkpoint {
    /// Parses `X,Y[,R]` (the `--checkpoint` syntax of `iwsim hub`).
    pub fn parse(spec: &str) -> Result<Self, ScenarioParseError> {
        let v = numbers(spec)?;
        Self::from_numbers(&v, spec)
    }

    fn from_numbers(v: &[f64], spec: &str) -> Result<Self, ScenarioParseError> {
        if !(2..=3).contains(&v.len()) {
            return Err(ScenarioParseError::Count { spec: spec.into(), found: v.len(), expected: "2 or 3 (X,Y[,R])" });
        }
        let c = Self { x_m: v[0], y_m: v[1], radius_m: v.get(2).copied().unwrap_or(DEFAULT_CHECKPOINT_RADIUS_M) };
        if c.radius_m <= 0.0 {
            return Err(ScenarioParseError::Shape { spec: spec.into(), what: "the radius must be positive" });
        }
        Ok(c)
    }
}

fn numbers(spec: &str) -> Result<Vec<f64>, ScenarioParseError> {
    spec.split(',')
        .enumerate()
        .map(|(k, t)| {
            t.trim()
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| ScenarioParseError::NotANumber { spec: spec.into(), item: k + 1 })
        })
        .collect()
}

/// The keys of a run's `summary.json` that the plot uses; each is `None` when absent.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Summary {
    /// `"lab"`: the lab spec of the run (`builtin:liacc` or a file).
    pub lab: Option<String>,
    /// `"obstacles"`: `[[X0,Y0,X1,Y1,H], …]`.
    pub obstacles: Option<Vec<Obstacle>>,
    /// `"checkpoints"`: `[[X,Y,R], …]`.
    pub checkpoints: Option<Vec<Checkpoint>>,
}

/// Why a `summary.json` could not be used.
#[derive(Debug, thiserror::Error)]
pub enum SummaryReadError {
    /// The file could not be read.
    #[error("{}: cannot read: {source}", .path.display())]
    Io {
        /// The summary file.
        path: PathBuf,
        /// What the system said.
        source: std::io::Error,
    },
    /// The file is not JSON.
    #[error("{}:{line}:{column}: not JSON: {message}", .path.display())]
    Json {
        /// The summary file.
        path: PathBuf,
        /// Line of the problem, from 1.
        line: usize,
        /// Column of the problem, from 1.
        column: usize,
        /// What serde_json said.
        message: String,
    },
    /// A key the plot uses has the wrong shape.
    #[error("{}: key `{key}`: {message}", .path.display())]
    Key {
        /// The summary file.
        path: PathBuf,
        /// The key, with the index of the item where that applies (`obstacles[2]`).
        key: String,
        /// What is wrong.
        message: String,
    },
}

impl Summary {
    /// Reads the keys the plot uses from the `summary.json` at `path`.
    pub fn read(path: &Path) -> Result<Self, SummaryReadError> {
        let text =
            std::fs::read_to_string(path).map_err(|source| SummaryReadError::Io { path: path.into(), source })?;
        Self::parse(&text, path)
    }

    /// Parses the text of a `summary.json`; `path` only names the file in errors. Keys other
    /// than `lab`, `obstacles` and `checkpoints` are ignored.
    pub fn parse(text: &str, path: &Path) -> Result<Self, SummaryReadError> {
        let root: serde_json::Value = serde_json::from_str(text).map_err(|e| SummaryReadError::Json {
            path: path.into(),
            line: e.line(),
            column: e.column(),
            message: e.to_string(),
        })?;
        let key_err = |key: String, message: String| SummaryReadError::Key { path: path.into(), key, message };
        let root = root.as_object().ok_or_else(|| key_err("(top level)".into(), "expected a JSON object".into()))?;
        let lab = match root.get("lab") {
            None | Some(serde_json::Value::Null) => None,
            Some(v) => Some(v.as_str().ok_or_else(|| key_err("lab".into(), "expected a string".into()))?.to_owned()),
        };
        let lists = |key: &str| -> Result<Option<Vec<NamedNumbers>>, SummaryReadError> {
            let Some(v) = root.get(key) else { return Ok(None) };
            let items = v.as_array().ok_or_else(|| key_err(key.into(), "expected an array of arrays".into()))?;
            let mut out = Vec::with_capacity(items.len());
            for (k, item) in items.iter().enumerate() {
                let name = format!("{key}[{k}]");
                let numbers: Option<Vec<f64>> = item
                    .as_array()
                    .map(|a| a.iter().map(|x| x.as_f64().filter(|x| x.is_finite())).collect::<Option<Vec<f64>>>())
                    .unwrap_or(None);
                let numbers = numbers.ok_or_else(|| key_err(name.clone(), "expected an array of numbers".into()))?;
                out.push((name, numbers));
            }
            Ok(Some(out))
        };
        let obstacles = lists("obstacles")?
            .map(|items| {
                items
                    .iter()
                    .map(|(name, v)| Obstacle::from_numbers(v, name).map_err(|e| key_err(name.clone(), e.to_string())))
                    .collect::<Result<Vec<_>, _>>()
            })
            .transpose()?;
        let checkpoints = lists("checkpoints")?
            .map(|items| {
                items
                    .iter()
                    .map(|(name, v)| {
                        Checkpoint::from_numbers(v, name).map_err(|e| key_err(name.clone(), e.to_string()))
                    })
                    .collect::<Result<Vec<_>, _>>()
            })
            .transpose()?;
        Ok(Self { lab, obstacles, checkpoints })
    }
}

/// An item of a summary list, named for errors (`obstacles[2]`), and its numbers.
type NamedNumbers = (String, Vec<f64>);

/// Everything drawn under the trajectory.
#[derive(Debug, Clone, Default)]
pub struct Scene {
    /// The lab (outline, walls, beacons, targets), if one is known.
    pub lab: Option<Lab>,
    /// Scenario obstacles, drawn with letters A, B, … in this order.
    pub obstacles: Vec<Obstacle>,
    /// Scenario checkpoints, numbered 1, 2, … in this order.
    pub checkpoints: Vec<Checkpoint>,
}

/// A window of the floor, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// Left edge.
    pub x0: f64,
    /// Right edge.
    pub x1: f64,
    /// Bottom edge.
    pub y0: f64,
    /// Top edge.
    pub y1: f64,
}

impl View {
    /// Width, metres.
    pub fn width(&self) -> f64 {
        self.x1 - self.x0
    }

    /// Height, metres.
    pub fn height(&self) -> f64 {
        self.y1 - self.y0
    }

    /// Whether a point lies inside (edges included).
    pub fn contains(&self, x: f64, y: f64) -> bool {
        (self.x0..=self.x1).contains(&x) && (self.y0..=self.y1).contains(&y)
    }

    /// The window to draw: the bounding box of `points` and of the checkpoints, plus
    /// [`MARGIN_M`], kept inside the lab (unless the points themselves leave it).
    pub fn around(points: impl IntoIterator<Item = (f64, f64)>, scene: &Scene) -> Self {
        let mut v = View { x0: f64::INFINITY, x1: f64::NEG_INFINITY, y0: f64::INFINITY, y1: f64::NEG_INFINITY };
        let mut grow = |x: f64, y: f64| {
            v.x0 = v.x0.min(x);
            v.x1 = v.x1.max(x);
            v.y0 = v.y0.min(y);
            v.y1 = v.y1.max(y);
        };
        for (x, y) in points {
            grow(x, y);
        }
        for c in &scene.checkpoints {
            grow(c.x_m - c.radius_m, c.y_m - c.radius_m);
            grow(c.x_m + c.radius_m, c.y_m + c.radius_m);
        }
        if !v.x0.is_finite() {
            v = View { x0: 0.0, x1: 0.0, y0: 0.0, y1: 0.0 };
        }
        let bounds = v.bounds(scene);
        let mut v = View { x0: v.x0 - MARGIN_M, x1: v.x1 + MARGIN_M, y0: v.y0 - MARGIN_M, y1: v.y1 + MARGIN_M };
        if let Some(b) = bounds {
            v = v.clamped(&b);
        }
        v
    }

    /// How far a view may reach: the lab, or further where this window leaves it; `None`
    /// without a lab.
    pub fn bounds(&self, scene: &Scene) -> Option<View> {
        scene.lab.as_ref().map(|lab| View {
            x0: self.x0.min(0.0),
            x1: self.x1.max(lab.width_m),
            y0: self.y0.min(0.0),
            y1: self.y1.max(lab.height_m),
        })
    }

    /// The window grown to `width` × `height` about its centre, shifted to stay inside
    /// `bounds` and cut where `bounds` is smaller.
    pub fn grown_to(&self, width: f64, height: f64, bounds: Option<&View>) -> Self {
        let grow = |lo: f64, hi: f64, size: f64, b: Option<(f64, f64)>| -> (f64, f64) {
            let extra = (size - (hi - lo)).max(0.0) / 2.0;
            let (mut lo, mut hi) = (lo - extra, hi + extra);
            if let Some((blo, bhi)) = b {
                if lo < blo {
                    hi += blo - lo;
                    lo = blo;
                }
                if hi > bhi {
                    lo -= hi - bhi;
                    hi = bhi;
                }
                lo = lo.max(blo);
            }
            (lo, hi)
        };
        let (x0, x1) = grow(self.x0, self.x1, width, bounds.map(|b| (b.x0, b.x1)));
        let (y0, y1) = grow(self.y0, self.y1, height, bounds.map(|b| (b.y0, b.y1)));
        View { x0, x1, y0, y1 }
    }

    fn clamped(&self, b: &View) -> Self {
        View { x0: self.x0.max(b.x0), x1: self.x1.min(b.x1), y0: self.y0.max(b.y0), y1: self.y1.min(b.y1) }
    }

    /// The part of a simple polygon inside the window (Sutherland–Hodgman against each edge);
    /// empty when nothing is inside. The drawing backend does not clip, so every filled shape
    /// goes through here.
    pub fn clip_polygon(&self, polygon: &[(f64, f64)]) -> Vec<(f64, f64)> {
        let mut out: Vec<(f64, f64)> = polygon.to_vec();
        // Each edge: a point is inside when `f(p) >= 0`; `cut` finds where a segment crosses.
        let edges: [(usize, f64, f64); 4] =
            [(0, self.x0, 1.0), (0, self.x1, -1.0), (1, self.y0, 1.0), (1, self.y1, -1.0)];
        for (axis, at, sign) in edges {
            let coord = |p: (f64, f64)| if axis == 0 { p.0 } else { p.1 };
            let inside = |p: (f64, f64)| sign * (coord(p) - at) >= 0.0;
            let input = std::mem::take(&mut out);
            for (k, &p) in input.iter().enumerate() {
                let q = input[(k + 1) % input.len()];
                let cross = || {
                    let t = (at - coord(p)) / (coord(q) - coord(p));
                    (p.0 + t * (q.0 - p.0), p.1 + t * (q.1 - p.1))
                };
                match (inside(p), inside(q)) {
                    (true, true) => out.push(q),
                    (true, false) => out.push(cross()),
                    (false, true) => {
                        out.push(cross());
                        out.push(q);
                    }
                    (false, false) => {}
                }
            }
            if out.is_empty() {
                break;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SUMMARY: &str = r#"{"scenario":"slalom","lab":"builtin:liacc",
        "obstacles":[[17,6.1,17.6,6.4,1.0],[19,5.8,19.6,6.1]],
        "checkpoints":[[10,6.1,0.5],[20,6.1]], "seed":1,
        "robots":[{"name":"chair1","log":"chair1.csv","ticks":120}], "extra":{"a":[1,2]}}"#;

    #[test]
    fn a_summary_gives_lab_obstacles_and_checkpoints_with_defaults() {
        let s = Summary::parse(SUMMARY, Path::new("run/summary.json")).expect("parses");
        assert_eq!(s.lab.as_deref(), Some("builtin:liacc"));
        assert_eq!(
            s.obstacles,
            Some(vec![
                Obstacle { x0: 17.0, y0: 6.1, x1: 17.6, y1: 6.4, height_m: 1.0 },
                Obstacle { x0: 19.0, y0: 5.8, x1: 19.6, y1: 6.1, height_m: DEFAULT_OBSTACLE_HEIGHT_M },
            ])
        );
        assert_eq!(
            s.checkpoints,
            Some(vec![
                Checkpoint { x_m: 10.0, y_m: 6.1, radius_m: 0.5 },
                Checkpoint { x_m: 20.0, y_m: 6.1, radius_m: DEFAULT_CHECKPOINT_RADIUS_M },
            ])
        );
    }

    #[test]
    fn a_summary_without_the_keys_gives_none() {
        let s = Summary::parse(r#"{"seed":3}"#, Path::new("summary.json")).expect("parses");
        assert_eq!(s, Summary::default());
    }

    #[test]
    fn a_summary_that_is_not_json_gives_line_and_column() {
        let err = Summary::parse("{\n  \"lab\": builtin }", Path::new("run/summary.json")).expect_err("not JSON");
        assert!(matches!(err, SummaryReadError::Json { line: 2, .. }), "{err:?}");
        assert!(err.to_string().starts_with("run/summary.json:2:"), "{err}");
    }

    #[test]
    fn a_bad_summary_item_is_named_with_its_index() {
        let err = Summary::parse(r#"{"obstacles":[[1,1,2,2],[3,3,"x",4]]}"#, Path::new("summary.json")).expect_err("x");
        assert!(matches!(&err, SummaryReadError::Key { key, .. } if key == "obstacles[1]"), "{err:?}");
        let err = Summary::parse(r#"{"checkpoints":[[1,1,-1]]}"#, Path::new("summary.json")).expect_err("r < 0");
        assert!(matches!(&err, SummaryReadError::Key { key, .. } if key == "checkpoints[0]"), "{err:?}");
        let err = Summary::parse(r#"{"lab":3}"#, Path::new("summary.json")).expect_err("lab 3");
        assert!(matches!(&err, SummaryReadError::Key { key, .. } if key == "lab"), "{err:?}");
    }

    #[test]
    fn command_line_lists_parse_like_the_hubs() {
        assert_eq!(Obstacle::parse("1,2,3,4").expect("ok").height_m, 1.0);
        assert_eq!(Checkpoint::parse("1, 2, 0.75").expect("ok").radius_m, 0.75);
        assert!(matches!(Obstacle::parse("1,2,3"), Err(ScenarioParseError::Count { found: 3, .. })));
        assert!(matches!(Obstacle::parse("3,2,1,4"), Err(ScenarioParseError::Shape { .. })));
        assert!(matches!(Checkpoint::parse("1,nan"), Err(ScenarioParseError::NotANumber { item: 2, .. })));
    }

    fn lab(width_m: f64, height_m: f64) -> Lab {
        Lab { name: "t".into(), width_m, height_m, walls: vec![], beacons: vec![], targets: vec![] }
    }

    #[test]
    fn the_view_is_the_trajectory_plus_margin_kept_inside_the_lab() {
        let scene = Scene { lab: Some(lab(44.0, 17.75)), ..Default::default() };
        let v = View::around([(0.5, 6.0), (8.0, 7.0)], &scene);
        assert_eq!(v, View { x0: 0.0, x1: 9.5, y0: 4.5, y1: 8.5 });
        let v = View::around([(0.5, 6.0), (8.0, 7.0)], &Scene::default());
        assert_eq!(v, View { x0: -1.0, x1: 9.5, y0: 4.5, y1: 8.5 });
    }

    #[test]
    fn growing_the_view_shifts_it_back_into_the_lab() {
        let b = View { x0: 0.0, x1: 44.0, y0: 0.0, y1: 17.75 };
        let v = View { x0: 0.0, x1: 9.5, y0: 4.5, y1: 8.5 }.grown_to(9.5, 6.0, Some(&b));
        assert_eq!(v, View { x0: 0.0, x1: 9.5, y0: 3.5, y1: 9.5 });
        let v = View { x0: 1.0, x1: 3.0, y0: 16.0, y1: 17.0 }.grown_to(4.0, 30.0, Some(&b));
        assert_eq!(v, View { x0: 0.0, x1: 4.0, y0: 0.0, y1: 17.75 });
    }

    #[test]
    fn clipping_keeps_the_part_of_a_polygon_inside_the_view() {
        let v = View { x0: 0.0, x1: 10.0, y0: 0.0, y1: 10.0 };
        let inside = [(1.0, 1.0), (2.0, 1.0), (2.0, 2.0)];
        assert_eq!(v.clip_polygon(&inside), [(2.0, 1.0), (2.0, 2.0), (1.0, 1.0)]);
        let across = [(-5.0, 4.0), (5.0, 4.0), (5.0, 6.0), (-5.0, 6.0)];
        let clipped = v.clip_polygon(&across);
        assert!(clipped.iter().all(|&(x, y)| v.contains(x, y)), "{clipped:?}");
        let area: f64 = (0..clipped.len())
            .map(|k| {
                let (p, q) = (clipped[k], clipped[(k + 1) % clipped.len()]);
                p.0 * q.1 - q.0 * p.1
            })
            .sum::<f64>()
            / 2.0;
        assert!((area.abs() - 10.0).abs() < 1e-9, "{area}");
        assert!(v.clip_polygon(&[(20.0, 20.0), (21.0, 20.0), (21.0, 21.0)]).is_empty());
    }
}
