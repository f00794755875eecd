//! Subcommand (not implemented yet).

use crate::Global;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Input: a file path or a built-in scene name.
    pub input: String,
}

pub fn run(args: Args, _g: &Global) -> anyhow::Result<()> {
    anyhow::bail!("not implemented yet: {}", args.input)
}
