//! The second core against `rayon::join`: two halves of `work_us` each, joined, with
//! the gap a grasp trial leaves between frames (2 ms, outside the timed region) or
//! none, so the cost of waking the other thread shows. `cargo bench -p softtouch-sim
//! --bench second_core`; the figures are in `second_core.rs`'s module docs.

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::time::{Duration, Instant};

/// About `us` microseconds of arithmetic.
fn work(us: u64) -> u64 {
    let start = Instant::now();
    let mut x = 1u64;
    while start.elapsed() < Duration::from_micros(us) {
        for _ in 0..64 {
            x = black_box(x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1));
        }
    }
    x
}

fn bench(c: &mut Criterion) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .expect("rayon pool");
    let mut g = c.benchmark_group("join");
    g.measurement_time(Duration::from_secs(3));
    g.warm_up_time(Duration::from_millis(500));
    for gap_ms in [0u64, 2] {
        for work_us in [0u64, 100] {
            let gap = Duration::from_millis(gap_ms);
            let timed = |iters: u64, join: &dyn Fn()| {
                let mut total = Duration::ZERO;
                for _ in 0..iters {
                    if !gap.is_zero() {
                        std::thread::sleep(gap);
                    }
                    let t = Instant::now();
                    join();
                    total += t.elapsed();
                }
                total
            };
            let name = |what: &str| format!("{what}/gap {gap_ms} ms/halves {work_us} us");
            g.bench_function(name("sequential"), |b| {
                b.iter_custom(|n| {
                    timed(n, &|| {
                        black_box(work(work_us));
                        black_box(work(work_us));
                    })
                });
            });
            g.bench_function(name("second_core"), |b| {
                b.iter_custom(|n| {
                    timed(n, &|| {
                        softtouch_sim::second_core::join(
                            || {
                                black_box(work(work_us));
                            },
                            || {
                                black_box(work(work_us));
                            },
                        );
                    })
                });
            });
            g.bench_function(name("rayon::join"), |b| {
                b.iter_custom(|n| {
                    timed(n, &|| {
                        pool.install(|| {
                            rayon::join(|| black_box(work(work_us)), || black_box(work(work_us)))
                        });
                    })
                });
            });
        }
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
