use std::path::Path;

use clevrtex_scene::Pass;

use crate::dataset::{self};
use crate::layout::{self};

use super::command::*;
use super::*;

#[test]
fn ranges_and_rerun_commands_print_safely() {
    assert_eq!(index_ranges(&[0, 3, 4, 5, 9]), "0, 3..=5, 9");
    let many: Vec<u64> = (0..50).map(|i| 2 * i).collect();
    assert!(index_ranges(&many).ends_with(", ... (30 more ranges)"));
    let cmd = ["clevrtex", "generate", "--out", "a b", "x;rm -rf ~", "it's"].map(String::from);
    assert_eq!(
        shell_words(&cmd),
        r"clevrtex generate --out 'a b' 'x;rm -rf ~' 'it'\''s'"
    );
    let hidden = ["\u{1b}[2K\rclevrtex".to_string()];
    assert_eq!(shell_words(&hidden), r"'\u{1b}[2K\u{d}clevrtex'");
}

/// A manifest's command is untrusted: the rerun offered keeps only flags of the fixed
/// list with plain values (before, `--blender /tmp/evil.sh` was offered as it was).
#[test]
fn the_rerun_offers_no_program_from_a_manifest() {
    let c: Vec<String> = [
        "/tmp/evil",
        "generate",
        "--blender",
        "/tmp/evil.sh",
        "--seed",
        "3",
        "-n",
        "4",
        "--blender=/tmp/x.sh",
        "--config",
        "$(rm -rf ~)",
        "--keep-exr",
        "--out",
        "/old",
        "--shard",
        "0/2",
        "--exec",
        "sh",
    ]
    .map(String::from)
    .to_vec();
    let r = rerun_command(&c, Path::new("/new")).unwrap();
    assert_eq!(
        r,
        [
            "clevrtex",
            "generate",
            "--seed",
            "3",
            "-n",
            "4",
            "--keep-exr",
            "--out",
            "/new",
            "--shard",
            "0/2"
        ]
    );
    assert!(!shell_words(&r).contains("evil"));
    assert_eq!(
        with_shard(&r, 1, 2)[..],
        [
            "clevrtex",
            "generate",
            "--seed",
            "3",
            "-n",
            "4",
            "--keep-exr",
            "--out",
            "/new",
            "--shard",
            "1/2"
        ]
    );
    let other = ["clevrtex", "render", "x"].map(String::from).to_vec();
    assert!(rerun_command(&other, Path::new("/new")).is_none());
}

#[test]
fn the_rerun_writes_where_verify_looked() {
    let c: Vec<String> = ["clevrtex", "generate", "--out", "/old", "-n", "4"]
        .map(String::from)
        .to_vec();
    assert_eq!(
        with_out(&c, Path::new("/new")),
        ["clevrtex", "generate", "--out", "/new", "-n", "4"]
    );
    let c: Vec<String> = ["clevrtex", "generate", "--out=/old"]
        .map(String::from)
        .to_vec();
    assert_eq!(
        with_out(&c, Path::new("/new")),
        ["clevrtex", "generate", "--out=/new"]
    );
}

/// `--remove-broken` deletes relative to a folder handle opened inside the dataset: a
/// bucket swapped for a link to a canary folder while it runs (here between two samples)
/// is refused, and nothing in the canary is deleted. Before, the canary's files of the
/// layout's names were deleted.
#[test]
fn remove_broken_deletes_nothing_through_a_swapped_bucket() {
    let data = tempfile::tempdir().unwrap();
    let canary = tempfile::tempdir().unwrap();
    let root = dataset::root(data.path()).unwrap();
    let v = root.join("clevrtex_full");
    let mut broken = Vec::new();
    for index in [0u64, 1000] {
        let dir = layout::sample_dir(&root, "full", index);
        std::fs::create_dir_all(&dir).unwrap();
        let stem = layout::stem("full", index);
        for f in [
            layout::metadata_file(&stem),
            layout::pass_file(&stem, Pass::Rgb),
        ] {
            std::fs::write(dir.join(&f), b"x").unwrap();
            std::fs::write(canary.path().join(&f), b"canary").unwrap();
        }
        broken.push(Broken {
            index,
            stem,
            dir,
            problems: vec!["broken".into()],
            rerun_remakes: true,
        });
    }
    let report = VariantReport {
        variant: "full".into(),
        broken,
        roots: vec![root.clone()],
        ..VariantReport::default()
    };
    let second = v.join("1");
    let mut swap = |dir: &Path| {
        if dir == second {
            std::fs::rename(&second, v.join("moved")).unwrap();
            std::os::unix::fs::symlink(canary.path(), &second).unwrap();
        }
    };
    let got = remove_broken_with(&report, &mut swap);
    let e = got.unwrap_err().to_string();
    assert!(e.contains("leads out of the dataset"), "{e}");
    assert_eq!(
        std::fs::read_dir(canary.path()).unwrap().count(),
        4,
        "nothing in the canary is deleted"
    );
    assert_eq!(
        std::fs::read_dir(v.join("0")).unwrap().count(),
        0,
        "the first sample went"
    );
    assert_eq!(std::fs::read_dir(v.join("moved")).unwrap().count(), 2);
}
