//! A benchmark world: LIACC floors (thesis Annex D) tiled side by side, ten wheelchairs per
//! floor, each with eight proximity sensors, driving with noise on under a small reactive
//! controller. The criterion bench and `iwsim bench world` both step this world, so their
//! figures describe the same load.
//!
//! Tiling keeps the density of walls and chairs per square metre realistic whatever the robot
//! count: 10,000 chairs live on 1,000 floors, not crammed onto one.

use nalgebra::{Point2, Vector2};

use world::map::{Lab, Params, Wall, builtin};
use world::math::{Pose, Real};
use world::rng::Rng;
use world::{Action, ProximitySpec, RobotHandle, RobotSpec, World, WorldBuildError};

/// Chairs per floor.
pub const ROBOTS_PER_FLOOR: usize = 10;

/// The tiled world and its chairs.
#[derive(Debug, Clone)]
pub struct TiledWorld {
    /// The world.
    pub world: World,
    /// Every chair, in the order added.
    pub robots: Vec<RobotHandle>,
    /// Floors along x and y.
    pub floors: (usize, usize),
    actions: Vec<Action>,
}

/// A wheelchair of the Intellwheels prototype's size with eight sensors round its body.
pub fn chair_spec(pose: Pose) -> RobotSpec {
    let [w, h, com] = sim_model::chair::BODY;
    let (front, rear, side) = (com * w, -(1.0 - com) * w, h / 2.0);
    let sensors = vec![
        ProximitySpec::deg(front, 0.0, 0.0, 45.0),
        ProximitySpec::deg(front, side, 45.0, 45.0),
        ProximitySpec::deg(front, -side, -45.0, 45.0),
        ProximitySpec::deg(0.0, side, 90.0, 45.0),
        ProximitySpec::deg(0.0, -side, -90.0, 45.0),
        ProximitySpec::deg(rear, side, 135.0, 45.0),
        ProximitySpec::deg(rear, -side, -135.0, 45.0),
        ProximitySpec::deg(rear, 0.0, 180.0, 45.0),
    ];
    RobotSpec { pose, ..RobotSpec::at(0.0, 0.0, 0.0) }
        .named("chair")
        .body(w, h, com)
        .motors(0.49, 0.83)
        .sensors(sensors)
}

/// Why the tiled world could not be built.
#[derive(Debug, thiserror::Error)]
pub enum TiledBuildError {
    /// The built-in LIACC map did not load (a build defect).
    #[error("the built-in LIACC map did not load")]
    NoLiacc,
    /// The world refused the tiled lab.
    #[error(transparent)]
    World(#[from] WorldBuildError),
    /// No free place was found for a chair.
    #[error("no free place for chair {0} after many tries")]
    NoRoom(usize),
}

/// `n` LIACC floors as one lab, laid out close to square.
pub fn tiled_lab(floors: usize) -> Result<(Lab, (usize, usize)), TiledBuildError> {
    let floor = builtin::map("liacc").ok_or(TiledBuildError::NoLiacc)?.lab;
    let (fw, fh) = (floor.width_m, floor.height_m);
    let floors = floors.max(1);
    let cols = ((floors as Real * fh / fw).sqrt().ceil() as usize).max(1);
    let rows = floors.div_ceil(cols);
    let mut walls = Vec::with_capacity(floor.walls.len() * cols * rows);
    for fy in 0..rows {
        for fx in 0..cols {
            let offset = Vector2::new(fx as Real * fw, fy as Real * fh);
            walls.extend(
                floor
                    .walls
                    .iter()
                    .map(|w| Wall { height_m: w.height_m, corners: w.corners.iter().map(|c| c + offset).collect() }),
            );
        }
    }
    let lab = Lab {
        name: format!("{cols}x{rows} LIACC floors"),
        width_m: cols as Real * fw,
        height_m: rows as Real * fh,
        walls,
        beacons: vec![],
        targets: vec![],
    };
    Ok((lab, (cols, rows)))
}

impl TiledWorld {
    /// `robots` chairs on tiled LIACC floors with the default (noisy) parameters; `seed`
    /// fixes both the placement and the world's noise.
    pub fn build(robots: usize, seed: u64) -> Result<Self, TiledBuildError> {
        let floors = robots.div_ceil(ROBOTS_PER_FLOOR);
        let (lab, (cols, rows)) = tiled_lab(floors)?;
        let params = Params {
            sensors: world::map::SensorSwitches { gps: true, beacon: false, compass: true },
            ..Params::default()
        };
        let mut world = World::new(&lab, params, seed)?;
        world.set_capacity(robots.max(world.len()));
        let floor = builtin::map("liacc").ok_or(TiledBuildError::NoLiacc)?.lab;
        let mut rng = Rng::seed_from_u64(seed ^ 0x005E_EDF1_00D5);
        let mut handles = Vec::with_capacity(robots);
        let mut placed_on_floor: Vec<Point2<Real>> = Vec::new();
        for k in 0..robots {
            let f = k / ROBOTS_PER_FLOOR;
            if k % ROBOTS_PER_FLOOR == 0 {
                placed_on_floor.clear();
            }
            let origin = Vector2::new((f % cols) as Real * floor.width_m, (f / cols) as Real * floor.height_m);
            let mut tries = 0;
            let spec = loop {
                tries += 1;
                if tries > 10_000 {
                    return Err(TiledBuildError::NoRoom(k));
                }
                let p =
                    Point2::new(rng.uniform(1.0, floor.width_m - 1.0), rng.uniform(1.0, floor.height_m - 1.0)) + origin;
                let spec = chair_spec(Pose::new(p.x, p.y, rng.uniform(-std::f64::consts::PI, std::f64::consts::PI)));
                // 2.2 m apart: two chairs (bound radius 0.93 m) never start touching.
                if placed_on_floor.iter().all(|q| (q - p).norm() > 2.2) && world.is_clear_of_walls(&spec) {
                    placed_on_floor.push(p);
                    break spec;
                }
            };
            handles.push(world.add_robot(spec.named(&format!("chair{k}"))).map_err(|_| TiledBuildError::NoRoom(k))?);
        }
        let _ = rows;
        Ok(Self { world, robots: handles, floors: (cols, rows), actions: Vec::with_capacity(robots) })
    }

    /// This tick's actions from the chairs' last readings (see [`wander`]).
    pub fn control(&mut self) -> &[Action] {
        wander(&self.world, &self.robots, &mut self.actions);
        &self.actions
    }

    /// Runs the controller and steps the world once.
    pub fn tick(&mut self, dt_s: Real) {
        self.control();
        let actions = std::mem::take(&mut self.actions);
        self.world.step(&actions, dt_s);
        self.actions = actions;
    }

    /// Steps the world with the actions computed last, without running the controller: what
    /// a benchmark of the world alone times.
    pub fn step_only(&mut self, dt_s: Real) {
        let actions = std::mem::take(&mut self.actions);
        self.world.step(&actions, dt_s);
        self.actions = actions;
    }
}

/// A small reactive controller for chairs made by [`chair_spec`]: go ahead, veer away from
/// the nearer side, turn on the spot when something is close in front or the chair is blocked.
/// Writes one action per live robot into `out`.
pub fn wander(world: &World, robots: &[RobotHandle], out: &mut Vec<Action>) {
    out.clear();
    for (k, &h) in robots.iter().enumerate() {
        let Some(r) = world.robot(h) else { continue };
        if let Some((l, rr)) = steer(r.readings.proximity(), r.collision, k % 2 == 0) {
            out.push(Action::motors(h, l, rr));
        }
    }
}

/// The reactive rule of [`wander`] for one chair of [`chair_spec`]'s sensor layout: motor
/// powers (left, right) from its proximity readings `d` (metres, in sensor order) and whether
/// it is blocked; `left_on_tie` picks the way to turn when both sides read alike. `None` when
/// the chair has fewer than the five front and side sensors the rule reads. The bench agents
/// of `iwsim bench lockstep` steer by this rule too, so both benchmarks carry one controller.
pub fn steer(d: &[Real], collision: bool, left_on_tie: bool) -> Option<(Real, Real)> {
    if d.len() < 5 {
        return None;
    }
    // Straight ahead decides whether to turn on the spot; the diagonals and sides only
    // steer, so a chair follows a corridor narrower than its sensors' reach.
    let (ahead, front_left, front_right, left, right) = (d[0], d[1], d[2], d[3], d[4]);
    let turn_left = front_left + left > front_right + right || (front_left == front_right && left_on_tie);
    Some(if ahead < 0.7 || collision {
        if turn_left { (-0.4, 0.4) } else { (0.4, -0.4) }
    } else if front_left < 0.45 || left < 0.3 {
        (0.8, 0.45)
    } else if front_right < 0.45 || right < 0.3 {
        (0.45, 0.8)
    } else {
        (0.9, 0.9)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_keep_ten_chairs_per_floor_none_touching_a_wall() {
        let t = TiledWorld::build(45, 3).expect("builds");
        assert_eq!(t.world.len(), 45);
        let (cols, rows) = t.floors;
        assert!(cols * rows >= 5);
        assert_eq!(t.world.lab().walls.len(), 23 * cols * rows);
        for &h in &t.robots {
            let r = t.world.robot(h).expect("alive");
            assert!(t.world.is_clear_of_walls(&RobotSpec { pose: r.pose, ..r.spec.clone() }));
        }
    }

    #[test]
    fn chairs_wander_without_driving_through_walls() {
        let mut t = TiledWorld::build(20, 5).expect("builds");
        let start: Vec<Pose> = t.robots.iter().map(|&h| t.world.robot(h).expect("alive").pose).collect();
        for _ in 0..300 {
            t.tick(0.1);
        }
        let mut moved = 0;
        for (k, &h) in t.robots.iter().enumerate() {
            let r = t.world.robot(h).expect("alive");
            assert!(t.world.is_clear_of_walls(&RobotSpec { pose: r.pose, ..r.spec.clone() }), "chair {k} is in a wall");
            if (r.pose.position() - start[k].position()).norm() > 1.0 {
                moved += 1;
            }
        }
        assert!(moved >= 10, "only {moved} of 20 chairs got anywhere");
    }
}
