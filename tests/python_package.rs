//! The Python package `clevrtex` (`crates/python`): its pytest suite, run with the test venv's
//! Python (where `scripts/setup.sh --test-venv` installs it with `pip install ./crates/python`)
//! and this build's CLI, which it compares itself with. Skipped visibly without it; required
//! under `CLEVRTEX_REQUIRE_TOOLS=1` (CI).

use crate::util::{repo_root, test_python_or_skip, text};

#[test]
fn python_package_pytest_suite_passes() {
    let Some(python) = test_python_or_skip(
        "python_package_pytest_suite_passes",
        "clevrtex, pytest, scipy, sklearn, PIL",
    ) else {
        return;
    };
    let out = std::process::Command::new(python)
        .args([
            "-m",
            "pytest",
            "-q",
            "-p",
            "no:cacheprovider",
            "crates/python/tests",
        ])
        .current_dir(repo_root())
        .env("CLEVRTEX_BIN", env!("CARGO_BIN_EXE_clevrtex"))
        .output()
        .unwrap();
    let all = text(&out);
    assert!(out.status.success(), "pytest failed:\n{all}");
    assert!(all.contains(" passed"), "{all}");
    assert!(
        !all.contains("skipped"),
        "no package test may skip here:\n{all}"
    );
}

/// Issue 32: `examples/train_toy.py` end to end: a tiny dataset generated with this build and
/// real Blender, loaded through torch's `DataLoader` (batch 8, 2 workers, `clevrtex.collate`)
/// with per-object masks and depth, a few training steps, masks scored by `clevrtex.Evaluator`.
/// Skipped visibly without torch (`./scripts/setup.sh --torch`) or Blender; required in CI.
#[test]
fn toy_training_loop_runs_end_to_end() {
    let test = "toy_training_loop_runs_end_to_end";
    let Some(python) = test_python_or_skip(test, "clevrtex, torch") else {
        return;
    };
    if crate::util::blender_or_skip(test).is_none() {
        return;
    }
    let out = std::process::Command::new(python)
        .arg("examples/train_toy.py")
        .current_dir(repo_root())
        .env("CLEVRTEX_BIN", env!("CARGO_BIN_EXE_clevrtex"))
        .output()
        .unwrap();
    let all = text(&out);
    assert!(out.status.success(), "train_toy.py failed:\n{all}");
    let last = String::from_utf8_lossy(&out.stdout)
        .lines()
        .last()
        .unwrap_or_default()
        .to_string();
    let summary: serde_json::Value =
        serde_json::from_str(&last).unwrap_or_else(|e| panic!("{e}: last line {last:?}\n{all}"));
    assert_eq!(summary["images"], 16, "{all}");
    assert_eq!(summary["steps"], 12, "{all}");
    let params = summary["parameters"].as_u64().unwrap();
    assert!((1000..10_000).contains(&params), "{params} parameters");
    for key in ["first_loss", "last_loss", "mIoU", "ARI_FG"] {
        let v = summary[key].as_f64().unwrap_or(f64::NAN);
        assert!(v.is_finite(), "`{key}` is {v}:\n{all}");
    }
    let miou = summary["mIoU"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&miou), "{miou}");
}
