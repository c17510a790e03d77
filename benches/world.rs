//! One world tick at 10, 100, 1,000 and 10,000 robots: wheelchairs with eight proximity
//! sensors each, driving with noise on, on tiled LIACC floors (ten chairs per floor, so the
//! density of walls and chairs stays that of the real floor).
//!
//! Run: `cargo bench --bench world` (add `-- 'world_tick/1000$'` to run one size). The same load
//! (100 untimed ticks, then 300 timed) is what `iwsim bench world --robots N` times, which
//! docs/performance.md quotes.

use std::hint::black_box;
use std::time::{Duration, Instant};

use bench_harness::tiled::TiledWorld;
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};

fn world_tick(c: &mut Criterion) {
    let mut group = c.benchmark_group("world_tick");
    for robots in [10usize, 100, 1_000, 10_000] {
        // The load of `iwsim bench world` with its defaults: 100 ticks of driving untimed,
        // then a window of 300 ticks; the world goes back to the same start each window.
        let mut start = TiledWorld::build(robots, 1).expect("tiled LIACC world builds");
        for _ in 0..100 {
            start.tick(0.1);
        }
        let mut w = start.clone();
        let mut in_window = 0;
        group.throughput(Throughput::Elements(robots as u64));
        group.sample_size(if robots >= 10_000 { 20 } else { 50 });
        group.measurement_time(Duration::from_secs(if robots >= 10_000 { 8 } else { 4 }));
        // Time `World::step` alone: the controller that makes the actions runs between ticks,
        // as an agent would, and is left out (as in `iwsim bench world`).
        group.bench_with_input(BenchmarkId::from_parameter(robots), &robots, |b, _| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                for _ in 0..iters {
                    if in_window == 300 {
                        w = start.clone();
                        in_window = 0;
                    }
                    in_window += 1;
                    w.control();
                    let t = Instant::now();
                    w.step_only(black_box(0.1));
                    total += t.elapsed();
                }
                total
            })
        });
    }
    group.finish();
}

criterion_group!(benches, world_tick);
criterion_main!(benches);
