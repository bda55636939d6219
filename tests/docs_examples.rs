//! Docs that run (issue 32): every ```` ```sh ````, ```` ```bash ```` and ```` ```python ````
//! block of README.md and docs/**/*.md (docs/notes/ included) runs as written, in one
//! temporary folder holding `data/` (a 10-image `camo` dataset rendered tiny by this build),
//! `preds/` (its masks as predictions) and `out/` (its WebDataset export), with this build's
//! `clevrtex` and the test venv's `python` first on PATH, and `.venv-bpy` linked to the bpy
//! venv of the real-render tests when there is one (the second Blender `clevrtex` finds, as in
//! the repository's root). A block directly under `<!-- not run: REASON -->` is left out, and
//! listed with its reason; one directly under `<!-- needs bpy -->` runs only with that venv
//! (its absence skipped visibly, or a failure where `CLEVRTEX_REQUIRE_BPY=1`).
//! Needs Blender and the test venv with the package and torch; skipped visibly without them,
//! required in CI.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::util::{blender_or_skip, bpy_or_skip, repo_root, test_python_or_skip, text};

/// One fenced block of a Markdown file.
#[derive(Debug)]
struct Block {
    /// `README.md:14` (the fence's line).
    place: String,
    /// `sh`, `bash` or `python`.
    lang: String,
    /// The code, the fence's indentation removed.
    code: String,
    /// The reason of a `<!-- not run: REASON -->` directly above, if any.
    not_run: Option<String>,
    /// Whether `<!-- needs bpy -->` is directly above.
    needs_bpy: bool,
}

const LANGS: [&str; 3] = ["sh", "bash", "python"];
const MARKER: &str = "<!-- not run:";
const NEEDS_BPY: &str = "<!-- needs bpy -->";

/// The shell and Python blocks of `text` (the file `name`), every other fence skipped whole.
fn blocks(name: &str, text: &str) -> Vec<Block> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let trimmed = lines[i].trim_start();
        let Some(info) = trimmed.strip_prefix("```") else {
            i += 1;
            continue;
        };
        let indent = lines[i].len() - trimmed.len();
        let lang = info.trim().to_string();
        let start = i;
        let mut code = String::new();
        i += 1;
        while i < lines.len() && !lines[i].trim_start().starts_with("```") {
            let l = lines[i];
            let cut = l.len() - l.trim_start().len();
            code.push_str(&l[cut.min(indent)..]);
            code.push('\n');
            i += 1;
        }
        i += 1;
        if !LANGS.contains(&lang.as_str()) {
            continue;
        }
        let above = start.checked_sub(1).map(|j| lines[j].trim());
        let not_run = above
            .and_then(|l| l.strip_prefix(MARKER))
            .map(|r| r.trim_end_matches("-->").trim().to_string());
        out.push(Block {
            place: format!("{name}:{}", start + 1),
            lang,
            code,
            not_run,
            needs_bpy: above == Some(NEEDS_BPY),
        });
    }
    out
}

/// The Markdown files under `dir`, its subfolders (`docs/notes/`) included, sorted by path.
fn markdown_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap().flatten() {
        let path = entry.path();
        let kind = entry.file_type().unwrap();
        if kind.is_dir() {
            out.extend(markdown_files(&path));
        } else if kind.is_file() && path.extension().is_some_and(|e| e == "md") {
            out.push(path);
        }
    }
    out.sort();
    out
}

/// Every block of README.md and docs/**/*.md, in file order.
fn all_blocks() -> Vec<Block> {
    let root = repo_root();
    let mut files = vec![root.join("README.md")];
    files.extend(markdown_files(&root.join("docs")));
    files
        .iter()
        .flat_map(|f| {
            let name = f.strip_prefix(&root).unwrap().display().to_string();
            blocks(&name, &std::fs::read_to_string(f).unwrap())
        })
        .collect()
}

#[test]
fn docs_blocks_are_found_and_every_skip_says_why() {
    let text = "a\n<!-- not run: needs a GPU -->\n```sh\nnvidia-smi\n```\n\n  ```python\n  print(1)\n    x = 2\n  ```\n<!-- needs bpy -->\n```sh\nx\n```\n```json\n```sh\n```\n";
    let b = blocks("t.md", text);
    assert_eq!(b.len(), 3, "{b:?}");
    assert_eq!(b[0].not_run.as_deref(), Some("needs a GPU"));
    assert_eq!(
        b.iter().map(|b| b.needs_bpy).collect::<Vec<_>>(),
        [false, false, true]
    );
    assert_eq!(
        (b[1].lang.as_str(), b[1].code.as_str()),
        ("python", "print(1)\n  x = 2\n")
    );
    assert_eq!(b[1].place, "t.md:7");
    let all = all_blocks();
    for b in &all {
        assert!(
            b.not_run.as_ref().is_none_or(|r| !r.is_empty()),
            "{}: `<!-- not run: -->` needs a reason",
            b.place
        );
    }
    // The notes are read too (issue 36: measurements moved there keep their commands).
    assert!(
        all.iter().any(|b| b.place.starts_with("docs/notes/")),
        "no block found under docs/notes/"
    );
    // The README's Python example runs (issue 32: it called a `batches` that does not exist).
    assert!(all
        .iter()
        .any(|b| b.place.starts_with("README.md") && b.lang == "python" && b.not_run.is_none()));
}

/// The shared folder: `data/` (10 `camo` images at 64x48, 4 samples, every pass), `preds/`
/// (each sample's mask, cropped and resized to the evaluation's 128x128, as `<stem>_mask.png`)
/// and `out/` (`data/` exported as WebDataset shards: `out/camo-<split>-000000.tar`).
fn workspace(dir: &Path, python: &Path) {
    let out = Command::new(env!("CARGO_BIN_EXE_clevrtex"))
        .args([
            "generate",
            "--variant",
            "camo",
            "-n",
            "10",
            "--width",
            "64",
            "--height",
            "48",
        ])
        .args(["--samples", "4", "--out"])
        .arg(dir.join("data"))
        .output()
        .unwrap();
    assert!(out.status.success(), "generate failed:\n{}", text(&out));
    // The masks at the evaluation's shape (crop, then 128x128), through the package.
    let code = "import clevrtex, os\nfrom PIL import Image\nos.mkdir('preds')\n\
                for i, _, m in clevrtex.Dataset('data', 'camo', split='all', return_metadata=False):\n    \
                Image.fromarray(m[0]).save(f'preds/CLEVRTEX_camo_{i:06}_mask.png')\n";
    let out = Command::new(python)
        .args(["-c", code])
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(out.status.success(), "preds/:\n{}", text(&out));
    let out = Command::new(env!("CARGO_BIN_EXE_clevrtex"))
        .args(["export", "--format", "webdataset", "data", "out"])
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(out.status.success(), "export failed:\n{}", text(&out));
}

#[test]
fn docs_examples_run_as_written() {
    let test = "docs_examples_run_as_written";
    let Some(python) = test_python_or_skip(test, "clevrtex, torch") else {
        return;
    };
    if blender_or_skip(test).is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    workspace(dir.path(), &python);
    // The bpy venv where `clevrtex` looks for it (`./.venv-bpy`), as in the repository's root.
    let bpy = bpy_or_skip(test);
    if let Some(venv) = bpy.as_ref().and_then(|p| p.parent()?.parent()) {
        std::os::unix::fs::symlink(venv, dir.path().join(".venv-bpy")).unwrap();
    }
    let bin = Path::new(env!("CARGO_BIN_EXE_clevrtex")).parent().unwrap();
    let venv_bin = python.parent().unwrap();
    let path = std::env::join_paths(
        [bin.to_path_buf(), venv_bin.to_path_buf()]
            .into_iter()
            .chain(std::env::split_paths(
                &std::env::var_os("PATH").unwrap_or_default(),
            )),
    )
    .unwrap();
    let mut failed = Vec::new();
    let mut ran = 0;
    for (i, b) in all_blocks().iter().enumerate() {
        if let Some(why) = &b.not_run {
            eprintln!("not run: {} ({}): {why}", b.place, b.lang);
            continue;
        }
        if b.needs_bpy && bpy.is_none() {
            eprintln!("not run: {} ({}): needs bpy", b.place, b.lang);
            continue;
        }
        let file = dir.path().join(format!(
            "block{i}.{}",
            if b.lang == "python" { "py" } else { "sh" }
        ));
        std::fs::write(&file, &b.code).unwrap();
        let mut cmd = if b.lang == "python" {
            Command::new(&python)
        } else {
            let mut c = Command::new("bash");
            c.args(["-euo", "pipefail"]);
            c
        };
        let out = cmd
            .arg(&file)
            .current_dir(dir.path())
            .env("PATH", &path)
            .output()
            .unwrap();
        ran += 1;
        if !out.status.success() {
            failed.push(format!(
                "{} ({}):\n{}\n--- output:\n{}",
                b.place,
                b.lang,
                b.code,
                text(&out)
            ));
        }
    }
    assert!(ran >= 3, "only {ran} blocks ran");
    assert!(
        failed.is_empty(),
        "{} examples failed:\n\n{}",
        failed.len(),
        failed.join("\n\n")
    );
}
