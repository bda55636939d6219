//! `clevrtex materials`.

use crate::exit::CmdResult;

/// Arguments of `clevrtex materials`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Run `clevrtex materials`.
pub fn run(_args: Args) -> CmdResult {
    anyhow::bail!("`clevrtex materials` is not implemented yet")
}
