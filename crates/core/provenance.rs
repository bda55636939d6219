//! What this binary was built from (set by the repository's `build.rs`): the version, the git
//! commit and whether the tree was modified; printed by `--version` and `doctor`, recorded in
//! every run manifest (`tool_commit`, `tool_modified`) and so on the dataset card.

/// The git commit of the build (40 hex digits), or `unknown`.
pub const COMMIT: &str = env!("CLEVRTEX_COMMIT");

/// `clevrtex --version`'s text after the name: `0.1.0 (commit 0123456789ab[, modified])`.
pub const VERSION_LINE: &str = env!("CLEVRTEX_VERSION_LINE");

/// Whether a tracked source differed from [`COMMIT`] at build time (`None`: not known).
pub fn modified() -> Option<bool> {
    match env!("CLEVRTEX_TREE_MODIFIED") {
        "true" => Some(true),
        "false" => Some(false),
        _ => None,
    }
}
