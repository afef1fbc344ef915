//! `urbansem cloud …`: statistics and format conversion of point cloud files.

use anyhow::{bail, Context};
use clap::Subcommand;
use geodata::classes::Class;
use geodata::cloud::kitti::read_label_file;
use geodata::cloud::{
    read_cloud_with, write_cloud_with, Encoding, Format, ReadOptions, WriteOptions,
};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Subcommands of `urbansem cloud`.
#[derive(Subcommand)]
pub enum CloudCommand {
    /// Read a point cloud (.ply, .pcd, .las, .laz, KITTI .bin) and print its statistics.
    Info {
        /// The cloud file; the format is chosen by extension.
        file: PathBuf,
        /// Print one JSON object instead of a readable summary.
        #[arg(long)]
        json: bool,
        /// Skip points with NaN/infinite coordinates (counted) instead of failing.
        #[arg(long)]
        drop_non_finite: bool,
    },
    /// Convert a point cloud between formats (chosen by the extensions of IN and OUT).
    Convert {
        /// The input cloud.
        input: PathBuf,
        /// The output cloud.
        output: PathBuf,
        /// Write PLY/PCD as text instead of binary.
        #[arg(long)]
        ascii: bool,
        /// Write PLY as binary big-endian.
        #[arg(long, conflicts_with = "ascii")]
        big_endian: bool,
        /// Write PCD as `binary_compressed` (LZF).
        #[arg(long, conflicts_with_all = ["ascii", "big_endian"])]
        compressed: bool,
        /// A per-point uint32 label file (KITTI-360/MCD/SemanticKITTI style) to attach as `raw_label`.
        #[arg(long)]
        labels: Option<PathBuf>,
        /// The dataset whose class ids the label file holds, to fill `label` too:
        /// `mcd` or `kitti360` (without it only `raw_label` is set).
        #[arg(long, requires = "labels")]
        label_set: Option<String>,
        /// Skip points with NaN/infinite coordinates (counted) instead of failing.
        #[arg(long)]
        drop_non_finite: bool,
    },
}

/// Runs one `urbansem cloud` subcommand.
pub fn run(command: CloudCommand) -> anyhow::Result<()> {
    match command {
        CloudCommand::Info {
            file,
            json,
            drop_non_finite,
        } => info(&file, json, drop_non_finite),
        CloudCommand::Convert {
            input,
            output,
            ascii,
            big_endian,
            compressed,
            labels,
            label_set,
            drop_non_finite,
        } => {
            let encoding = if ascii {
                Encoding::Ascii
            } else if big_endian {
                Encoding::BinaryBigEndian
            } else if compressed {
                Encoding::BinaryCompressed
            } else {
                Encoding::BinaryLittleEndian
            };
            convert(
                &input,
                &output,
                encoding,
                labels.as_deref(),
                label_set.as_deref(),
                drop_non_finite,
            )
        }
    }
}

fn info(path: &Path, json: bool, drop_non_finite: bool) -> anyhow::Result<()> {
    let format = Format::from_path(path)?;
    let bytes = std::fs::metadata(path)
        .with_context(|| format!("reading {}", path.display()))?
        .len();
    let start = Instant::now();
    let (cloud, report) = read_cloud_with(path, &ReadOptions { drop_non_finite })
        .with_context(|| format!("reading point cloud {}", path.display()))?;
    let read_s = start.elapsed().as_secs_f64();
    let columns = cloud.columns().names();
    let bounds = cloud.bounds();
    let hist = cloud.class_histogram();
    let precision = match cloud.precision {
        geodata::cloud::Precision::F32 => "f32",
        geodata::cloud::Precision::F64 => "f64",
    };
    let points_per_s = if read_s > 0.0 {
        cloud.len() as f64 / read_s
    } else {
        f64::INFINITY
    };
    if json {
        let classes: serde_json::Map<String, serde_json::Value> = if cloud.label.is_some() {
            Class::ALL
                .iter()
                .map(|c| {
                    (
                        c.name().to_string(),
                        serde_json::json!(hist[c.id() as usize]),
                    )
                })
                .collect()
        } else {
            serde_json::Map::new()
        };
        let value = serde_json::json!({
            "file": path.display().to_string(),
            "format": format.name(),
            "bytes": bytes,
            "points": cloud.len(),
            "points_in_file": report.points_in_file,
            "dropped_non_finite": report.dropped_non_finite,
            "columns": columns,
            "precision": precision,
            "bounds": bounds.map(|b| serde_json::json!({ "min": b.min, "max": b.max })),
            "classes": classes,
            "read_seconds": read_s,
            "points_per_second": points_per_s,
        });
        return print_out(&(serde_json::to_string_pretty(&value)? + "\n"));
    }
    let mut out = String::new();
    writeln!(out, "{}", path.display())?;
    writeln!(out, "  format     {} ({bytes} bytes)", format.name())?;
    writeln!(out, "  points     {}", cloud.len())?;
    if report.dropped_non_finite > 0 {
        writeln!(
            out,
            "  dropped    {} of {} points with non-finite coordinates",
            report.dropped_non_finite, report.points_in_file
        )?;
    }
    writeln!(
        out,
        "  columns    {} (positions {precision})",
        columns.join(" ")
    )?;
    if let Some(b) = bounds {
        writeln!(
            out,
            "  bounds     x {:.3} .. {:.3}, y {:.3} .. {:.3}, z {:.3} .. {:.3} m",
            b.min[0], b.max[0], b.min[1], b.max[1], b.min[2], b.max[2]
        )?;
    }
    if cloud.label.is_some() {
        writeln!(out, "  classes")?;
        for c in Class::ALL {
            let n = hist[c.id() as usize];
            if n > 0 {
                let pct = 100.0 * n as f64 / cloud.len().max(1) as f64;
                writeln!(out, "    {:<11} {n:>10} ({pct:5.1} %)", c.name())?;
            }
        }
    }
    writeln!(
        out,
        "  read       {:.3} s ({:.2} M points/s)",
        read_s,
        points_per_s / 1e6
    )?;
    print_out(&out)
}

/// Writes to stdout; a closed pipe (`| head`) is not an error.
fn print_out(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    match std::io::stdout().lock().write_all(text.as_bytes()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => Ok(other?),
    }
}

fn convert(
    input: &Path,
    output: &Path,
    encoding: Encoding,
    labels: Option<&Path>,
    label_set: Option<&str>,
    drop_non_finite: bool,
) -> anyhow::Result<()> {
    Format::from_path(output)?;
    let start = Instant::now();
    let (mut cloud, report) = read_cloud_with(input, &ReadOptions { drop_non_finite })
        .with_context(|| format!("reading point cloud {}", input.display()))?;
    if let Some(label_path) = labels {
        if report.dropped_non_finite > 0 {
            bail!(
                "cannot attach {} to {}: {} points were dropped, so labels no longer line up",
                label_path.display(),
                input.display(),
                report.dropped_non_finite
            );
        }
        let raw = read_label_file(label_path, Some(cloud.len()))
            .with_context(|| format!("reading labels {}", label_path.display()))?;
        if let Some(set) = label_set {
            let map: fn(u32) -> Class = match set {
                "mcd" => geodata::datasets::mcd::mcd_class,
                "kitti360" | "kitti-360" => geodata::datasets::kitti360::kitti360_class,
                other => super::usage!("unknown --label-set {other:?}; use mcd or kitti360"),
            };
            cloud.label = Some(raw.iter().map(|&r| map(r).id()).collect());
        }
        cloud.raw_label = Some(raw);
    }
    write_cloud_with(output, &cloud, &WriteOptions { encoding })
        .with_context(|| format!("writing point cloud {}", output.display()))?;
    eprintln!(
        "{} → {}: {} points ({}) in {:.3} s",
        input.display(),
        output.display(),
        cloud.len(),
        cloud.columns().names().join(" "),
        start.elapsed().as_secs_f64()
    );
    Ok(())
}
