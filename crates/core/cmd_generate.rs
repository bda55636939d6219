//! `clevrtex generate` and `clevrtex render`.

use crate::exit::CmdResult;

/// Arguments of `clevrtex generate`.
#[derive(Debug, clap::Args)]
pub struct GenerateArgs {}

/// Arguments of `clevrtex render`.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {}

/// Run `clevrtex generate`.
pub fn run_generate(_args: GenerateArgs) -> CmdResult {
    anyhow::bail!("`clevrtex generate` is not implemented yet")
}

/// Run `clevrtex render`.
pub fn run_render(_args: RenderArgs) -> CmdResult {
    anyhow::bail!("`clevrtex render` is not implemented yet")
}
