//! Subcommand (not implemented yet).

use crate::Global;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene: a file path or a built-in name.
    pub scene: String,
}

pub fn run(args: Args, _g: &Global) -> anyhow::Result<()> {
    anyhow::bail!("not implemented yet: {}", args.scene)
}
