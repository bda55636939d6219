//! One split rule everywhere (issue 32): a dataset grown in two runs keeps the split each run
//! recorded, and `verify`, `export`, `eval`, `report` and the Python `Dataset` all give every
//! sample that split.

use std::collections::BTreeMap;

use serde_json::Value;

use crate::util::{blender_or_skip, clevrtex, test_python_or_skip, text};

/// `clevrtex ARGS...`, which must succeed; its output.
fn ok(args: &[&std::ffi::OsStr]) -> String {
    let o = clevrtex().args(args).output().unwrap();
    assert_eq!(o.status.code(), Some(0), "{args:?}: {}", text(&o));
    text(&o)
}

fn os(s: &str) -> &std::ffi::OsStr {
    s.as_ref()
}

/// Splits by index from `verify --json`'s ranges of one variant.
fn from_ranges(ranges: &Value) -> BTreeMap<u64, String> {
    let mut out = BTreeMap::new();
    for (split, list) in ranges.as_object().unwrap() {
        for r in list.as_array().unwrap() {
            for i in r[0].as_u64().unwrap()..=r[1].as_u64().unwrap() {
                out.insert(i, split.clone());
            }
        }
    }
    out
}

#[test]
fn a_dataset_grown_in_two_runs_has_one_split_per_sample_in_every_tool() {
    let Some(blender) = blender_or_skip("grown_dataset_splits") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    for start in ["0", "10"] {
        ok(&[
            os("generate"),
            os("--variant"),
            os("clevr"),
            os("--allow-split-mismatch"),
            os("--start"),
            os(start),
            os("-n"),
            os("10"),
            os("--seed"),
            os("4"),
            os("--width"),
            os("32"),
            os("--height"),
            os("24"),
            os("--samples"),
            os("1"),
            os("--passes"),
            os("rgb,mask"),
            os("--blender"),
            blender.as_os_str(),
            os("--out"),
            data.as_os_str(),
        ]);
    }
    // What the runs recorded: the first (`--total` 10) test 0 and val 1; the second
    // (`--total` 20, indices 10..20) all train, although the position rule over 20 samples
    // would put val at 2..4.
    let want: BTreeMap<u64, String> = (0..20)
        .map(|i| {
            let s = match i {
                0 => "test",
                1 => "val",
                _ => "train",
            };
            (i, s.to_string())
        })
        .collect();
    let stem = |i: u64| format!("CLEVRTEX_clevr_{i:06}");
    for i in 0..20u64 {
        let meta: Value = serde_json::from_slice(
            &std::fs::read(data.join(format!("clevrtex_clevr/0/{}.json", stem(i)))).unwrap(),
        )
        .unwrap();
        assert_eq!(meta["split"].as_str(), Some(want[&i].as_str()), "{i}");
    }

    // verify: whole (each recorded split is its run's), and the same splits.
    let json = dir.path().join("verify.json");
    let out = ok(&[
        os("verify"),
        data.as_os_str(),
        os("--json"),
        json.as_os_str(),
    ]);
    assert!(out.contains("splits: test 1, val 1, train 18"), "{out}");
    let v: Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(from_ranges(&v[0]["splits"]), want, "{v}");

    // export: each sample in the shards of its split.
    let shards = dir.path().join("wds");
    ok(&[os("export"), data.as_os_str(), shards.as_os_str()]);
    let mut exported = BTreeMap::new();
    for e in std::fs::read_dir(&shards).unwrap().flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let Some(rest) = name.strip_prefix("clevr-") else {
            continue;
        };
        let split = rest.split('-').next().unwrap().to_string();
        let mut a = tar::Archive::new(std::fs::File::open(e.path()).unwrap());
        for entry in a.entries().unwrap() {
            let p = entry.unwrap().path().unwrap().display().to_string();
            if let Some(s) = p.strip_suffix(".json") {
                let i: u64 = s.rsplit('_').next().unwrap().parse().unwrap();
                exported.insert(i, split.clone());
            }
        }
    }
    assert_eq!(exported, want);

    // eval: the stems each split scores (no predictions: all scored as background).
    let preds = dir.path().join("preds");
    std::fs::create_dir(&preds).unwrap();
    let mut scored = BTreeMap::new();
    for split in ["test", "val", "train"] {
        let csv = dir.path().join(format!("{split}.csv"));
        ok(&[
            os("eval"),
            preds.as_os_str(),
            data.as_os_str(),
            os("--split"),
            os(split),
            os("--allow-missing"),
            os("--bootstrap"),
            os("0"),
            os("--csv"),
            csv.as_os_str(),
        ]);
        let text = std::fs::read_to_string(&csv).unwrap();
        for line in text.lines().skip(1) {
            let i = (0..20u64)
                .find(|i| line.contains(&stem(*i)))
                .unwrap_or_else(|| panic!("no stem in `{line}`"));
            assert!(scored.insert(i, split.to_string()).is_none(), "{i} twice");
        }
    }
    assert_eq!(scored, want);

    // report: the table of images per split.
    let page = dir.path().join("report.html");
    ok(&[
        os("report"),
        os("--out"),
        page.as_os_str(),
        data.as_os_str(),
    ]);
    let html = std::fs::read_to_string(&page).unwrap();
    let table = html
        .split("Images per variant and split")
        .nth(1)
        .unwrap()
        .split("</table>")
        .next()
        .unwrap();
    assert!(
        table.contains("<th>train</th><th>val</th><th>test</th>")
            && table.contains("<tr><td>clevr</td><td>18</td><td>1</td><td>1</td><td>20</td></tr>"),
        "{table}"
    );

    // A recorded split that is not its run's is reported, naming the sample (the run of
    // 10..20 of 20 gives index 12 `train`).
    let copy = dir.path().join("edited");
    assert!(std::process::Command::new("cp")
        .arg("-a")
        .arg(&data)
        .arg(&copy)
        .status()
        .unwrap()
        .success());
    let f = copy.join(format!("clevrtex_clevr/0/{}.json", stem(12)));
    let mut meta: Value = serde_json::from_slice(&std::fs::read(&f).unwrap()).unwrap();
    meta["split"] = "val".into();
    std::fs::write(&f, serde_json::to_vec(&meta).unwrap()).unwrap();
    let o = clevrtex().arg("verify").arg(&copy).output().unwrap();
    assert_eq!(o.status.code(), Some(3), "{}", text(&o));
    assert!(
        text(&o).contains(&format!("{} (`", stem(12)))
            && text(&o).contains(
                "metadata `split` is `val`, but the run of indices 10..20 of 20 (`MANIFEST-10-20-0of1.json`) puts index 12 in `train`"
            ),
        "{}",
        text(&o)
    );

    // The Python `Dataset` (its Rust reader): the indices of each split.
    let Some(python) = test_python_or_skip("grown_dataset_splits (Python half)", "clevrtex") else {
        return;
    };
    let script = r#"
import sys, clevrtex
from clevrtex import _native
for split in ("test", "val", "train"):
    idx = [s[0] for s in _native.discover(sys.argv[1], "clevr", split)[1]]
    assert len(clevrtex.Dataset(sys.argv[1], "clevr", split=split)) == len(idx)
    print(split, " ".join(map(str, idx)))
"#;
    let o = std::process::Command::new(&python)
        .args(["-c", script])
        .arg(&data)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let mut python_splits = BTreeMap::new();
    for line in String::from_utf8_lossy(&o.stdout).lines() {
        let mut words = line.split(' ');
        let split = words.next().unwrap().to_string();
        for i in words.filter(|w| !w.is_empty()) {
            python_splits.insert(i.parse::<u64>().unwrap(), split.clone());
        }
    }
    assert_eq!(python_splits, want);
}

/// An empty split is an error naming the split sizes found, in `eval` and the Python
/// `Dataset` alike (a dataset recording no split, like the published ClevrTex, is split by
/// position: 5 samples give test 0, val 1, train 4).
#[test]
fn an_empty_split_is_an_error_naming_the_sizes() {
    let dir = tempfile::tempdir().unwrap();
    let g = dir.path().join("gt");
    let src = crate::util::data("eval/gt/clevrtex_vbg/0");
    let dst = g.join("clevrtex_vbg/0");
    std::fs::create_dir_all(&dst).unwrap();
    for e in std::fs::read_dir(&src).unwrap().flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let index: u64 = name[13..19].parse().unwrap();
        if index < 5 {
            std::fs::copy(e.path(), dst.join(&name)).unwrap();
        }
    }
    let preds = dir.path().join("preds");
    std::fs::create_dir(&preds).unwrap();
    let o = clevrtex()
        .arg("eval")
        .arg(&preds)
        .arg(&g)
        .args(["--allow-missing", "--bootstrap", "0"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("it has 5 samples in all (test 0, val 1, train 4)"),
        "{}",
        text(&o)
    );
    let Some(python) = test_python_or_skip("an_empty_split_is_an_error (Python half)", "clevrtex")
    else {
        return;
    };
    let script = r#"
import sys, clevrtex
try:
    clevrtex.Dataset(sys.argv[1], "vbg", split="test")
except ValueError as e:
    print(e)
else:
    raise SystemExit("no error")
"#;
    let o = std::process::Command::new(&python)
        .args(["-c", script])
        .arg(&g)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("the `test` split of") && out.contains("(test 0, val 1, train 4)"),
        "{out}"
    );
}
