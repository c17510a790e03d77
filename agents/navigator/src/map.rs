//! The navigator's map: the lab's size and its walls as polygons, built from the items the
//! hub publishes (so the navigator never parses map files and never depends on the hub).

use ipc_types::{MAP_CHECKPOINT, MAP_CORNER, MAP_WALL, MapHeader, MapItem};

use crate::geom::{Seg, V2};

/// A wall: a polygon standing on the floor.
#[derive(Debug, Clone, PartialEq)]
pub struct MapWall {
    /// Corners in order (either orientation).
    pub corners: Vec<V2>,
    /// Height, metres.
    pub height_m: f64,
    /// A scenario's obstacle (placed by the run, not part of the map file). The navigator
    /// does not plan on these: it has to find them with its sensors, as the thesis's chair did.
    pub obstacle: bool,
}

impl MapWall {
    /// An axis-aligned box.
    pub fn rectangle(x0: f64, y0: f64, x1: f64, y1: f64, obstacle: bool) -> Self {
        Self {
            corners: vec![V2::new(x0, y0), V2::new(x1, y0), V2::new(x1, y1), V2::new(x0, y1)],
            height_m: 1.0,
            obstacle,
        }
    }

    /// The outline's segments.
    pub fn segments(&self) -> impl Iterator<Item = Seg> + '_ {
        let n = self.corners.len();
        (0..n).map(move |i| Seg::new(self.corners[i], self.corners[(i + 1) % n]))
    }

    /// Whether a point lies inside the polygon (even–odd rule).
    pub fn contains(&self, p: V2) -> bool {
        let n = self.corners.len();
        let mut inside = false;
        let mut j = n.wrapping_sub(1);
        for i in 0..n {
            let (a, b) = (self.corners[i], self.corners[j]);
            if (a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x {
                inside = !inside;
            }
            j = i;
        }
        inside
    }
}

/// A scenario checkpoint as the hub publishes it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapCheckpoint {
    /// Centre, metres.
    pub pos: V2,
    /// Radius, metres.
    pub radius_m: f64,
}

/// The lab as the navigator knows it.
#[derive(Debug, Clone, PartialEq)]
pub struct NavMap {
    /// Lab name.
    pub name: String,
    /// Extent along x, metres (the lab is `[0, width] × [0, height]`, bordered by walls).
    pub width_m: f64,
    /// Extent along y, metres.
    pub height_m: f64,
    /// Interior walls and scenario obstacles.
    pub walls: Vec<MapWall>,
    /// The scenario's checkpoints, if the hub has any.
    pub checkpoints: Vec<MapCheckpoint>,
}

/// Why the hub's map items could not be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MapBuildError {
    /// The lab's size is not a positive finite number.
    #[error("the lab's size {width} x {height} m is not usable")]
    BadSize {
        /// Width given.
        width: f64,
        /// Height given.
        height: f64,
    },
    /// A corner came before any wall.
    #[error("map item {item}: a corner before any wall")]
    CornerWithoutWall {
        /// Index of the item.
        item: usize,
    },
    /// A wall ended with fewer corners than it announced, or fewer than three.
    #[error("wall {wall} has {got} corners; {expected} were announced (at least 3 needed)")]
    MissingCorners {
        /// The wall's index.
        wall: u32,
        /// Corners announced.
        expected: usize,
        /// Corners received.
        got: usize,
    },
    /// A value was not a finite number.
    #[error("map item {item} holds a value that is not a finite number")]
    NotFinite {
        /// Index of the item.
        item: usize,
    },
}

impl NavMap {
    /// A map of an empty lab.
    pub fn empty(width_m: f64, height_m: f64) -> Self {
        Self { name: String::new(), width_m, height_m, walls: Vec::new(), checkpoints: Vec::new() }
    }

    /// Reads the map as the hub publishes it: `MAP_WALL` items (a = height, b = corner count,
    /// c = 1 for a scenario obstacle) each followed by its `MAP_CORNER` items, and
    /// `MAP_CHECKPOINT` items. Other kinds (beacons, targets, grid) are not needed here.
    pub fn from_items(header: &MapHeader, items: &[MapItem]) -> Result<Self, MapBuildError> {
        let (width, height) = (header.width_m, header.height_m);
        if !(width.is_finite() && height.is_finite() && width > 0.0 && height > 0.0) {
            return Err(MapBuildError::BadSize { width, height });
        }
        let mut map = Self::empty(width, height);
        map.name = header.name.as_str().unwrap_or("").to_owned();
        // (wall index, corners announced) of the wall being read.
        let mut open: Option<(u32, usize)> = None;
        let close = |map: &NavMap, open: Option<(u32, usize)>| -> Result<(), MapBuildError> {
            if let Some((wall, expected)) = open {
                let got = map.walls.last().map_or(0, |w| w.corners.len());
                if got != expected || got < 3 {
                    return Err(MapBuildError::MissingCorners { wall, expected, got });
                }
            }
            Ok(())
        };
        for (i, it) in items.iter().enumerate() {
            if !(it.a.is_finite() && it.b.is_finite() && it.c.is_finite()) {
                return Err(MapBuildError::NotFinite { item: i });
            }
            match it.kind {
                MAP_WALL => {
                    close(&map, open.take())?;
                    let expected = if it.b >= 0.0 && it.b < 1e6 { it.b as usize } else { 0 };
                    map.walls.push(MapWall {
                        corners: Vec::with_capacity(expected.min(64)),
                        height_m: it.a,
                        obstacle: it.c != 0.0,
                    });
                    open = Some((it.index, expected));
                }
                MAP_CORNER => {
                    let wall = match (&open, map.walls.last_mut()) {
                        (Some(_), Some(w)) => w,
                        _ => return Err(MapBuildError::CornerWithoutWall { item: i }),
                    };
                    wall.corners.push(V2::new(it.a, it.b));
                }
                MAP_CHECKPOINT => {
                    close(&map, open.take())?;
                    map.checkpoints.push(MapCheckpoint { pos: V2::new(it.a, it.b), radius_m: it.c });
                }
                _ => close(&map, open.take())?,
            }
        }
        close(&map, open.take())?;
        Ok(map)
    }

    /// The walls the navigator plans on: every wall that is not a scenario obstacle.
    pub fn known_walls(&self) -> impl Iterator<Item = &MapWall> {
        self.walls.iter().filter(|w| !w.obstacle)
    }

    /// The outline segments of the known walls and of the lab's border.
    pub fn known_segments(&self) -> Vec<Seg> {
        let (w, h) = (self.width_m, self.height_m);
        let corners = [V2::new(0.0, 0.0), V2::new(w, 0.0), V2::new(w, h), V2::new(0.0, h)];
        let mut segs: Vec<Seg> = (0..4).map(|i| Seg::new(corners[i], corners[(i + 1) % 4])).collect();
        for wall in self.known_walls() {
            segs.extend(wall.segments());
        }
        segs
    }

    /// Whether a point lies inside the lab and outside every known wall.
    pub fn is_open(&self, p: V2) -> bool {
        p.x > 0.0
            && p.y > 0.0
            && p.x < self.width_m
            && p.y < self.height_m
            && !self.known_walls().any(|w| w.contains(p))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bytemuck::Zeroable as _;

    fn header(w: f64, h: f64) -> MapHeader {
        MapHeader { width_m: w, height_m: h, ..MapHeader::zeroed() }
    }

    fn item(kind: u32, index: u32, a: f64, b: f64, c: f64) -> MapItem {
        MapItem { kind, index, a, b, c }
    }

    #[test]
    fn walls_obstacles_and_checkpoints_are_read_from_the_hubs_items() {
        let mut items = vec![item(MAP_WALL, 0, 2.5, 4.0, 0.0)];
        for (x, y) in [(1.0, 1.0), (2.0, 1.0), (2.0, 2.0), (1.0, 2.0)] {
            items.push(item(MAP_CORNER, 0, x, y, 0.0));
        }
        items.push(item(MAP_WALL, 1, 1.0, 3.0, 1.0));
        for (x, y) in [(5.0, 5.0), (6.0, 5.0), (6.0, 6.0)] {
            items.push(item(MAP_CORNER, 1, x, y, 0.0));
        }
        items.push(item(ipc_types::MAP_GRID, 0, 3.0, 3.0, 0.0));
        items.push(item(MAP_CHECKPOINT, 0, 8.0, 2.0, 0.5));
        let map = NavMap::from_items(&header(10.0, 8.0), &items).expect("valid");
        assert_eq!(map.walls.len(), 2);
        assert!(!map.walls[0].obstacle && map.walls[1].obstacle);
        assert_eq!(map.known_walls().count(), 1);
        assert_eq!(map.known_segments().len(), 4 + 4, "the border and the one known wall");
        assert_eq!(map.checkpoints, vec![MapCheckpoint { pos: V2::new(8.0, 2.0), radius_m: 0.5 }]);
        assert!(!map.is_open(V2::new(1.5, 1.5)) && map.is_open(V2::new(5.8, 5.5)), "obstacles are not known");
    }

    #[test]
    fn malformed_items_are_refused_with_a_reason() {
        let corner = item(MAP_CORNER, 0, 1.0, 1.0, 0.0);
        assert_eq!(
            NavMap::from_items(&header(10.0, 8.0), &[corner]),
            Err(MapBuildError::CornerWithoutWall { item: 0 })
        );
        let short = [item(MAP_WALL, 3, 1.0, 4.0, 0.0), corner, corner, corner];
        assert_eq!(
            NavMap::from_items(&header(10.0, 8.0), &short),
            Err(MapBuildError::MissingCorners { wall: 3, expected: 4, got: 3 })
        );
        assert!(matches!(NavMap::from_items(&header(-1.0, 8.0), &[]), Err(MapBuildError::BadSize { .. })));
        let nan = item(MAP_CHECKPOINT, 0, f64::NAN, 1.0, 0.5);
        assert_eq!(NavMap::from_items(&header(10.0, 8.0), &[nan]), Err(MapBuildError::NotFinite { item: 0 }));
    }
}
