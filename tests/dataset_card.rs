//! `DATASET_CARD.md` (issue 32): `generate` writes it into its `--out` folder from the union
//! of the runs' manifests, so shards writing into one folder at once leave a card of every
//! run; `verify`, `export` and `report` do not take it for a file of the dataset.

use crate::many_writers::generate;
use crate::util::{blender_or_skip, clevrtex, text};

#[test]
fn shards_writing_at_once_leave_a_card_of_every_run() {
    let Some(blender) = blender_or_skip("shards_writing_at_once_leave_a_card_of_every_run") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("data");
    // Two shards of 0..4 at once, then the dataset grown by 4..6 (`--total` 6).
    let children: Vec<_> = ["0/2", "1/2"]
        .iter()
        .map(|s| {
            generate(&blender, &out, &["-n", "4", "--shard", s])
                .stdout(std::process::Stdio::piped())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .unwrap()
        })
        .collect();
    for c in children {
        let o = c.wait_with_output().unwrap();
        assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    }
    let card = std::fs::read_to_string(out.join("DATASET_CARD.md")).unwrap();
    for row in [
        "| `clevr` | 0..4 | 0/2 | 4 |",
        "| `clevr` | 0..4 | 1/2 | 4 |",
    ] {
        assert!(card.contains(row), "{row}\n{card}");
    }
    assert!(card.contains("| `clevr` | 0 | 0 | 4 | 4 | 4 |"), "{card}");
    let o = generate(
        &blender,
        &out,
        &["--start", "4", "-n", "2", "--allow-split-mismatch"],
    )
    .output()
    .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let card = std::fs::read_to_string(out.join("DATASET_CARD.md")).unwrap();
    assert!(card.contains("| `clevr` | 0 | 0 | 6 | 6 | 6 |"), "{card}");
    assert!(
        card.contains("--shard 1/2") && card.contains("--start 4"),
        "{card}"
    );
    assert!(!card.contains("| depth |") && card.contains("| mask | `<stem>_flat.png`"));
    assert!(
        card.contains("32x24 pixels, 1 Cycles samples per pixel"),
        "{card}"
    );
    // Issue 41: what a paper names: the suite (none here), the tool's version and commit (as
    // `--version` and the manifests give it), the layouts' fingerprint, the materials used,
    // and a citation of the tool with its repository and year.
    let version = text(&clevrtex().arg("--version").output().unwrap());
    let commit = version
        .split("commit ")
        .nth(1)
        .and_then(|r| r.get(..12))
        .unwrap_or_else(|| panic!("no commit in `--version`: {version}"));
    let manifest: serde_json::Value = serde_json::from_slice(
        &std::fs::read(out.join("clevrtex_clevr/MANIFEST-4-6-0of1.json")).unwrap(),
    )
    .unwrap();
    assert!(
        manifest["tool_commit"]
            .as_str()
            .is_some_and(|c| c.starts_with(commit)),
        "{manifest}"
    );
    for want in [
        "- **Suite**: none".to_string(),
        "- `clevr`: not a variant the public loader knows".to_string(),
        format!("`0.1.0 @ {commit}"),
        "over 6 sample(s)".to_string(),
        "### Materials used".to_string(),
        "- built-in: `metal`".to_string(),
        "  url     = {https://".to_string(),
        "  year    = {20".to_string(),
    ] {
        assert!(card.contains(&want), "{want:?} not in: {card}");
    }
    assert!(card.contains("- **Materials**: procedural"), "{card}");
    // No temporary is left, and the card is no file of the dataset to the readers.
    let names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        !names.iter().any(|n| n.contains("clevrtex-tmp")),
        "{names:?}"
    );
    let o = clevrtex().arg("verify").arg(&out).output().unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let o = clevrtex()
        .arg("export")
        .arg(&out)
        .arg(dir.path().join("wds"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(!text(&o).contains("DATASET_CARD"), "{}", text(&o));
    let o = clevrtex()
        .arg("report")
        .arg("--out")
        .arg(dir.path().join("report.html"))
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(!text(&o).contains("DATASET_CARD"), "{}", text(&o));
}

/// Issue 41: the card says variant by variant what the public loader makes of the folder,
/// and the card, `verify` and `report` say where a grown variant's recorded splits are not
/// the public loader's: `camo` grown from 12 to 20 images with another `--total` (the loader
/// cuts test 2, val 2, train 16; the runs recorded test 1, val 1, train 18), `pbg` made in one
/// run (read unchanged), `clevr` (a variant the public loader does not know).
#[test]
fn the_card_says_what_the_public_loader_makes_of_each_variant() {
    let Some(blender) = blender_or_skip("the_card_says_what_the_public_loader_makes") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("data");
    for args in [
        &["--variant", "camo", "-n", "12"][..],
        &[
            "--variant",
            "camo",
            "--start",
            "12",
            "-n",
            "8",
            "--allow-split-mismatch",
        ][..],
        &["--variant", "pbg", "-n", "10"][..],
        &["--variant", "clevr", "-n", "3"][..],
    ] {
        let o = clevrtex()
            .arg("generate")
            .args(args)
            .args(["--width", "32", "--height", "24", "--samples", "1"])
            .args(["--passes", "rgb,mask", "--blender"])
            .arg(&blender)
            .arg("--out")
            .arg(&out)
            .env_remove("SLURM_ARRAY_TASK_ID")
            .env_remove("JOB_COMPLETION_INDEX")
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(0), "{args:?}: {}", text(&o));
    }
    let card = std::fs::read_to_string(out.join("DATASET_CARD.md")).unwrap();
    for want in [
        "- `camo`: read, but with other splits than those recorded here: its position rule over all 20 samples gives test 2, val 2, train 16, the runs recorded test 1, val 1, train 18",
        "- `pbg`: read unchanged (`CLEVRTEX(path, 'pbg', split)`), with the splits recorded here (test 1, val 1, train 8)",
        "- `clevr`: not a variant the public loader knows (it raises `Unknown variant clevr`)",
    ] {
        assert!(card.contains(want), "{want:?} not in: {card}");
    }
    assert!(!card.contains("read this dataset unchanged"), "{card}");

    let o = clevrtex().arg("verify").arg(&out).output().unwrap();
    let t = text(&o);
    assert_eq!(o.status.code(), Some(0), "{t}");
    assert!(
        t.contains("the recorded splits (test 1, val 1, train 18) differ from the public loader's position rule over these 20 samples (test 2, val 2, train 16)"),
        "{t}"
    );
    let html = dir.path().join("report.html");
    let o = clevrtex()
        .arg("report")
        .arg("--out")
        .arg(&html)
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let page = std::fs::read_to_string(&html).unwrap();
    assert!(
        page.contains("<b>warning</b>: camo: the recorded splits (test 1, val 1, train 18) differ"),
        "no split warning for camo in the report"
    );
    assert!(
        !page.contains("<b>warning</b>: pbg:"),
        "pbg's splits are the loader's"
    );
}
