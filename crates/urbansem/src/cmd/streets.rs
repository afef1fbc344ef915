//! `urbansem streets …`: street offset and width per OSM segment (issue 5).

use clap::Args;

/// Arguments of `urbansem streets`.
#[derive(Args)]
pub struct StreetsArgs {
    /// Arguments (the command is being built; see issue 5).
    #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
    pub rest: Vec<String>,
}

/// Runs `urbansem streets`.
pub fn run(_args: StreetsArgs) -> anyhow::Result<()> {
    anyhow::bail!("urbansem streets is not available in this build yet (issue 5)")
}
