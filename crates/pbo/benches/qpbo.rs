//! Criterion benches of QPBO and max-flow on the seeded instances of `pbo::instances`
//! (the `--quick` sizes of `urbansem bench pbo`, which prints the ratio to Kolmogorov's
//! QPBO and BK max-flow; this bench times urbansem alone).

// criterion_group! generates an undocumented public function.
#![allow(missing_docs)]
use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use pbo::instances::{denoising_grid, random_sparse, segmentation_3d};

fn bench_instances(c: &mut Criterion) {
    let instances = [
        denoising_grid(256, 256, 1),
        random_sparse(20_000, 6, 2),
        segmentation_3d(32, 3),
    ];
    let mut group = c.benchmark_group("pbo");
    group.sample_size(10);
    for inst in &instances {
        group.bench_function(format!("qpbo_build_solve/{}", inst.name), |b| {
            b.iter(|| {
                let mut q = inst.to_qpbo::<i32>();
                q.solve();
                q.num_labelled()
            })
        });
        group.bench_function(format!("qpbo_solve/{}", inst.name), |b| {
            b.iter_batched(
                || {
                    let mut q = inst.to_qpbo::<i32>();
                    q.prepare();
                    q
                },
                |mut q| {
                    q.solve();
                    q.num_labelled()
                },
                BatchSize::LargeInput,
            )
        });
        if inst.is_cut_form() {
            group.bench_function(format!("maxflow_solve/{}", inst.name), |b| {
                b.iter_batched(
                    || {
                        let mut g = inst.to_graph::<i32>();
                        if let Some(g) = g.as_mut() {
                            g.prepare();
                        }
                        g
                    },
                    |g| g.map(|mut g| g.maxflow(false)),
                    BatchSize::LargeInput,
                )
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench_instances);
criterion_main!(benches);
