//! `urbansem cloud …`: statistics and format conversion of point cloud files.

use anyhow::{bail, Context};
use clap::Subcommand;
use geodata::cloud::info::CloudInfo;
use geodata::cloud::kitti::read_label_file;
use geodata::cloud::mcap::{bag_info, read_bag_cloud_at, Pick};
use geodata::cloud::{
    read_cloud_with, write_cloud_with, Encoding, Format, ReadOptions, WriteOptions,
};
use geodata::datasets::LabelSet;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Subcommands of `urbansem cloud`.
#[derive(Subcommand)]
pub enum CloudCommand {
    /// Read a point cloud (.ply, .pcd, .las, .laz, KITTI .bin) and print its statistics; for a
    /// ROS 2 bag (.mcap), list its topics, message counts and point fields.
    Info {
        /// The cloud file or bag; the format is chosen by extension.
        file: PathBuf,
        /// Print one JSON object instead of a readable summary.
        #[arg(long)]
        json: bool,
        /// Skip points with NaN/infinite coordinates (counted) instead of failing.
        #[arg(long)]
        drop_non_finite: bool,
    },
    /// Convert a point cloud between formats (chosen by the extensions of IN and OUT); IN may
    /// be a ROS 2 bag (.mcap), of which one PointCloud2 message is converted.
    Convert {
        /// The input cloud or bag.
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
        /// The message to read when IN is a ROS 2 bag (.mcap).
        #[command(flatten)]
        bag: super::BagPickArgs,
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
            bag,
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
            let message = bag.pick(&input)?;
            convert(
                &input,
                &output,
                encoding,
                labels.as_deref(),
                label_set.as_deref(),
                drop_non_finite,
                message,
            )
        }
    }
}

fn info(path: &Path, json: bool, drop_non_finite: bool) -> anyhow::Result<()> {
    let format = Format::from_path(path)?;
    if format == Format::Mcap {
        let info =
            bag_info(path).with_context(|| format!("reading ROS 2 bag {}", path.display()))?;
        if json {
            return print_out(&(serde_json::to_string_pretty(&info)? + "\n"));
        }
        return print_out(&info.text());
    }
    let bytes = std::fs::metadata(path)
        .with_context(|| format!("reading {}", path.display()))?
        .len();
    let start = Instant::now();
    let (cloud, report) = read_cloud_with(path, &ReadOptions { drop_non_finite })
        .with_context(|| format!("reading point cloud {}", path.display()))?;
    let info = CloudInfo::new(
        path,
        format,
        bytes,
        &cloud,
        &report,
        start.elapsed().as_secs_f64(),
    );
    if json {
        return print_out(&(serde_json::to_string_pretty(&serde_json::to_value(&info)?)? + "\n"));
    }
    print_out(&info.text())
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
    bag_message: Option<(Option<&str>, Pick)>,
) -> anyhow::Result<()> {
    Format::from_path(output)?;
    let start = Instant::now();
    let options = ReadOptions { drop_non_finite };
    let (mut cloud, report) = match bag_message {
        Some((topic, pick)) => read_bag_cloud_at(input, topic, pick, &options),
        None => read_cloud_with(input, &options),
    }
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
        match label_set {
            Some(name) => {
                let Some(set) = LabelSet::from_name(name) else {
                    super::usage!("unknown --label-set {name:?}; use mcd or kitti360");
                };
                set.attach(&mut cloud, raw);
            }
            None => cloud.raw_label = Some(raw),
        }
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
