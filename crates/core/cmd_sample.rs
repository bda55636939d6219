//! `clevrtex sample`.

use crate::exit::CmdResult;

/// Arguments of `clevrtex sample`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Run `clevrtex sample`.
pub fn run(_args: Args) -> CmdResult {
    anyhow::bail!("`clevrtex sample` is not implemented yet")
}
