//! The navigator's map: the lab's size and its walls as polygons, built from the items the
//! hub publishes (so the navigator never parses map files and never depends on the hub).

use agent_sdk::map::{Map, MapDecodeError};
use ipc_types::{MapHeader, MapItem};
use places::Checkpoint;

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
    pub checkpoints: Vec<Checkpoint>,
}

impl NavMap {
    /// A map of an empty lab.
    pub fn empty(width_m: f64, height_m: f64) -> Self {
        Self { name: String::new(), width_m, height_m, walls: Vec::new(), checkpoints: Vec::new() }
    }

    /// The navigator's view of the hub's decoded map: its walls and obstacles as polygons and
    /// its checkpoints (beacons, targets and the grid are not needed here).
    pub fn new(map: &Map) -> Self {
        let point = |p: &agent_sdk::map::Point| V2::new(p.x, p.y);
        Self {
            name: map.name.clone(),
            width_m: map.width_m,
            height_m: map.height_m,
            // A wall of height 0 is a line on the floor: chairs drive over it and sensors do
            // not see it.
            walls: map
                .walls
                .iter()
                .filter(|w| w.height_m > 0.0)
                .map(|w| MapWall {
                    corners: w.corners.iter().map(point).collect(),
                    height_m: w.height_m,
                    obstacle: w.obstacle,
                })
                .collect(),
            checkpoints: map.checkpoints.clone(),
        }
    }

    /// Decodes the hub's map items with [`Map::decode`] (the one decoder every client shares)
    /// and builds the navigator's view of them, for callers that hold the raw items.
    pub fn from_items(header: &MapHeader, items: &[MapItem]) -> Result<Self, MapDecodeError> {
        Map::decode(header, items).map(|m| Self::new(&m))
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
    use agent_sdk::map::{Point, Wall};

    fn wall(corners: &[(f64, f64)], obstacle: bool) -> Wall {
        Wall { height_m: 1.0, corners: corners.iter().map(|&(x, y)| Point::new(x, y)).collect(), obstacle }
    }

    #[test]
    fn walls_obstacles_and_checkpoints_come_from_the_hubs_map() {
        let map = Map {
            name: "lab".into(),
            width_m: 10.0,
            height_m: 8.0,
            walls: vec![
                wall(&[(1.0, 1.0), (2.0, 1.0), (2.0, 2.0), (1.0, 2.0)], false),
                wall(&[(5.0, 5.0), (6.0, 5.0), (6.0, 6.0)], true),
                // A line on the floor (height 0): no wall to plan round.
                Wall { height_m: 0.0, ..wall(&[(0.0, 4.0), (10.0, 4.0), (10.0, 4.2), (0.0, 4.2)], false) },
            ],
            checkpoints: vec![Checkpoint { x: 8.0, y: 2.0, radius: 0.5 }],
            ..Map::default()
        };
        let map = NavMap::new(&map);
        assert_eq!((map.name.as_str(), map.width_m, map.height_m), ("lab", 10.0, 8.0));
        assert_eq!(map.walls.len(), 2);
        assert!(!map.walls[0].obstacle && map.walls[1].obstacle);
        assert_eq!(map.walls[1].corners[2], V2::new(6.0, 6.0));
        assert_eq!(map.known_walls().count(), 1);
        assert_eq!(map.known_segments().len(), 4 + 4, "the border and the one known wall");
        assert_eq!(map.checkpoints, vec![Checkpoint { x: 8.0, y: 2.0, radius: 0.5 }]);
        assert!(!map.is_open(V2::new(1.5, 1.5)) && map.is_open(V2::new(5.8, 5.5)), "obstacles are not known");
        assert!(map.is_open(V2::new(5.0, 4.1)), "a line is driven over");
    }

    #[test]
    fn raw_items_go_through_the_sdks_decoder() {
        use bytemuck::Zeroable as _;
        let header = MapHeader { width_m: -1.0, height_m: 8.0, ..MapHeader::zeroed() };
        assert_eq!(NavMap::from_items(&header, &[]), Err(MapDecodeError::BadSize { width: -1.0, height: 8.0 }));
        let header = MapHeader { width_m: 10.0, ..header };
        assert_eq!(NavMap::from_items(&header, &[]), Ok(NavMap::empty(10.0, 8.0)));
    }
}
