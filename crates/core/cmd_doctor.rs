//! `clevrtex doctor`.

use crate::exit::CmdResult;

/// Arguments of `clevrtex doctor`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Run `clevrtex doctor`.
pub fn run(_args: Args) -> CmdResult {
    anyhow::bail!("`clevrtex doctor` is not implemented yet")
}
