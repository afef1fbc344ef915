//! `urbansem demo` (skeleton).

use clap::Args;

/// Options of `urbansem demo`.
#[derive(Args)]
pub struct DemoArgs {}

/// Runs the demo.
pub fn run(_args: DemoArgs) -> anyhow::Result<()> {
    anyhow::bail!("demo: not built yet")
}
