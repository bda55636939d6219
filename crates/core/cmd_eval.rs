//! `clevrtex eval`.

use crate::exit::CmdResult;

/// Arguments of `clevrtex eval`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Run `clevrtex eval`.
pub fn run(_args: Args) -> CmdResult {
    anyhow::bail!("`clevrtex eval` is not implemented yet")
}
