//! `urbansem streets bench-svm`: our bin SVM trained and tested on a dataset's bins, the same
//! bins exported in libsvm format for `scripts/bench_streets_svm.py` (libsvm side by side).

use crate::metrics::peak_rss_bytes;
use anyhow::{bail, Context};
use serde_json::json;
use std::path::Path;
use std::time::Instant;
use streets::dataset::StreetsDataset;
use streets::features::FEATURE_DIMS;
use streets::model::{dataset_bins, GeometryOptions, Scaler, Target};
use streets::svm::{Svm, SvmOptions};

#[allow(clippy::too_many_arguments)]
/// Runs `urbansem streets bench-svm`: trains the bin SVM on a dataset's bins, tests it, and
/// exports the same scaled bins in libsvm format for the peer.
pub fn bench_svm(
    dataset: &Path,
    n_train: usize,
    n_test: usize,
    export: Option<&Path>,
    c: f64,
    cache_mb: usize,
    seed: u64,
    json: bool,
) -> anyhow::Result<()> {
    use rand::seq::SliceRandom;
    use rand::SeedableRng;
    let ds = StreetsDataset::load(dataset)
        .with_context(|| format!("loading the streets dataset {}", dataset.display()))?;
    let bins = dataset_bins(&ds, &GeometryOptions::default(), Target::DrivingArea);
    let (x, y) = (bins.features, bins.labels);
    drop(ds);
    let n = y.len();
    if n < n_train + n_test {
        bail!(
            "{} has {n} labelled bins, fewer than --train {n_train} + --test {n_test}",
            dataset.display()
        );
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.shuffle(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed));
    let gather = |ids: &[usize]| {
        let mut xs = Vec::with_capacity(ids.len() * FEATURE_DIMS);
        for &i in ids {
            xs.extend_from_slice(&x[i * FEATURE_DIMS..(i + 1) * FEATURE_DIMS]);
        }
        (xs, ids.iter().map(|&i| y[i]).collect::<Vec<bool>>())
    };
    let (mut xtr, ytr) = gather(&order[..n_train]);
    let (mut xte, yte) = gather(&order[n_train..n_train + n_test]);
    let scaler = Scaler::fit(&xtr, FEATURE_DIMS);
    scaler.apply(&mut xtr);
    scaler.apply(&mut xte);
    if let Some(dir) = export {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        for (name, xs, ys) in [("train.svm", &xtr, &ytr), ("test.svm", &xte, &yte)] {
            let mut s = String::new();
            for (row, &l) in xs.chunks_exact(FEATURE_DIMS).zip(ys.iter()) {
                s += if l { "+1" } else { "-1" };
                for (k, v) in row.iter().enumerate() {
                    if *v != 0.0 {
                        s += &format!(" {}:{}", k + 1, v);
                    }
                }
                s += "\n";
            }
            let p = dir.join(name);
            geodata::fsio::write_atomic(&p, s)
                .with_context(|| format!("writing {}", p.display()))?;
        }
    }
    let options = SvmOptions {
        c,
        cache_mb,
        ..SvmOptions::default()
    };
    // Reset the peak-RSS counter so that it measures training (Linux; ignored elsewhere).
    drop(x);
    let _ = std::fs::write("/proc/self/clear_refs", "5");
    let t = Instant::now();
    let svm = Svm::train_flat(&xtr, FEATURE_DIMS, &ytr, &options)?;
    let train_peak = peak_rss_bytes();
    let train_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let pred = svm.predict_flat(&xte)?;
    let predict_s = t.elapsed().as_secs_f64();
    let acc =
        pred.iter().zip(&yte).filter(|(a, b)| a == b).count() as f64 / yte.len().max(1) as f64;
    let v = json!({
        "train_bins": n_train, "test_bins": n_test, "features": FEATURE_DIMS,
        "c": c, "gamma": svm.gamma, "eps": options.eps, "cache_mb": cache_mb,
        "train_seconds": train_s, "predict_seconds": predict_s, "accuracy": acc,
        "support_vectors": svm.support_count(), "iterations": svm.stats.iterations,
        "objective": svm.stats.objective, "peak_rss_bytes": train_peak,
        "threads": rayon::current_num_threads(),
    });
    if json {
        println!("{}", serde_json::to_string(&v)?);
    } else {
        println!("{}", serde_json::to_string_pretty(&v)?);
    }
    Ok(())
}
