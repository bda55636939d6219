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
