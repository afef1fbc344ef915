//! One module per command group; each has a clap `…Command` enum and a `run` function.

/// An error in how a command was called (exit code 2), as opposed to a failure while it ran
/// (exit code 1); the bench harness raises the same type.
pub use urbansem_bench::UsageError;

/// Returns a [`UsageError`] from the enclosing function, formatted like `format!`.
macro_rules! usage {
    ($($arg:tt)*) => {
        return Err(anyhow::Error::new($crate::cmd::UsageError(format!($($arg)*))))
    };
}
pub(crate) use usage;

pub mod cloud;
pub mod demo;
pub mod localize;
pub mod mln;
pub mod osm;
pub mod pbo;
pub mod shard;
pub mod sim;
pub mod srtree;
pub mod streets;

/// Which message of a ROS 2 bag a command reads when its cloud argument is a `.mcap` file.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct BagPickArgs {
    /// The bag's PointCloud2 topic (.mcap input only; needed when the bag has several).
    #[arg(long)]
    pub topic: Option<String>,
    /// Which message of the topic to read, 0-based in file order (.mcap input only; default 0).
    #[arg(long, conflicts_with = "time")]
    pub index: Option<usize>,
    /// Read the message logged nearest to this time, seconds since the epoch (.mcap input only).
    #[arg(long, value_name = "SECONDS")]
    pub time: Option<f64>,
}

impl BagPickArgs {
    /// Whether any of the options is given.
    pub fn given(&self) -> bool {
        self.topic.is_some() || self.index.is_some() || self.time.is_some()
    }

    /// The message to read when `path` is a bag: its topic and pick; `None` for any other
    /// cloud file (the options are then a usage error).
    pub fn pick(
        &self,
        path: &std::path::Path,
    ) -> anyhow::Result<Option<(Option<&str>, geodata::cloud::mcap::Pick)>> {
        use geodata::cloud::mcap::Pick;
        let is_bag =
            geodata::cloud::Format::from_path(path).ok() == Some(geodata::cloud::Format::Mcap);
        if !is_bag {
            if self.given() {
                usage!(
                    "--topic, --index and --time select a message of a ROS 2 bag (.mcap); {} is not one",
                    path.display()
                );
            }
            return Ok(None);
        }
        let pick = match self.time {
            Some(s) if !(s.is_finite() && s >= 0.0) => {
                usage!("--time {s} is not a time in seconds since the epoch")
            }
            Some(s) => Pick::Time((s * 1e9).round() as u64),
            None => Pick::Index(self.index.unwrap_or(0)),
        };
        Ok(Some((self.topic.as_deref(), pick)))
    }

    /// Reads the cloud `path`: one message of a bag as the options pick it, any other cloud
    /// file as it is (the options are then a usage error). Returns the cloud and its name
    /// (`BAG TOPIC#INDEX` for a bag message) and the seconds reading took.
    pub fn read(
        &self,
        path: &std::path::Path,
    ) -> anyhow::Result<(geodata::cloud::PointCloud, String, f64)> {
        use anyhow::Context;
        use geodata::cloud::mcap::{read_bag_cloud_at, Pick};
        let t = std::time::Instant::now();
        let Some((topic, pick)) = self.pick(path)? else {
            let cloud = geodata::cloud::read_cloud(path)
                .with_context(|| format!("reading {}", path.display()))?;
            return Ok((cloud, path.display().to_string(), t.elapsed().as_secs_f64()));
        };
        let (cloud, _) = read_bag_cloud_at(path, topic, pick, &Default::default())
            .with_context(|| format!("reading {}", path.display()))?;
        let name = match (topic, pick) {
            (Some(t), Pick::Index(i)) => format!("{} {t}#{i}", path.display()),
            (Some(t), Pick::Time(ns)) => format!("{} {t}@{}", path.display(), ns as f64 / 1e9),
            (None, _) => path.display().to_string(),
        };
        Ok((cloud, name, t.elapsed().as_secs_f64()))
    }
}

/// Prints a report as pretty JSON, keys sorted.
pub(crate) fn print_json(report: &impl serde::Serialize) -> anyhow::Result<()> {
    println!(
        "{}",
        serde_json::to_string_pretty(&serde_json::to_value(report)?)?
    );
    Ok(())
}
