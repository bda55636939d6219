//! `DATASET_CARD.md`: the dataset card `generate` writes into its `--out` folder, with the
//! sections of a Hugging Face dataset card (summary; contents: variants, samples per split,
//! passes with their encodings; how it was made: tool and Blender versions, seeds, config
//! hashes, commands; how it differs from the published ClevrTex; the materials' licence;
//! citations).
//!
//! The card is made from the union of the dataset's run manifests (and one sample's metadata
//! per variant, for the render settings), never from the run that writes it alone: every run
//! (each shard of a sharded run too) rewrites it under an exclusive `flock` of
//! `OUT/.clevrtex-card.lock` after writing its manifest, through a temporary file and a rename,
//! so the last writer leaves a card of every run. Manifests and metadata are untrusted: their
//! strings reach the card with control characters escaped and out of Markdown's way.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use crate::card_parts::{self as parts, code, fenced, RenderSettings};
use crate::dataset;
use crate::fingerprint::{self, Layouts};
use crate::layout::{self, Split};
use crate::manifest::{merge_ranges, Manifest};
use clevrtex_scene::Pass;

/// The card's file name, in the dataset's `--out` folder.
pub const CARD_FILE: &str = "DATASET_CARD.md";
/// The file whose `flock` serialises the card's writers (kept).
pub const CARD_LOCK: &str = ".clevrtex-card.lock";

/// What one variant's runs say, for the card.
#[derive(Debug, Default)]
struct VariantRuns {
    manifests: Vec<(String, Manifest)>,
    /// Every run's `render.width`, `render.height`, `render.samples` (its manifest's, else
    /// one of its samples' metadata), with the runs that used them.
    render: RenderSettings,
    /// The layouts of its finished runs' samples (fingerprint, materials used).
    layouts: Layouts,
}

/// Samples of each split the runs planned (each index once, with the split the run that
/// first covers it gives it: the recorded one), and how many are complete (in a finished
/// manifest).
/// What the public loader makes of `variant` whose planned samples have the recorded splits
/// `by_split`: unknown to it (`clevr`, a config's own name), read with the splits recorded,
/// or read with other splits (its position rule over all the samples differs from the
/// splits the runs recorded: a dataset grown with another `--total`).
fn loader_claim(variant: &str, by_split: &BTreeMap<Split, u64>) -> String {
    if !clevrtex_scene::suite::public_loader_knows(variant) {
        return format!(
            "{}: not a variant the public loader knows (it raises `Unknown variant {}`); read it with `clevrtex.Dataset`, score it with `clevrtex eval`",
            code(variant),
            clevrtex_scene::text::printable(variant)
        );
    }
    let n: u64 = by_split.values().sum();
    let rule = layout::variant_splits(variant);
    let theirs: BTreeMap<Split, u64> = Split::ALL
        .iter()
        .map(|&s| {
            let r = s.range(rule, n);
            (s, r.end - r.start)
        })
        .collect();
    let sizes = |m: &BTreeMap<Split, u64>| {
        Split::ALL
            .iter()
            .map(|s| format!("{} {}", s.name(), m.get(s).unwrap_or(&0)))
            .collect::<Vec<_>>()
            .join(", ")
    };
    if Split::ALL
        .iter()
        .all(|s| by_split.get(s).unwrap_or(&0) == theirs.get(s).unwrap_or(&0))
    {
        format!(
            "{}: read unchanged (`CLEVRTEX(path, '{}', split)`), with the splits recorded here ({})",
            code(variant),
            clevrtex_scene::text::printable(variant),
            sizes(by_split)
        )
    } else {
        format!(
            "{}: read, but with other splits than those recorded here: its position rule over all {n} samples gives {}, the runs recorded {} (the dataset was grown with another `--total`); the public evaluator and `clevrtex eval --split` score other sets (`clevrtex verify` names the positions; remake the variant with one `--total` in a new folder)",
            code(variant),
            sizes(&theirs),
            sizes(by_split)
        )
    }
}

fn counts(variant: &str, runs: &[(String, Manifest)]) -> (BTreeMap<Split, u64>, u64) {
    let rule = layout::variant_splits(variant);
    let mut by_split = BTreeMap::new();
    let mut covered: Vec<(u64, u64)> = Vec::new();
    let mut ordered: Vec<&Manifest> = runs.iter().map(|(_, m)| m).collect();
    ordered.sort_by_key(|m| (m.start, m.end, m.total));
    for m in ordered {
        // The part of the run's range no earlier run covered.
        let mut parts = vec![(m.start, m.end.max(m.start))];
        for &(a, b) in &covered {
            parts = parts
                .into_iter()
                .flat_map(|(s, e)| {
                    [(s, e.min(a)), (s.max(b), e)]
                        .into_iter()
                        .filter(|(x, y)| x < y)
                })
                .collect();
        }
        for (s, e) in parts {
            for split in Split::ALL {
                let r = split.range(rule, m.total);
                let n = e.min(r.end).saturating_sub(s.max(r.start));
                *by_split.entry(split).or_insert(0) += n;
            }
        }
        covered.push((m.start, m.end));
        covered = merge_ranges(covered);
    }
    let complete: BTreeSet<&str> = runs
        .iter()
        .filter(|(_, m)| m.finished)
        .flat_map(|(_, m)| m.files.keys())
        .filter(|f| f.ends_with(".json"))
        .map(String::as_str)
        .collect();
    (by_split, complete.len() as u64)
}

/// Hugging Face's size category of `n` samples.
fn size_category(n: u64) -> &'static str {
    match n {
        0..1_000 => "n<1K",
        1_000..10_000 => "1K<n<10K",
        10_000..100_000 => "10K<n<100K",
        100_000..1_000_000 => "100K<n<1M",
        _ => "1M<n<10M",
    }
}

/// The card's text for the runs found by variant, and the suites their manifests name.
fn card_text(
    title: &str,
    variants: &BTreeMap<String, VariantRuns>,
    suites: &BTreeSet<String>,
) -> String {
    use std::fmt::Write as _;
    let mut c = String::new();
    let mut planned_all = 0;
    let mut rows = Vec::new();
    for (v, runs) in variants {
        let (by_split, complete) = counts(v, &runs.manifests);
        let planned: u64 = by_split.values().sum();
        planned_all += planned;
        rows.push(format!(
            "| {} | {} | {} | {} | {planned} | {complete} |",
            code(v),
            by_split.get(&Split::Test).unwrap_or(&0),
            by_split.get(&Split::Val).unwrap_or(&0),
            by_split.get(&Split::Train).unwrap_or(&0),
        ));
    }
    let _ = write!(
        c,
        "---\npretty_name: {}\ntask_categories:\n- image-segmentation\ntags:\n- synthetic\n- object-centric\n- clevrtex\nsize_categories:\n- {}\n---\n\n",
        serde_json::Value::String(format!("{title} (clevrtex)")),
        size_category(planned_all)
    );
    let _ = writeln!(c, "# {}\n", clevrtex_scene::text::printable(title));
    c += "This card is written by `clevrtex generate` and rewritten by each of its runs from the \
           manifests of every run in this folder (`clevrtex_<variant>/MANIFEST-*.json`): edits \
           to it are lost at the next run.\n\n";

    c += "## Dataset summary\n\n";
    c += "Synthetic scenes for unsupervised multi-object segmentation in the style of ClevrTex \
           (Karazija, Laina, Rupprecht, NeurIPS 2021 Datasets and Benchmarks), itself built on \
           CLEVR (Johnson et al., CVPR 2017): 3 to 10 objects with procedural, photo-like \
           materials on a studio backdrop, sampled from a seed and rendered with Blender's Cycles \
           by clevrtex (after the public generator, karazijal/clevrtex-generation). Each sample is an image with its instance mask, the passes listed below and CLEVR \
           metadata (objects, their material, shape, size, colour, 3D and pixel coordinates, \
           the camera). Layout and file names follow the published ClevrTex; what its public \
           loader and evaluator (karazijal/clevrtex-generation `clevrtex_eval.py`) make of \
           each variant here:\n\n";
    for (v, runs) in variants {
        let (by_split, _) = counts(v, &runs.manifests);
        c += &format!("- {}\n", loader_claim(v, &by_split));
    }
    c += "\n";

    c += "## Contents\n\n";
    c += "| variant | test | val | train | planned | complete |\n|---|---|---|---|---|---|\n";
    for r in &rows {
        c += r;
        c += "\n";
    }
    c += "\n*planned*: the indices of the runs' ranges; *complete*: samples listed in a finished \
           run's manifest (check with `clevrtex verify`). Each sample's split is the `split` of \
           its metadata, fixed at generation from the run's `--total` (test the first \
           int(0.1 N), val up to int(0.2 N), train the rest) and kept when the dataset grows; \
           every clevrtex reader (`eval`, `export`, `report`, the Python `Dataset`) takes it \
           from there.\n\n";
    let passes: BTreeSet<Pass> = variants
        .values()
        .flat_map(|r| &r.manifests)
        .flat_map(|(_, m)| &m.passes)
        .filter_map(|p| Pass::from_name(p))
        .collect();
    c += "### Passes\n\n| pass | file | encoding in the file | in `clevrtex export` WebDataset shards |\n|---|---|---|---|\n";
    for p in &passes {
        let spec = p.spec();
        let e = &spec.encoding;
        let mut enc = format!("{}-bit {} PNG: {}", e.bits, e.channels, e.encoding);
        if let Some(s) = e.scale {
            let _ = write!(enc, "; scale {s}");
        }
        if let Some(b) = e.background {
            let _ = write!(
                enc,
                "; background {}",
                serde_json::to_string(&b).unwrap_or_default()
            );
        }
        let _ = writeln!(
            c,
            "| {} | `<stem>{}.png` | {} | `{}`: {} |",
            spec.name,
            spec.file_suffix,
            enc.replace('|', "/"),
            spec.webdataset_key,
            spec.webdataset_doc
        );
    }
    c += "\nEvery sample also has `<stem>.json` (its metadata, `passes` repeating these \
           encodings). Depth is planar (along the camera's view axis) in metres; normals are \
           world-space.\n\n";

    c += "## How it was made\n\n";
    c += "| variant | indices | shard | total | seed | config hash | clevrtex | Blender | finished |\n|---|---|---|---|---|---|---|---|---|\n";
    let mut commands: Vec<String> = Vec::new();
    let mut user_materials = false;
    for (v, runs) in variants {
        let mut list: Vec<&(String, Manifest)> = runs.manifests.iter().collect();
        list.sort_by_key(|(_, m)| (m.start, m.end, m.shard));
        for (_, m) in list {
            let _ = writeln!(
                c,
                "| {} | {}..{} | {}/{} | {} | {} | {} | {} | {} | {} |",
                code(v),
                m.start,
                m.end,
                m.shard[0],
                m.shard[1],
                m.total,
                m.seed,
                code(&m.config_hash),
                code(&parts::tool_of(m)),
                if m.blender_version.is_empty() {
                    "(none yet)".to_string()
                } else {
                    code(&m.blender_version)
                },
                if m.finished { "yes" } else { "no" }
            );
            user_materials |= m.command.iter().any(|a| a.starts_with("--materials"));
            let line = crate::verify::shell_words(&m.command);
            if !commands.contains(&line) {
                commands.push(line);
            }
        }
    }
    let mut render = RenderSettings::new();
    for r in variants.values() {
        for (k, runs) in &r.render {
            render.entry(*k).or_default().extend(runs.iter().cloned());
        }
    }
    c += &parts::render_lines(&render);
    c += "\nThe commands of the runs (rerunning one resumes and repairs it):\n\n";
    c += &fenced("sh", &commands);
    c += "\n";
    let used: BTreeMap<String, (Vec<&Manifest>, &Layouts)> = variants
        .iter()
        .map(|(v, r)| {
            (
                v.clone(),
                (r.manifests.iter().map(|(_, m)| m).collect(), &r.layouts),
            )
        })
        .collect();
    c += &parts::identity_section(suites, &used);
    c += &parts::materials_section(&used);

    c += "## Differences from the published ClevrTex\n\n";
    let builtin_text = "procedural Blender node recipes of clevrtex's catalogue \
           (`materials/` of the clevrtex repository), not the published set's materials, \
           which are made from Poliigon textures that the public generator \
           (karazijal/clevrtex-generation) cannot redistribute. Object and background \
           materials look alike in kind (wood, stone, fabric, metal, ...), not texel for texel";
    let user_text = "user materials given with `--materials` (listed with their content \
           hashes under \"Materials used\"), not the published set's; their likeness to it \
           is that of the files given";
    let _ = writeln!(
        c,
        "- **Materials**: {}.",
        match parts::all_user(&used) {
            Some(true) => user_text.to_string(),
            Some(false) => builtin_text.to_string(),
            None => format!("some {user_text}; the others {builtin_text}"),
        }
    );
    let _ = writeln!(
        c,
        "- **Sample count**: {planned_all} planned here; the published main ClevrTex set has \
         50,000 images (Karazija et al., 2021)."
    );
    if !render.is_empty() {
        let here: Vec<String> = render
            .keys()
            .map(|(w, h, s)| format!("{w}x{h} pixels and {s} samples per pixel"))
            .collect();
        let _ = writeln!(
            c,
            "- **Resolution and sampling**: {} here; the published set is 320x240, rendered \
             with the public generator's 512 samples.",
            here.join(", ")
        );
    }
    c += "- **Renderer**: the Blender versions in the table above; the published set was \
           rendered with Blender 2.92 (the public generator's README).\n\n";

    c += "## Licence\n\n";
    c += "clevrtex and its material catalogue are licensed under MIT OR Apache-2.0 \
           (`LICENSE-MIT`, `LICENSE-APACHE` of the clevrtex repository); the catalogue's \
           materials are procedural node recipes with no third-party texture. ";
    if user_materials || parts::all_user(&used) != Some(false) {
        c += "Some runs used user materials (`--materials`, see the commands above): their \
               licences apply to the images that show them. ";
    }
    c += "Whoever publishes this dataset chooses the licence of its images.\n\n";

    c += "## Citation\n\nIf you use this dataset, cite ClevrTex, CLEVR and the tool:\n\n";
    let version = variants
        .values()
        .flat_map(|r| &r.manifests)
        .map(|(_, m)| m.tool_version.as_str())
        .find(|v| {
            !v.is_empty()
                && v.chars()
                    .all(|c| c.is_ascii_alphanumeric() || ".-+".contains(c))
        })
        .unwrap_or(env!("CARGO_PKG_VERSION"));
    let bib = [
        "@inproceedings{karazija2021clevrtex,".to_string(),
        "  title     = {ClevrTex: A Texture-Rich Benchmark for Unsupervised Multi-Object Segmentation},".into(),
        "  author    = {Karazija, Laurynas and Laina, Iro and Rupprecht, Christian},".into(),
        "  booktitle = {Proceedings of the Neural Information Processing Systems Track on Datasets and Benchmarks},".into(),
        "  year      = {2021},".into(),
        "  url       = {https://arxiv.org/abs/2111.10265}".into(),
        "}".into(),
        String::new(),
        "@inproceedings{johnson2017clevr,".into(),
        "  title     = {CLEVR: A Diagnostic Dataset for Compositional Language and Elementary Visual Reasoning},".into(),
        "  author    = {Johnson, Justin and Hariharan, Bharath and van der Maaten, Laurens and Fei-Fei, Li and Zitnick, C. Lawrence and Girshick, Ross},".into(),
        "  booktitle = {Proceedings of the IEEE Conference on Computer Vision and Pattern Recognition (CVPR)},".into(),
        "  year      = {2017},".into(),
        "  url       = {https://arxiv.org/abs/1612.06890}".into(),
        "}".into(),
        String::new(),
    ];
    let mut bib = bib.to_vec();
    bib.extend(parts::tool_bibtex(version));
    c += &fenced("bibtex", &bib);
    c
}

/// Rewrite `OUT/DATASET_CARD.md` from every run manifest under `out` (see the module
/// documentation); the card's path. `Err` is one message with a `hint:` line.
pub fn write_card(out: &Path) -> Result<PathBuf, String> {
    let lock_path = out.join(CARD_LOCK);
    let lock = crate::run_lock::open_lock_file(&lock_path)?;
    lock.lock().map_err(|e| {
        format!(
            "cannot lock `{}`: {e}\nhint: check that `{}` is writable",
            lock_path.display(),
            out.display()
        )
    })?;
    let found = dataset::manifests_in(out).map_err(|e| {
        format!(
            "cannot read `{}`: {e}\nhint: check that the folder exists and is readable",
            out.display()
        )
    })?;
    let root = dataset::root(out).map_err(|e| format!("cannot read `{}`: {e}", out.display()))?;
    let mut variants: BTreeMap<String, VariantRuns> = BTreeMap::new();
    let mut suites = BTreeSet::new();
    let mut dirs: BTreeMap<String, PathBuf> = BTreeMap::new();
    for (v, path) in found {
        // A manifest that cannot be read is `verify`'s to report; the card shows the rest.
        let Ok(m) = Manifest::read(&path) else {
            continue;
        };
        // The suite a run was made for (`generate --suite`), when its manifest names one.
        if let Some(suite) = dataset::read(&root, &path, dataset::MAX_FILE_BYTES)
            .ok()
            .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
            .and_then(|j| j["suite"].as_str().map(str::to_string))
        {
            suites.insert(suite);
        }
        let vdir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
        dirs.entry(v.clone()).or_insert_with(|| vdir.clone());
        let runs = variants.entry(v.clone()).or_default();
        // The run's render settings: its manifest's, else (older manifests) a sample's.
        let render = parts::render_of(&m).or_else(|| {
            m.files
                .keys()
                .filter(|f| f.ends_with(".json") && !f.contains(".."))
                .find_map(|rel| {
                    let bytes =
                        dataset::read(&root, &vdir.join(rel), dataset::MAX_METADATA_BYTES).ok()?;
                    let meta: serde_json::Value = serde_json::from_slice(&bytes).ok()?;
                    let r = &meta["render"];
                    Some((
                        r["width"].as_u64()?,
                        r["height"].as_u64()?,
                        r["samples"].as_u64()?,
                    ))
                })
        });
        if let Some(r) = render {
            runs.render
                .entry(r)
                .or_default()
                .push(format!("{} {}..{}", code(&v), m.start, m.end));
        }
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        runs.manifests.push((name, m));
    }
    for (v, runs) in &mut variants {
        let list: Vec<&Manifest> = runs.manifests.iter().map(|(_, m)| m).collect();
        runs.layouts = fingerprint::layouts(&root, &dirs[v], &list);
    }
    let title = out
        .canonicalize()
        .ok()
        .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_else(|| "clevrtex dataset".into());
    let text = card_text(&title, &variants, &suites);
    let path = out.join(CARD_FILE);
    // The one atomic writer: a unique temporary, no link followed, removed on every error.
    crate::atomic::write(&path, text.as_bytes())
        .map_err(|e| crate::Error::write(&path, e).to_string())?;
    drop(lock);
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(start: u64, end: u64, total: u64, finished: bool) -> (String, Manifest) {
        let mut m = Manifest::unfinished();
        m.variant = "full".into();
        m.start = start;
        m.end = end;
        m.total = total;
        m.finished = finished;
        m.tool_version = "0.1.0".into();
        m.passes = vec!["rgb".into(), "mask".into(), "depth".into()];
        m.command = vec![
            "clevrtex".into(),
            "generate".into(),
            "--x`|\u{1b}[2J".into(),
        ];
        (String::new(), m)
    }

    #[test]
    fn counts_take_each_index_once_with_its_run_s_split() {
        // Grown: 0..10 of 10, then 10..20 of 20 (all train), and 0..10 run again.
        let runs = [
            run(0, 10, 10, true),
            run(10, 20, 20, false),
            run(0, 10, 10, true),
        ];
        let (by, _) = counts("full", &runs);
        assert_eq!(
            (by[&Split::Test], by[&Split::Val], by[&Split::Train]),
            (1, 1, 18)
        );
    }

    #[test]
    fn the_card_names_splits_passes_runs_and_escapes_what_manifests_say() {
        let mut variants = BTreeMap::new();
        variants.insert(
            "full".to_string(),
            VariantRuns {
                manifests: vec![run(0, 10, 10, true), run(10, 20, 20, true)],
                render: [((64, 48, 4), vec!["`full` 0..20".to_string()])].into(),
                layouts: Layouts::default(),
            },
        );
        let card = card_text("data", &variants, &BTreeSet::new());
        assert!(
            card.starts_with("---\npretty_name: \"data (clevrtex)\""),
            "{card}"
        );
        assert!(card.contains("| `full` | 1 | 1 | 18 | 20 | 0 |"), "{card}");
        assert!(
            card.contains("| depth | `<stem>_depth_0001.png` | 16-bit gray PNG"),
            "{card}"
        );
        assert!(
            card.contains("`depth.npy`: float32 (H, W) planar depth in metres"),
            "{card}"
        );
        assert!(
            card.contains("64x48 pixels and 4 samples per pixel here"),
            "{card}"
        );
        for section in [
            "## Dataset summary",
            "## Contents",
            "## How it was made",
            "## Differences from the published ClevrTex",
            "## Licence",
            "## Citation",
        ] {
            assert!(card.contains(section), "{section}");
        }
        // No raw escape sequence; the command's backtick cannot close its fence.
        assert!(!card.contains('\u{1b}'), "{card}");
        assert!(
            card.contains("@inproceedings{karazija2021clevrtex"),
            "{card}"
        );
    }

    #[test]
    fn the_card_describes_the_materials_used_and_the_runs_identity() {
        let (name, mut m) = run(0, 4, 4, true);
        m.tool_commit = "0123456789abcdef0123456789abcdef01234567".into();
        m.tool_modified = Some(true);
        m.user_materials.insert(
            "Bricks01".into(),
            crate::manifest::UserMaterial {
                file: "Bricks01.blend".into(),
                group: Some("Bricks01".into()),
                textures: vec!["tex/b.png".into()],
                xxh3: "00000000deadbeef".into(),
            },
        );
        let layouts = Layouts {
            fingerprint: "0123456789abcdef".into(),
            samples: 4,
            unread: 0,
            materials: [("Bricks01".to_string(), 13)].into(),
        };
        let mut variants = BTreeMap::new();
        variants.insert(
            "full".to_string(),
            VariantRuns {
                manifests: vec![(name, m)],
                render: BTreeMap::new(),
                layouts,
            },
        );
        let card = card_text("data", &variants, &BTreeSet::new());
        for want in [
            "| `Bricks01` | `Bricks01.blend` | `Bricks01` | 1 | `00000000deadbeef` | 13 |",
            "0 built-in material(s) of clevrtex's catalogue, 1 user material(s)",
            "- **Materials**: user materials given with `--materials`",
            "- **Suite**: none",
            "`0.1.0 @ 0123456789ab (modified)`",
            "`full`: `0123456789abcdef` over 4 sample(s)",
            "their licences apply",
        ] {
            assert!(card.contains(want), "{want:?} not in: {card}");
        }
        assert!(!card.contains("procedural Blender node recipes"), "{card}");
    }
}
