//! A warm tick allocates nothing: scratch buffers live in the world, so stepping thousands of
//! ticks costs no allocator traffic (ARCHITECTURE.md states it; this counts it). The count is
//! taken with a global allocator that counts every thread's calls (the world steps on one).
mod counting;

use world::map::{Params, builtin};
use world::{Action, RobotSpec, World};

#[global_allocator]
static ALLOCATOR: counting::Counting = counting::Counting;

use counting::allocations_in;

#[test]
fn a_warm_tick_allocates_nothing() {
    let map = builtin::map("liacc").expect("built in");
    // Noise on: the generator and every sensor's noise run as in a real run.
    let mut world = World::new(&map.lab, Params::default(), 7).expect("valid lab");
    let mut actions = Vec::new();
    for k in 0..12 {
        let x = 6.0 + 2.5 * k as f64;
        // Every third robot a disc, so the sensors' disc pass runs too.
        let spec = RobotSpec::at(x, 6.1, 0.0);
        let spec = if k % 3 == 2 { spec.disc(0.9) } else { spec.body(1.1, 0.65, 0.8) };
        let chair = world.add_robot(spec).expect("a free start");
        // Different powers per chair: some drive, some turn, some meet walls and each other.
        let (l, r) = [(1.0, 1.0), (0.6, 1.0), (-0.5, 0.5), (1.0, 0.2)][k % 4];
        actions.push(Action::motors(chair, l, r));
    }
    // Warm up: the grids and scratch buffers reach their working size.
    for _ in 0..300 {
        world.step(&actions, 0.1);
    }
    let before = world.state_hash();
    let calls = allocations_in(|| {
        for _ in 0..300 {
            world.step(&actions, 0.1);
        }
    });
    assert_ne!(world.state_hash(), before, "the chairs kept moving while counted");
    assert_eq!(calls, 0, "allocator calls in 300 warm ticks of 12 robots");
}
