//! One world tick at 10, 100, 1,000 and 10,000 robots: wheelchairs with eight proximity
//! sensors each, driving with noise on, on tiled LIACC floors (ten chairs per floor, so the
//! density of walls and chairs stays that of the real floor).
//!
//! Run: `cargo bench --bench world` (add `-- 10000` to run one size). The same load is timed by
//! `iwsim bench world --robots N --ticks T`, which README quotes.

use std::hint::black_box;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use hub::tiled::TiledWorld;

fn world_tick(c: &mut Criterion) {
    let mut group = c.benchmark_group("world_tick");
    for robots in [10usize, 100, 1_000, 10_000] {
        let mut w = TiledWorld::build(robots, 1).expect("tiled LIACC world builds");
        for _ in 0..20 {
            w.tick(0.1);
        }
        group.throughput(Throughput::Elements(robots as u64));
        group.sample_size(if robots >= 10_000 { 20 } else { 50 });
        group.measurement_time(Duration::from_secs(if robots >= 10_000 { 8 } else { 4 }));
        group.bench_with_input(BenchmarkId::from_parameter(robots), &robots, |b, _| {
            b.iter(|| {
                w.tick(black_box(0.1));
            })
        });
    }
    group.finish();
}

criterion_group!(benches, world_tick);
criterion_main!(benches);
