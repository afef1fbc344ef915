//! `urbansem localize …`: global localization of a scan on OSM building outlines (issue 6).

use clap::Args;

/// Arguments of `urbansem localize`.
#[derive(Args)]
pub struct LocalizeArgs {
    /// Arguments (the command is being built; see issue 6).
    #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
    pub rest: Vec<String>,
}

/// Runs `urbansem localize`.
pub fn run(_args: LocalizeArgs) -> anyhow::Result<()> {
    anyhow::bail!("urbansem localize is not available in this build yet (issue 6)")
}
