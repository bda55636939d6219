//! `clevrtex bench`.

use crate::exit::CmdResult;

/// Arguments of `clevrtex bench`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Run `clevrtex bench`.
pub fn run(_args: Args) -> CmdResult {
    anyhow::bail!("`clevrtex bench` is not implemented yet")
}
