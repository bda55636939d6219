//! Where the pictures go: an output file given on the command line must not land inside a
//! dataset it is drawn from (shared by `clevrtex report` and `clevrtex preview`).

use std::path::{Path, PathBuf};

/// Refuse an `--out` file inside one of the datasets `dirs`: writing there could overwrite a
/// dataset file (`--out data/clevrtex_full/0/CLEVRTEX_full_000000.png`).
pub fn refuse_output_inside(out: &Path, dirs: &[&Path]) -> anyhow::Result<()> {
    let parent = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    // The folder the file would go to, with links resolved (it must exist to be written).
    let Ok(parent) = parent.canonicalize() else {
        return Ok(());
    };
    for dir in dirs {
        let Ok(root) = dir.canonicalize() else {
            continue;
        };
        if parent.starts_with(&root) {
            anyhow::bail!(
                "`--out {}` is inside the dataset `{}`: writing there could overwrite its files\nhint: write the output outside the dataset folder, e.g. `--out {}`",
                out.display(),
                dir.display(),
                out.file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_else(|| "report.html".into())
            );
        }
    }
    Ok(())
}
