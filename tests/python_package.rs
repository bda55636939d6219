//! The Python package `clevrtex` (`crates/python`): its pytest suite, run with the test venv's
//! Python (where `scripts/setup.sh --test-venv` installs the wheel `scripts/build_wheel.sh` makes)
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

/// Issue 49: the wheel that `scripts/build_wheel.sh` made (`dist/`, as `scripts/setup.sh
/// --test-venv` builds it) installs with pip into a fresh venv, offline and without Rust or a
/// build, and the package it installs is that venv's own and scores. numpy comes from the test
/// venv (a `.pth` line written after the install, after the fresh venv's own site-packages, so
/// its `clevrtex` comes first).
/// Skipped visibly without the wheel or the test venv; required in CI.
#[test]
fn the_wheel_installs_into_a_fresh_venv() {
    let test = "the_wheel_installs_into_a_fresh_venv";
    let Some(python) = test_python_or_skip(test, "numpy") else {
        return;
    };
    let dist = repo_root().join("dist");
    let wheel = std::fs::read_dir(&dist).ok().and_then(|d| {
        d.flatten()
            .map(|e| e.path())
            .filter(|p| {
                p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with("clevrtex-") && n.ends_with(".whl"))
            })
            .max_by_key(|p| p.metadata().and_then(|m| m.modified()).ok())
    });
    let Some(wheel) = wheel else {
        crate::util::skip(
            test,
            crate::util::REQUIRE_TOOLS,
            &format!("no wheel `clevrtex-*.whl` in `{}`", dist.display()),
            "run `./scripts/build_wheel.sh` (or `./scripts/setup.sh --test-venv`)",
        );
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let venv = dir.path().join("venv");
    let run = |cmd: &mut std::process::Command| {
        let out = cmd.output().unwrap();
        assert!(out.status.success(), "{cmd:?} failed:\n{}", text(&out));
        String::from_utf8_lossy(&out.stdout).trim().to_string()
    };
    // The test venv's base interpreter makes the fresh venv; its site-packages lends numpy.
    let base =
        run(std::process::Command::new(&python)
            .args(["-c", "import sys; print(sys._base_executable)"]));
    let lend = run(std::process::Command::new(&python).args([
        "-c",
        "import numpy, os; print(os.path.dirname(os.path.dirname(numpy.__file__)))",
    ]));
    run(std::process::Command::new(base)
        .args(["-m", "venv"])
        .arg(&venv));
    let fresh = venv.join("bin/python");
    let site = run(std::process::Command::new(&fresh).args([
        "-c",
        "import sysconfig; print(sysconfig.get_paths()['purelib'])",
    ]));
    run(std::process::Command::new(&fresh)
        .args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
            "--no-index",
            "--no-deps",
        ])
        .arg(&wheel));
    // Lent after the install: pip would otherwise take the test venv's `clevrtex` as installed.
    std::fs::write(
        std::path::Path::new(&site).join("lend_numpy.pth"),
        format!("{lend}\n"),
    )
    .unwrap();
    let code = "import clevrtex, numpy as np, sys\n\
                gt = np.array([[0, 1, 1], [0, 2, 2]], dtype=np.uint8)[None]\n\
                r = clevrtex.evaluate(gt, gt)\n\
                print(clevrtex.__file__.startswith(sys.prefix), r['mIoU'], r['ARI'])\n";
    let said = run(std::process::Command::new(&fresh).args(["-c", code]));
    assert_eq!(
        said, "True 1.0 1.0",
        "the fresh venv's clevrtex (from `{}`) must be its own and score a mask against itself as 1",
        wheel.display()
    );
}
