//! A warm tick on several threads allocates (next to) nothing: the world's own code keeps its
//! per-chunk scratch, so the only allocator calls left are the thread pool's (its job queue
//! grows one block per 63 steps handed to it). ARCHITECTURE.md states it; this counts every
//! thread's calls, so it lives alone in its own test binary.
mod counting;

use world::map::{Params, builtin};
use world::{Action, RobotSpec, World};

#[global_allocator]
static ALLOCATOR: counting::Counting = counting::Counting;

#[test]
fn a_warm_parallel_tick_leaves_allocation_to_the_thread_pool() {
    // 306 chairs: over the parallel threshold, on the LIACC floor's walls, noise on.
    let map = builtin::map("liacc").expect("built in");
    let mut world = World::new(&map.lab, Params::default(), 7).expect("valid lab");
    world.set_capacity(400);
    assert_eq!(world.set_threads(2), 2);
    let mut actions = Vec::new();
    let mut k = 0usize;
    for iy in 0..29 {
        for ix in 0..47 {
            let (x, y) = (1.2 + 0.9 * ix as f64, 1.2 + 0.55 * iy as f64);
            let spec = RobotSpec::at(x, y, (k * 41 % 360) as f64).body(0.5, 0.3, 0.8);
            let spec = if k % 3 == 2 { RobotSpec::at(x, y, 0.0).disc(0.4) } else { spec };
            if actions.len() < 306 && world.is_free(&spec) {
                let chair = world.add_robot(spec).expect("a free start");
                let (l, r) = [(1.0, 1.0), (0.6, 1.0), (-0.5, 0.5), (1.0, 0.2)][k % 4];
                actions.push(Action::motors(chair, l, r));
            }
            k += 1;
        }
    }
    assert!(world.len() >= world::PARALLEL_MIN_ROBOTS, "{} chairs placed", world.len());
    for _ in 0..300 {
        world.step(&actions, 0.1);
    }
    let before = world.state_hash();
    let calls = counting::allocations_in(|| {
        for _ in 0..100 {
            world.step(&actions, 0.1);
        }
    });
    assert_ne!(world.state_hash(), before, "the chairs kept moving while counted");
    // One job handed to the pool per step: its queue takes a new block every 63 (2 per 100).
    assert!(calls <= 4, "allocator calls on all threads in 100 warm ticks of {} robots: {calls}", world.len());
}
