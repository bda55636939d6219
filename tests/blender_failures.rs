//! A Blender that is missing, crashes, hangs, babbles, never starts or cannot build a scene:
//! retries, time limits and messages (mostly the fake Blender of `tests/fake_blender/`), and
//! `doctor` on a broken Blender.

use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::{Duration, Instant};

use serde_json::Value;

use crate::generate::{fake_blender, files_under, generate_fake, ledger_lines};
use crate::util::{blender_or_skip, clevrtex, data, text};

#[test]
fn missing_blender_is_named_with_the_install_hint() {
    let dir = tempfile::tempdir().unwrap();
    let out = clevrtex()
        .args([
            "generate",
            "--variant",
            "clevr",
            "-n",
            "1",
            "--blender",
            "/no/such/blender",
            "--out",
        ])
        .arg(dir.path())
        .output()
        .unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert!(t.contains("`/no/such/blender`"), "{t}");
    assert!(t.contains("apt-get install blender"), "{t}");
    assert!(t.contains("--blender"), "{t}");
}

#[test]
fn fake_crash_is_retried_then_recorded_in_the_ledger() {
    let dir = tempfile::tempdir().unwrap();
    let out = generate_fake("crash", dir.path(), &["-n", "1", "--retries", "1"]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(3), "partial exit code\n{t}");
    // The report names the program, the exit status and the stderr tail.
    assert!(t.contains("restarting a Blender worker"), "{t}");
    assert!(t.contains("SIGSEGV"), "{t}");
    assert!(t.contains("--- stderr"), "{t}");
    assert!(t.contains("segmentation fault while rendering"), "{t}");
    let ledger = ledger_lines(dir.path());
    assert_eq!(ledger.len(), 1, "{ledger:?}");
    assert_eq!(ledger[0]["index"], 0);
    assert_eq!(ledger[0]["stem"], "CLEVRTEX_clevr_000000");
    assert!(
        !files_under(dir.path()).iter().any(|f| f.ends_with(".png")),
        "no image of a failed sample: {:?}",
        files_under(dir.path())
    );
}

#[test]
fn doctor_names_a_broken_blender_with_its_stderr_tail() {
    let out = clevrtex()
        .env("FAKE_BLENDER_MODE", "noready")
        .env_remove("CLEVRTEX_BLENDER")
        .args(["doctor", "--blender"])
        .arg(fake_blender())
        .output()
        .unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert!(t.contains("No module named 'bpy'"), "{t}");
    assert!(
        !t.contains("run `clevrtex doctor`"),
        "doctor points to itself: {t}"
    );
    assert!(t.contains("apt-get install blender"), "{t}");
}

#[test]
fn fake_hang_times_out_and_is_killed() {
    let dir = tempfile::tempdir().unwrap();
    let t0 = Instant::now();
    let out = generate_fake(
        "hang",
        dir.path(),
        &["-n", "1", "--retries", "0", "--timeout", "1.5"],
    );
    let t = text(&out);
    assert_eq!(out.status.code(), Some(3), "{t}");
    assert!(t.contains("timed out after 1.5 s"), "{t}");
    assert!(
        t.contains("CLEVRTEX_clevr_000000"),
        "the report names the scene\n{t}"
    );
    assert!(
        t0.elapsed() < Duration::from_secs(30),
        "took {:?}",
        t0.elapsed()
    );
    assert_eq!(ledger_lines(dir.path()).len(), 1);
}

#[test]
fn fake_garbage_is_a_protocol_error() {
    let dir = tempfile::tempdir().unwrap();
    let out = generate_fake("garbage", dir.path(), &["-n", "1", "--retries", "0"]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(3), "{t}");
    assert!(t.contains("malformed reply"), "{t}");
    assert!(t.contains("this is not json"), "{t}");
    // Says what happened, not that the install is broken.
    assert!(t.contains("a reply line was cut or garbled"), "{t}");
    assert!(!t.contains("disagree") && !t.contains("reinstall"), "{t}");
}

#[test]
fn fake_chatter_then_exit_is_a_crash_not_a_reply() {
    let dir = tempfile::tempdir().unwrap();
    let out = generate_fake("chatter", dir.path(), &["-n", "1", "--retries", "0"]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(3), "{t}");
    assert!(t.contains("exited (exit status: 0)"), "{t}");
    assert!(
        t.contains("--- stdout (last 25 lines)"),
        "chatter is kept as a tail\n{t}"
    );
}

#[test]
fn fake_crash_with_fail_fast_stops_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let out = generate_fake(
        "crash",
        dir.path(),
        &["-n", "3", "--retries", "0", "--fail-fast"],
    );
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert_eq!(
        ledger_lines(dir.path()).len(),
        1,
        "stopped after the first failure\n{t}"
    );
}

#[test]
fn broken_blender_stops_the_run_with_its_stderr_tail() {
    let dir = tempfile::tempdir().unwrap();
    let out = generate_fake("noready", dir.path(), &["-n", "2"]);
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert!(t.contains("No module named 'bpy'"), "{t}");
    assert!(
        ledger_lines(dir.path()).is_empty(),
        "a broken install is not a per-image failure"
    );
}

#[test]
fn a_silent_worker_is_hung_long_before_the_overall_limit() {
    // A wrapper selects the fake's mode without touching this process's environment.
    let dir = tempfile::tempdir().unwrap();
    let wrapper = dir.path().join("blender");
    std::fs::write(
        &wrapper,
        format!(
            "#!/bin/sh\nFAKE_BLENDER_MODE=hang exec '{}' \"$@\"\n",
            fake_blender().display()
        ),
    )
    .unwrap();
    std::process::Command::new("chmod")
        .arg("+x")
        .arg(&wrapper)
        .status()
        .unwrap();
    let bridge = clevrtex_render::BridgeDir::create("{}").unwrap();
    let mut worker = clevrtex_render::Worker::start(
        &clevrtex_render::WorkerOptions::new(wrapper, &bridge, Arc::new(AtomicBool::new(false)))
            .with_threads(1)
            .with_startup_timeout(Duration::from_secs(30)),
    )
    .unwrap();
    worker.set_idle_timeout(Some(Duration::from_secs(1)));
    let t0 = Instant::now();
    let err = worker
        .render(
            &dir.path().join("scene.json"),
            clevrtex_render::Mode::Final,
            dir.path(),
            Duration::from_secs(120),
        )
        .unwrap_err();
    assert!(t0.elapsed() < Duration::from_secs(20), "{:?}", t0.elapsed());
    assert!(err.is_worker_failure());
    assert!(err.to_string().contains("silent for"), "{err}");
    assert!(worker.is_dead());
}

/// `clevrtex doctor` with a program that never answers: killed and reported within its
/// `--timeout`, not a hang.
#[test]
fn doctor_reports_a_blender_that_never_answers() {
    let t = Instant::now();
    let out = clevrtex()
        .env("FAKE_BLENDER_MODE", "deaf")
        .args(["doctor", "--timeout", "2", "--blender"])
        .arg(fake_blender())
        .output()
        .unwrap();
    let t_ = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t_}");
    assert!(
        t_.contains("--version` did not answer within 2 s; it was killed"),
        "{t_}"
    );
    assert!(t.elapsed() < Duration::from_secs(20), "{:?}", t.elapsed());
}

/// SIGTERM while `doctor` waits for `BLENDER --version` kills the probe's process group: it
/// was left running, orphaned (third hostile pass, issue 21).
#[test]
fn doctor_leaves_no_version_probe_behind_on_sigterm() {
    let dir = tempfile::tempdir().unwrap();
    let marker = format!("clevrtex-doctor-probe-{}", std::process::id());
    let script = dir.path().join("blender");
    std::fs::write(
        &script,
        format!("#!/bin/bash\nexec -a {marker} sleep 300\n"),
    )
    .unwrap();
    std::fs::set_permissions(&script, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
    let probe_running = || {
        std::process::Command::new("pgrep")
            .args(["-f", &marker])
            .output()
            .map(|o| o.status.success())
            .unwrap_or(false)
    };
    let child = clevrtex()
        .args(["doctor", "--timeout", "60", "--blender"])
        .arg(&script)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let t = Instant::now();
    while !probe_running() && t.elapsed() < Duration::from_secs(20) {
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(probe_running(), "the probe never started");
    let st = std::process::Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(st.success());
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(143), "{}", text(&out));
    std::thread::sleep(Duration::from_millis(500));
    let left = probe_running();
    if left {
        let _ = std::process::Command::new("pkill")
            .args(["-f", &marker])
            .status();
    }
    assert!(
        !left,
        "the `--version` probe outlived doctor: {}",
        text(&out)
    );
}

/// A worker that never starts is given up on after `--startup-timeout` (not a fixed 120 s),
/// and the hint names that flag, not `--timeout`.
#[test]
fn startup_timeout_is_a_flag_and_its_hint_names_it() {
    let dir = tempfile::tempdir().unwrap();
    let t = Instant::now();
    let out = generate_fake("deaf", dir.path(), &["-n", "1", "--startup-timeout", "1.5"]);
    let t_ = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t_}");
    assert!(
        t_.contains("timed out after 1.5 s while starting up"),
        "{t_}"
    );
    assert!(t_.contains("raise `--startup-timeout`"), "{t_}");
    assert!(t.elapsed() < Duration::from_secs(30), "{:?}", t.elapsed());
}

/// A scene file that cannot be built is named as the user's file in the message (not the
/// worker's temporary copy), with what was wrong. An unknown material, which the bridge used to
/// fail on (exit 3), is refused before any image is rendered since `render` checks the scene
/// files' materials against the catalogue and `--materials` (issue 33): exit 1.
#[test]
fn bridge_errors_name_the_users_scene_file() {
    let Some(blender) = blender_or_skip("bridge_errors_name_the_users_scene_file") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let mut scene: Value =
        serde_json::from_str(&std::fs::read_to_string(data("scenes/tiny3.json")).unwrap()).unwrap();
    scene["objects"][0]["material"]["name"] = Value::from("no_such_material");
    let file = dir.path().join("scenes/odd.json");
    std::fs::create_dir_all(file.parent().unwrap()).unwrap();
    std::fs::write(&file, scene.to_string()).unwrap();
    let out = clevrtex()
        .args(["render", "--retries", "0", "--blender"])
        .arg(&blender)
        .arg("--out")
        .arg(dir.path().join("out"))
        .arg(&file)
        .output()
        .unwrap();
    let t = text(&out);
    assert_eq!(out.status.code(), Some(1), "{t}");
    assert!(
        t.contains(&format!("scene file `{}`", file.display())),
        "{t}"
    );
    assert!(t.contains("no_such_material"), "{t}");
    assert!(t.contains("hint: "), "{t}");
    assert!(
        !dir.path().join("out").join("clevrtex_clevr").exists(),
        "{t}"
    );
}
