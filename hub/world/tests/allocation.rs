//! A warm tick allocates nothing: scratch buffers live in the world, so stepping thousands of
//! ticks costs no allocator traffic (ARCHITECTURE.md states it; this counts it). The count is
//! taken with a global allocator that counts the calls made on the test's own thread.
#![allow(unsafe_code)] // A global allocator can only be written with `unsafe impl`.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use world::map::{Params, builtin};
use world::{Action, RobotSpec, World};

struct Counting;

thread_local! {
    // `const` initialisation: reading it never allocates, so the allocator may use it.
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static CALLS: Cell<u64> = const { Cell::new(0) };
}

fn note() {
    if COUNTING.with(Cell::get) {
        CALLS.with(|c| c.set(c.get() + 1));
    }
}

// SAFETY: every call is forwarded unchanged to the system allocator; counting touches only
// const-initialised thread-locals, which neither allocate nor re-enter the allocator.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        // SAFETY: the caller's contract for `alloc` is passed on as it is.
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from `System` through this allocator, with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        // SAFETY: as for `dealloc`; the new size is the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Allocator calls made on this thread while `f` runs.
fn allocations_in(f: impl FnOnce()) -> u64 {
    CALLS.with(|c| c.set(0));
    COUNTING.with(|c| c.set(true));
    f();
    COUNTING.with(|c| c.set(false));
    CALLS.with(Cell::get)
}

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
