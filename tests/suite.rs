//! `generate --suite` (issue 41): the published suite made in shards equals the suite made in
//! one run (`verify --against`: layouts, masks and metadata image by image), its splits are
//! the public loader's for every variant that loader knows, a dataset grown with another
//! `--total` is refused before anything renders, and a suite's bad input is refused with
//! nothing written. (Runs of mixed settings failing `verify`:
//! `verify::runs_of_other_settings_in_one_folder_fail_verify_unless_mixed_on_purpose`.)

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Output;

use serde_json::Value;

use crate::util::{blender_or_skip, blender_wrapper, clevrtex, test_python_or_skip, text};

/// The suite's scale in these tests: the issue's try, 70 images (full 25, pbg, vbg, grassbg
/// and camo 10 each, outd 5), every variant with a test split.
const SCALE: &str = "0.0005";
/// The images per variant of the suite at scale 0.0001 (14 in all).
const SMALL_SUITE: [(&str, usize); 6] = [
    ("full", 5),
    ("pbg", 2),
    ("vbg", 2),
    ("grassbg", 2),
    ("camo", 2),
    ("outd", 1),
];
/// The public loader's variants: the suite's.
const VARIANTS: [&str; 6] = ["full", "pbg", "vbg", "grassbg", "camo", "outd"];

/// `clevrtex generate --suite clevrtex --scale SCALE` into `out`, tiny renders, then `extra`.
fn suite(blender: &Path, out: &Path, extra: &[&str]) -> Output {
    clevrtex()
        .args(["generate", "--suite", "clevrtex", "--scale", SCALE])
        .args(["--width", "32", "--height", "24", "--samples", "1"])
        .args(["--passes", "rgb,mask", "--blender"])
        .arg(blender)
        .arg("--out")
        .arg(out)
        .args(extra)
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("JOB_COMPLETION_INDEX")
        .output()
        .unwrap()
}

/// Every file below `dir` with its bytes (locks included: nothing may appear or change).
fn tree(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let bytes = std::fs::read(&p).unwrap_or_default();
                out.insert(p.strip_prefix(dir).unwrap().to_path_buf(), bytes);
            }
        }
    }
    out
}

/// The suite in two shards into `a`: `verify` calls `a` whole, the public loader's splits
/// equal `clevrtex.Dataset`'s, the suite's command run whole over it renders nothing, growing
/// a variant with another `--total` is refused before Blender starts, and `verify`'s repair
/// hints run as printed. (That shards make the bytes of one run:
/// `a_suites_variants_share_their_workers_and_make_what_fresh_workers_make`, on the smaller
/// suite.)
#[test]
fn a_suite_in_two_shards_is_whole_with_the_public_loaders_splits() {
    let Some(blender) = blender_or_skip("suite_in_two_shards") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let a = tmp.path().join("a");
    for shard in ["0/2", "1/2"] {
        let o = suite(&blender, &a, &["--shard", shard]);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(0), "shard {shard}: {t}");
        assert!(
            t.contains("70 images (full 25, pbg 10, vbg 10, grassbg 10, camo 10, outd 5)"),
            "{t}"
        );
    }

    let o = clevrtex().arg("verify").arg(&a).output().unwrap();
    let t = text(&o);
    assert_eq!(o.status.code(), Some(0), "{t}");
    assert!(
        t.contains("suite `clevrtex` at scale 0.0005: whole (6 variants, 70 images)"),
        "{t}"
    );

    // The public loader's splits (`tests/eval_reference/harness.py`, its `_reindex` and split
    // rule) against `clevrtex.Dataset`'s, for every variant, split by split.
    if let Some(python) = test_python_or_skip("suite_public_loader_splits", "clevrtex") {
        let script = r#"
import json, sys
sys.path.insert(0, sys.argv[1])
import harness, clevrtex
root = sys.argv[2]
public = harness.public_splits(root)
ours = {}
for v in public:
    ours[v] = {}
    for s in harness.PUBLIC_SPLITS:
        try:
            ds = clevrtex.Dataset(root, dataset_variant=v, split=s, return_metadata=False)
            ours[v][s] = [int(ds[i][0]) for i in range(len(ds))]
        except ValueError as e:
            if "is empty" not in str(e):
                raise
            ours[v][s] = []
print(json.dumps({"public": public, "ours": ours}))
"#;
        let o = std::process::Command::new(&python)
            .arg("-c")
            .arg(script)
            .arg(crate::util::repo_root().join("tests/eval_reference"))
            .arg(&a)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", text(&o));
        let v: Value = serde_json::from_slice(&o.stdout).unwrap();
        let public = v["public"].as_object().unwrap();
        assert_eq!(
            public.keys().map(String::as_str).collect::<Vec<_>>().len(),
            VARIANTS.len(),
            "{v}"
        );
        for variant in VARIANTS {
            assert_eq!(
                v["public"][variant], v["ours"][variant],
                "{variant}: the public loader's splits vs clevrtex.Dataset's"
            );
        }
        // The position rule over the whole variant: full's 25 images give test 2, val 3.
        assert_eq!(v["public"]["full"]["test"], serde_json::json!([0, 1]));
        assert_eq!(v["public"]["full"]["val"], serde_json::json!([2, 3, 4]));
        assert_eq!(v["public"]["pbg"]["test"], serde_json::json!([0]));
        assert_eq!(
            v["public"]["outd"]["test"],
            serde_json::json!([0, 1, 2, 3, 4])
        );
    }

    // The card names the suite, and every variant is read unchanged by the public loader.
    let card = std::fs::read_to_string(a.join("DATASET_CARD.md")).unwrap();
    assert!(card.contains("- **Suite**: `clevrtex`"), "{card}");
    for v in VARIANTS {
        assert!(
            card.contains(&format!(
                "- `{v}`: read unchanged (`CLEVRTEX(path, '{v}', split)`)"
            )),
            "{v}: {card}"
        );
    }

    // The suite's command again, whole (no `--shard`): every sample is complete, nothing
    // changes.
    let before = tree(&a);
    let o = suite(&blender, &a, &[]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let after = tree(&a);
    let changed: Vec<_> = after
        .iter()
        .filter(|(rel, bytes)| {
            let name = rel.file_name().unwrap().to_string_lossy();
            name.starts_with("CLEVRTEX_") && before.get(*rel) != Some(bytes)
        })
        .map(|(rel, _)| rel.display().to_string())
        .collect();
    assert!(changed.is_empty(), "a rerun changed {changed:?}");

    // Growing `full` past the suite's 25 with a run of another total: refused before anything
    // is made, and before Blender is started (the wrapper would leave its marker).
    let marker = tmp.path().join("blender-started");
    let bin = tmp.path().join("bin");
    std::fs::create_dir_all(&bin).unwrap();
    let wrapper = blender_wrapper(&bin, &format!(": > '{}'\nexit 1", marker.display()));
    let before = tree(&a);
    let o = clevrtex()
        .args(["generate", "--variant", "full", "--start", "25", "-n", "5"])
        .args(["--width", "32", "--height", "24", "--samples", "1"])
        .args(["--passes", "rgb,mask", "--blender"])
        .arg(&wrapper)
        .arg("--out")
        .arg(&a)
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("JOB_COMPLETION_INDEX")
        .output()
        .unwrap();
    let t = text(&o);
    assert_ne!(o.status.code(), Some(0), "{t}");
    // A plain `generate` in a suite's folder (issue 48): it would rewrite the variant's
    // manifest without the suite; refused, naming `SUITE.json` and the suite's command.
    assert!(
        t.contains("SUITE.json` records suite `clevrtex`")
            && t.contains("--suite clevrtex --scale 0.0005 --seed 0"),
        "{t}"
    );
    assert!(!marker.exists(), "Blender was started: {t}");
    assert_eq!(tree(&a), before, "the refused run wrote into the folder");

    // Issue 48: every repair hint `verify` prints for a suite runs as printed (the suite, its
    // scale and the size flags kept): a sample deleted from a two-shard suite, then the
    // suite's plan deleted.
    let blender_env = ("CLEVRTEX_BLENDER", blender.as_os_str());
    let run_hints = |t: &str| {
        let hints = printed_commands(t);
        assert!(!hints.is_empty(), "no command printed: {t}");
        for h in &hints {
            assert!(
                h.contains("--suite clevrtex --scale 0.0005") && h.contains("--width 32"),
                "{h}"
            );
            let words: Vec<&str> = h.split(' ').collect();
            assert_eq!(words[0], "clevrtex", "{h}");
            let o = clevrtex()
                .args(&words[1..])
                .env(blender_env.0, blender_env.1)
                .env_remove("SLURM_ARRAY_TASK_ID")
                .env_remove("JOB_COMPLETION_INDEX")
                .output()
                .unwrap();
            assert_eq!(o.status.code(), Some(0), "`{h}`: {}", text(&o));
        }
    };
    let verify = |dir: &Path| clevrtex().arg("verify").arg(dir).output().unwrap();
    for f in std::fs::read_dir(a.join("clevrtex_camo/0")).unwrap() {
        let p = f.unwrap().path();
        if p.file_name()
            .unwrap()
            .to_string_lossy()
            .starts_with("CLEVRTEX_camo_000001")
        {
            std::fs::remove_file(p).unwrap();
        }
    }
    let o = verify(&a);
    let t = text(&o);
    assert_ne!(o.status.code(), Some(0), "{t}");
    run_hints(&t);
    let o = verify(&a);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    // No `SUITE.json`: not whole, although every manifest records the suite.
    std::fs::remove_file(a.join("SUITE.json")).unwrap();
    let o = verify(&a);
    let t = text(&o);
    assert_ne!(o.status.code(), Some(0), "{t}");
    assert!(t.contains("no `SUITE.json` is in"), "{t}");
    run_hints(&t);
    let o = verify(&a);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(0), "{t}");
    assert!(t.contains("whole (6 variants, 70 images)"), "{t}");
}

/// The starts of Blender a run's summaries count (`blender start ... (N start(s))`, one line
/// per variant's run), added.
fn starts(t: &str) -> u64 {
    t.lines()
        .filter_map(|l| l.split_once("s  (")?.1.strip_suffix(" start(s))"))
        .map(|n| n.trim().parse::<u64>().unwrap())
        .sum()
}

/// Issue 51: a suite's variants share their Blender workers. The 14-image suite (scale
/// 0.0001: full 5, pbg, vbg, grassbg and camo 2 each, outd 1) with 2 workers starts Blender
/// twice in all, the later variants' runs taking the workers of the one before (9 times, said
/// in the suite's last line), and each variant's masks and metadata are byte-identical to a
/// plain `generate` of that variant alone with a fresh worker. A `render` of scene files of
/// two variants starts one worker for both.
#[test]
fn a_suites_variants_share_their_workers_and_make_what_fresh_workers_make() {
    let Some(blender) = blender_or_skip("suite_variants_share_workers") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let (shared, alone) = (tmp.path().join("shared"), tmp.path().join("alone"));
    let tiny = ["--width", "32", "--height", "24", "--samples", "1"];
    let passes = ["--passes", "rgb,mask", "--threads", "1", "--blender"];
    // The 14-image suite into `out` with `extra` (workers, shard).
    let small_suite = |out: &Path, extra: &[&str]| {
        clevrtex()
            .args(["generate", "--suite", "clevrtex", "--scale", "0.0001"])
            .args(tiny)
            .args(extra)
            .args(passes)
            .arg(&blender)
            .arg("--out")
            .arg(out)
            .env_remove("SLURM_ARRAY_TASK_ID")
            .env_remove("JOB_COMPLETION_INDEX")
            .output()
            .unwrap()
    };
    let o = small_suite(&shared, &["--workers", "2"]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(0), "{t}");
    assert!(
        t.contains("full 5, pbg 2, vbg 2, grassbg 2, camo 2, outd 1"),
        "{t}"
    );
    assert_eq!(starts(&t), 2, "{t}");
    assert!(
        t.contains("9 worker(s) carried on from one variant to the next"),
        "{t}"
    );
    let mut compared = 0;
    for (v, n) in SMALL_SUITE {
        let o = clevrtex()
            .args(["generate", "--variant", v, "-n", &n.to_string()])
            .args(tiny)
            .args(["--workers", "1"])
            .args(passes)
            .arg(&blender)
            .arg("--out")
            .arg(&alone)
            .env_remove("SLURM_ARRAY_TASK_ID")
            .env_remove("JOB_COMPLETION_INDEX")
            .output()
            .unwrap();
        let t = text(&o);
        assert_eq!(o.status.code(), Some(0), "{v}: {t}");
        assert_eq!(starts(&t), 1, "{v}: {t}");
        for i in 0..n {
            for suffix in ["_flat.png", ".json"] {
                let rel = format!("clevrtex_{v}/0/CLEVRTEX_{v}_{i:06}{suffix}");
                let want = std::fs::read(alone.join(&rel)).unwrap();
                assert!(
                    std::fs::read(shared.join(&rel)).unwrap() == want,
                    "{rel}: the suite's shared worker made other bytes than a fresh one"
                );
                compared += 1;
            }
        }
    }
    assert_eq!(compared, 28);

    // The suite in two shards is the suite of one run: `verify --against` finds the same
    // layouts, masks and metadata in every variant, and the files are byte-identical.
    let sharded = tmp.path().join("sharded");
    for shard in ["0/2", "1/2"] {
        let o = small_suite(&sharded, &["--workers", "1", "--shard", shard]);
        assert_eq!(o.status.code(), Some(0), "shard {shard}: {}", text(&o));
    }
    let o = clevrtex()
        .arg("verify")
        .arg(&sharded)
        .arg("--against")
        .arg(&shared)
        .output()
        .unwrap();
    let t = text(&o);
    assert_eq!(o.status.code(), Some(0), "{t}");
    assert!(
        t.contains("suite `clevrtex` at scale 0.0001: whole (6 variants, 14 images)"),
        "{t}"
    );
    for (v, n) in SMALL_SUITE {
        assert!(
            t.contains(&format!(
                "{v}: against `{}`: {n} of {n} image(s) in both hold the same layout, mask and metadata",
                shared.display()
            )),
            "{v}: {t}"
        );
    }
    let (ta, tb) = (tree(&sharded), tree(&shared));
    let mut compared = 0;
    for (rel, bytes) in &ta {
        let name = rel.file_name().unwrap().to_string_lossy();
        if name.starts_with("CLEVRTEX_") && (name.ends_with("_flat.png") || name.ends_with(".json"))
        {
            assert_eq!(Some(bytes), tb.get(rel), "{} differs", rel.display());
            compared += 1;
        }
    }
    assert_eq!(compared, 2 * 14);

    // `render` of scene files of two variants (made tiny): one pool, one worker for both.
    let (sampled, scenes) = (tmp.path().join("sampled"), tmp.path().join("scenes"));
    std::fs::create_dir_all(&scenes).unwrap();
    for v in ["pbg", "outd"] {
        let o = clevrtex()
            .args(["sample", "--variant", v, "-n", "1", "--out"])
            .arg(&sampled)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(0), "{v}: {}", text(&o));
        let name = format!("CLEVRTEX_{v}_000000.json");
        let file = sampled.join(format!("clevrtex_{v}/0/{name}"));
        let mut scene: Value = serde_json::from_slice(&std::fs::read(file).unwrap()).unwrap();
        for (key, value) in [("width", 32), ("height", 24), ("samples", 1)] {
            scene["render"][key] = value.into();
        }
        std::fs::write(scenes.join(name), scene.to_string()).unwrap();
    }
    let o = clevrtex()
        .arg("render")
        .arg(&scenes)
        .args(["--workers", "1"])
        .args(passes)
        .arg(&blender)
        .arg("--out")
        .arg(tmp.path().join("rendered"))
        .output()
        .unwrap();
    let t = text(&o);
    assert_eq!(o.status.code(), Some(0), "{t}");
    assert!(t.contains("rendered 2 images"), "{t}");
    assert_eq!(starts(&t), 1, "{t}");
}

/// The `clevrtex generate` commands a `verify` output offers: its indented command lines and
/// its back-quoted `rerun `...`` ones.
fn printed_commands(t: &str) -> Vec<String> {
    let mut v = Vec::new();
    for line in t.lines() {
        let line = line.trim();
        if line.starts_with("clevrtex generate ") {
            v.push(line.to_string());
        } else if let Some((_, rest)) = line.split_once("rerun `clevrtex generate ") {
            if let Some((cmd, _)) = rest.split_once('`') {
                v.push(format!("clevrtex generate {cmd}"));
            }
        }
    }
    v
}

/// Issue 48: two suites at different scales started together into one folder: the suite's
/// lock lets one write `SUITE.json`, the other is refused (never the loser's plan left).
#[test]
fn of_two_suites_started_together_one_is_refused_and_its_plan_never_written() {
    let tmp = tempfile::tempdir().unwrap();
    for attempt in 0..4 {
        let out = tmp.path().join(format!("out{attempt}"));
        let spawn = |scale: &str| {
            clevrtex()
                .args(["generate", "--suite", "clevrtex", "--scale", scale])
                .arg("--out")
                .arg(&out)
                .args(["--blender", "/nonexistent/blender"])
                .env_remove("SLURM_ARRAY_TASK_ID")
                .env_remove("JOB_COMPLETION_INDEX")
                .stdout(std::process::Stdio::piped())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .unwrap()
        };
        let (x, y) = (spawn("0.0005"), spawn("0.001"));
        let (x, y) = (x.wait_with_output().unwrap(), y.wait_with_output().unwrap());
        let refused = |o: &Output| text(o).contains("holds suite `clevrtex` at scale");
        assert!(
            refused(&x) != refused(&y),
            "exactly one must be refused:\n{}\n---\n{}",
            text(&x),
            text(&y)
        );
        let winner = if refused(&x) { "0.001" } else { "0.0005" };
        let plan: Value =
            serde_json::from_slice(&std::fs::read(out.join("SUITE.json")).unwrap()).unwrap();
        assert_eq!(plan["plan"]["scale"].to_string(), winner, "{plan}");
    }
}

/// A suite's bad input: an unknown suite, a scale that empties a variant or passes the index
/// cap, a folder holding a variant the suite does not have, and a folder of another suite's
/// plan: a message naming what is wrong, a non-zero exit, nothing written (no Blender needed:
/// every refusal comes first).
#[test]
fn a_suites_bad_input_is_refused_with_nothing_written() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let run = |args: &[&str], out: &Path| {
        let o = clevrtex()
            .arg("generate")
            .args(args)
            .arg("--out")
            .arg(out)
            .args(["--blender", "/nonexistent/blender"])
            .env_remove("SLURM_ARRAY_TASK_ID")
            .env_remove("JOB_COMPLETION_INDEX")
            .output()
            .unwrap();
        (o.status.code(), text(&o))
    };
    for (args, wants) in [
        (
            &["--variant", "full", "-n", "1", "--scale", "0.01"][..],
            &["`--scale 0.01` sizes a benchmark suite, and no `--suite` is given"][..],
        ),
        (
            &["--suite", "clevrtex", "--max-worker-memory", "0"][..],
            &["`--max-worker-memory 0` is out of range"][..],
        ),
        (
            &["--suite", "clevrtex2"][..],
            &["unknown suite `clevrtex2`", "pass one of: clevrtex"][..],
        ),
        (
            &["--suite", "clevrtex", "--scale", "0.00001"][..],
            &[
                "makes variant `pbg` of suite `clevrtex` empty",
                "at least 0.0001",
            ][..],
        ),
        (
            &["--suite", "clevrtex", "--scale", "3000"][..],
            &["makes variant `full` of suite `clevrtex` 150000000 images, over the cap"][..],
        ),
        (
            &["--suite", "clevrtex", "--scale=-1"][..],
            &["`--scale -1` is not a positive number"][..],
        ),
    ] {
        let (code, t) = run(args, &out);
        assert!(code.is_some_and(|c| c != 0), "{args:?}: {t}");
        for w in wants {
            assert!(t.contains(w), "{args:?}: {w:?} not in: {t}");
        }
        assert!(!out.exists(), "{args:?} wrote {}", out.display());
    }

    // A folder holding a variant the suite does not have.
    let foreign = tmp.path().join("foreign");
    std::fs::create_dir_all(foreign.join("clevrtex_clevr")).unwrap();
    let before = tree(&foreign);
    let (code, t) = run(&["--suite", "clevrtex", "--scale", SCALE], &foreign);
    assert!(code.is_some_and(|c| c != 0), "{t}");
    assert!(
        t.contains("holds `clevrtex_clevr`, a variant that suite `clevrtex` does not have"),
        "{t}"
    );
    assert_eq!(tree(&foreign), before);
    assert!(!foreign.join("SUITE.json").exists());

    // A folder of the suite at another scale: named, not resumed into.
    let other = tmp.path().join("other");
    std::fs::create_dir_all(&other).unwrap();
    let plan = clevrtex_scene::suite::find("clevrtex")
        .unwrap()
        .plan(0.001, 0)
        .unwrap();
    clevrtex_dataset::suite::write(&other, &plan).unwrap();
    let before = tree(&other);
    let (code, t) = run(&["--suite", "clevrtex", "--scale", SCALE], &other);
    assert!(code.is_some_and(|c| c != 0), "{t}");
    assert!(
        t.contains("holds suite `clevrtex` at scale 0.001 with seed 0, not suite `clevrtex` at scale 0.0005 with seed 0"),
        "{t}"
    );
    assert_eq!(tree(&other), before);

    // A plain `generate` into that suite's folder (issue 48): refused, naming the file.
    let (code, t) = run(&["--variant", "full", "-n", "2"], &other);
    assert!(code.is_some_and(|c| c != 0), "{t}");
    assert!(
        t.contains("SUITE.json` records suite `clevrtex`")
            && t.contains("generate --suite clevrtex --scale 0.001 --seed 0"),
        "{t}"
    );
    assert_eq!(tree(&other), before);
    // A `SUITE.json` that cannot be read is named.
    std::fs::write(other.join("SUITE.json"), b"{").unwrap();
    let (code, t) = run(&["--suite", "clevrtex", "--scale", SCALE], &other);
    assert!(code.is_some_and(|c| c != 0), "{t}");
    assert!(t.contains("SUITE.json` is not a suite file"), "{t}");
}
