//! The collision phase: every moving robot's next pose against the walls and the other bodies.

use super::{Motion, World, overlaps};
use crate::geom::{PlacedBody, bodies_intersect, body_hits_triangle};

/// A collision verdict bit: the next pose meets a wall or the lab's border.
pub(super) const HIT_WALL: u8 = 1;
/// A collision verdict bit: the next pose meets another body.
pub(super) const HIT_ROBOT: u8 = 2;

impl World {
    /// Fills `scratch.blocked[i]` with (hit, enforce) for every slot: `hit` holds [`HIT_WALL`]
    /// and [`HIT_ROBOT`] bits (both when the next pose meets a wall and a body; challenges
    /// charge each kind of contact its own penalty).
    ///
    /// A robot is refused its next pose when that pose meets a wall, or another body at either
    /// its current or its next pose: testing both makes the outcome independent of the order
    /// robots are visited in, and two robots can never move into each other. Something the
    /// robot already overlaps at its current pose does not block it, so bodies that start
    /// interpenetrated (a Real chair driven into a virtual one) can separate. Real robots are
    /// never refused; `hit` then reports that they overlap something.
    pub(super) fn resolve_collisions(&mut self, stats: &mut super::StepStats, chunking: &super::Chunking) {
        let mut blocked = std::mem::take(&mut self.scratch.blocked);
        blocked.clear();
        blocked.resize(self.motion.len(), (0, false));
        // Each robot's verdict reads only the phase's inputs, so chunks run in any order.
        let mut units = vec![(); blocked.len()]; // zero-sized: never allocates
        let mut chunk_units = [(); super::MAX_CHUNKS];
        let this = &*self;
        super::run_chunks(chunking, &mut blocked, &mut units, &mut chunk_units, |base, blocked, _, ()| {
            for (k, b) in blocked.iter_mut().enumerate() {
                let m = &this.motion[base + k];
                if m.alive && (m.moving || m.real) {
                    *b = (this.next_pose_hits(base + k, m), !m.real);
                }
            }
        });
        stats.colliding += blocked.iter().filter(|(hit, _)| *hit != 0).count() as u32;
        self.scratch.blocked = blocked;
    }

    fn next_pose_hits(&self, i: usize, m: &Motion) -> u8 {
        let escape = !m.real;
        let mut hits = 0;
        let s = &self.statics;
        let (x0, y0, x1, y1) = s.spec.cell_range(m.next_min, m.next_max);
        'walls: for iy in y0..=y1 {
            for ix in x0..=x1 {
                for &t in s.triangles_in(iy * s.spec.nx + ix) {
                    let tri = &s.triangles[t as usize];
                    if overlaps(m.next_min, m.next_max, tri.min, tri.max)
                        && body_hits_triangle(&m.next, &tri.p)
                        && !(escape
                            && overlaps(m.cur_min, m.cur_max, tri.min, tri.max)
                            && body_hits_triangle(&m.cur, &tri.p))
                    {
                        hits = HIT_WALL;
                        break 'walls;
                    }
                }
            }
        }
        // Bodies are tested even after a wall: a contact with both costs both penalties.
        let mut hit = false;
        self.dyn_grid.query(m.next_min, m.next_max, |j| {
            let j = j as usize;
            if hit || j == i {
                return;
            }
            let o = &self.motion[j];
            let meets = |b: &PlacedBody, bmin, bmax| {
                overlaps(m.next_min, m.next_max, bmin, bmax) && bodies_intersect(&m.next, b)
            };
            let meets_other =
                meets(&o.cur, o.cur_min, o.cur_max) || (o.moving && meets(&o.next, o.next_min, o.next_max));
            if meets_other {
                let already =
                    escape && overlaps(m.cur_min, m.cur_max, o.cur_min, o.cur_max) && bodies_intersect(&m.cur, &o.cur);
                hit = !already;
            }
        });
        hits | (hit as u8 * HIT_ROBOT)
    }

    /// Whether a placed body touches any wall (the lab border included).
    pub(super) fn body_hits_wall(&self, b: &PlacedBody) -> bool {
        let (min, max) = b.aabb();
        let s = &self.statics;
        let (x0, y0, x1, y1) = s.spec.cell_range(min, max);
        (y0..=y1).any(|iy| {
            (x0..=x1).any(|ix| {
                s.triangles_in(iy * s.spec.nx + ix).iter().any(|&t| {
                    let tri = &s.triangles[t as usize];
                    overlaps(min, max, tri.min, tri.max) && body_hits_triangle(b, &tri.p)
                })
            })
        })
    }
}
