//! Many writers into one output folder (issue 21): runs of other ranges each keep their own
//! manifest and `verify` takes the union; a run's plan is written before its first image, so
//! an interrupted or preempted run is incomplete, not whole; overlapping runs refuse to start
//! while another holds the range's lock; `verify --remove-broken` and its rerun remake exactly
//! the broken samples, in the folder that was verified.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use crate::util::{blender_or_skip, clevrtex, fake_blender, text};

/// `clevrtex generate` of clevr at 32x24 with rgb and mask into `out`, plus `extra`.
pub(crate) fn generate(blender: &Path, out: &Path, extra: &[&str]) -> Command {
    let mut c = clevrtex();
    c.args(["generate", "--variant", "clevr", "--seed", "4"])
        .args(["--width", "32", "--height", "24", "--samples", "1"])
        .args(["--passes", "rgb,mask", "--workers", "1", "--blender"])
        .arg(blender)
        .arg("--out")
        .arg(out)
        .args(extra)
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("SLURM_ARRAY_TASK_COUNT")
        .env_remove("JOB_COMPLETION_INDEX")
        .env_remove("CLEVRTEX_BLENDER");
    c
}

fn run_ok(mut c: Command) {
    let o = c.output().unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
}

fn verify(args: &[&Path], extra: &[&str]) -> (Option<i32>, String) {
    let o = clevrtex()
        .arg("verify")
        .args(extra)
        .args(args)
        .output()
        .unwrap();
    (o.status.code(), text(&o))
}

/// A `generate` with the fake Blender that hangs on its first request: it holds its lock and
/// has written its plan once its lock file exists. Killed with its workers if the test ends
/// before [`signal`] reaps it.
fn hanging(out: &Path, extra: &[&str]) -> Hanging {
    Hanging(Some(
        generate(&fake_blender(), out, extra)
            .env("FAKE_BLENDER_MODE", "hang")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    ))
}

/// A child that is killed, with the processes it started, when dropped unreaped.
struct Hanging(Option<Child>);

impl Hanging {
    fn id(&self) -> u32 {
        self.0.as_ref().expect("not reaped").id()
    }
}

impl Drop for Hanging {
    fn drop(&mut self) {
        if let Some(mut c) = self.0.take() {
            for k in descendants(c.id()) {
                let _ = Command::new("kill")
                    .args(["-KILL", &k.to_string()])
                    .status();
            }
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// Wait until `path` exists (at most a minute).
fn wait_for(path: &Path) {
    let t = Instant::now();
    while !path.exists() {
        assert!(
            t.elapsed() < Duration::from_secs(60),
            "no `{}`",
            path.display()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// The output of `c`, killed (a failure) if it runs over `secs`.
pub(crate) fn output_within(mut c: Command, secs: u64) -> Output {
    let mut child = c
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t.elapsed() > Duration::from_secs(secs) {
            child.kill().unwrap();
            let o = child.wait_with_output().unwrap();
            panic!("still running after {secs} s:\n{}", text(&o));
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    child.wait_with_output().unwrap()
}

/// The processes started by `pid` (by any of its threads), and theirs.
fn descendants(pid: u32) -> Vec<u32> {
    let mut out = Vec::new();
    for task in std::fs::read_dir(format!("/proc/{pid}/task"))
        .into_iter()
        .flatten()
        .flatten()
    {
        let kids = std::fs::read_to_string(task.path().join("children")).unwrap_or_default();
        for k in kids.split_whitespace().filter_map(|k| k.parse().ok()) {
            out.extend(descendants(k));
            out.push(k);
        }
    }
    out
}

/// Send `sig` to `child` (for `KILL`, to the processes it started first: the fake Blender,
/// which no clean-up would end) and reap it.
fn signal(mut child: Hanging, sig: &str) -> Output {
    let child = child.0.take().expect("not reaped");
    let pid = child.id();
    if sig == "KILL" {
        for k in descendants(pid) {
            let _ = Command::new("kill")
                .args(["-KILL", &k.to_string()])
                .status();
        }
    }
    let st = Command::new("kill")
        .arg(format!("-{sig}"))
        .arg(pid.to_string())
        .status()
        .unwrap();
    assert!(st.success());
    child.wait_with_output().unwrap()
}

fn lock(out: &Path, name: &str) -> PathBuf {
    out.join("clevrtex_clevr").join(name)
}

#[test]
fn a_grown_dataset_verifies_whole_and_repairs_in_the_folder_verified() {
    let Some(blender) = blender_or_skip("a_grown_dataset_verifies_whole") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("first");
    run_ok(generate(&blender, &out, &["-n", "2"]));
    run_ok(generate(&blender, &out, &["--start", "2", "-n", "2"]));
    let vdir = out.join("clevrtex_clevr");
    assert!(vdir.join("MANIFEST-0-2-0of1.json").is_file());
    assert!(vdir.join("MANIFEST-2-4-0of1.json").is_file());
    let (code, t) = verify(&[&out], &[]);
    assert_eq!(code, Some(0), "{t}");
    assert!(t.contains("clevr: 4 of 4 expected samples whole"), "{t}");

    // Moved elsewhere, one sample of the second run damaged: only it is removed, and the
    // rerun names the folder verified.
    let moved = dir.path().join("moved");
    std::fs::rename(&out, &moved).unwrap();
    let sub = moved.join("clevrtex_clevr/0");
    let png = sub.join("CLEVRTEX_clevr_000003.png");
    let bytes = std::fs::read(&png).unwrap();
    std::fs::write(&png, &bytes[..bytes.len() / 2]).unwrap();
    let (code, t) = verify(&[&moved], &["--remove-broken"]);
    assert_eq!(code, Some(3), "{t}");
    assert!(t.contains("broken samples (1):"), "{t}");
    assert!(
        t.contains(&format!("--out {}", moved.display())),
        "the rerun writes where verify looked: {t}"
    );
    assert!(!t.contains(&format!("--out {}", out.display())), "{t}");
    assert!(!sub.join("CLEVRTEX_clevr_000003.json").exists());
    for i in 0..3 {
        assert!(
            sub.join(format!("CLEVRTEX_clevr_{i:06}.json")).is_file(),
            "{i}"
        );
    }
    run_ok(generate(&blender, &moved, &["--start", "2", "-n", "2"]));
    let (code, t) = verify(&[&moved], &[]);
    assert_eq!(code, Some(0), "{t}");
}

#[test]
fn interrupted_and_preempted_runs_are_incomplete() {
    let Some(blender) = blender_or_skip("interrupted_and_preempted_runs_are_incomplete") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("data");
    run_ok(generate(&blender, &out, &["-n", "2"]));
    // A run of 0..6 in two shards (two SLURM tasks), both preempted before their first image.
    let a = hanging(&out, &["-n", "6", "--shard", "0/2"]);
    let b = hanging(&out, &["-n", "6", "--shard", "1/2"]);
    wait_for(&lock(&out, ".clevrtex-run-0-6-0of2.lock"));
    wait_for(&lock(&out, ".clevrtex-run-0-6-1of2.lock"));
    for c in [a, b] {
        let o = signal(c, "TERM");
        assert_eq!(o.status.code(), Some(143), "{}", text(&o));
    }
    assert!(!lock(&out, ".clevrtex-run-0-6-0of2.lock").exists());
    let (code, t) = verify(&[&out], &[]);
    assert_eq!(code, Some(3), "{t}");
    assert!(t.contains("missing (4): 2..=5"), "{t}");
    assert!(
        t.contains("MANIFEST-0-6-0of2.json`: the run of indices 0..6 (shard 0/2) did not finish"),
        "{t}"
    );
    assert!(
        t.contains("MANIFEST-0-6-1of2.json`: the run of indices 0..6 (shard 1/2) did not finish"),
        "{t}"
    );
    assert!(t.contains("--shard 1/2"), "{t}");
}

#[test]
fn an_overlapping_run_refuses_while_the_range_is_held() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("data");
    let a = hanging(&out, &["-n", "4"]);
    let held = lock(&out, ".clevrtex-run-0-4-0of1.lock");
    wait_for(&held);
    let o = output_within(
        {
            let mut c = generate(&fake_blender(), &out, &["--start", "2", "-n", "4"]);
            c.env("FAKE_BLENDER_MODE", "hang");
            c
        },
        60,
    );
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(t.contains("overlap those of another run"), "{t}");
    assert!(t.contains(&format!("pid {}", a.id())), "{t}");
    assert!(t.contains(&held.display().to_string()), "{t}");
    assert!(t.contains("hint: wait for that run to end"), "{t}");
    // Its holder killed outright (no clean-up): the lock stays but is stale, and a new run
    // of the range starts (here its images fail: the fake Blender crashes).
    signal(a, "KILL");
    assert!(held.exists());
    let o = output_within(
        {
            let mut c = generate(&fake_blender(), &out, &["-n", "4", "--retries", "0"]);
            c.env("FAKE_BLENDER_MODE", "crash");
            c
        },
        120,
    );
    let t = text(&o);
    assert_eq!(o.status.code(), Some(3), "{t}");
    assert!(!t.contains("overlap"), "{t}");
    assert!(!held.exists(), "the new run's lock went with it");
}

/// A FIFO in place of the run lock's guard, the ledger or the ledger's lock never blocks
/// `generate`: it is opened without blocking, found not to be a regular file and refused,
/// naming it. Before, `generate` blocked on the open for good (SIGTERM did not end it either;
/// hostile pass 3, repro-14).
#[test]
fn a_fifo_in_place_of_a_lock_or_the_ledger_never_blocks_generate() {
    let entry =
        r#"{"index":0,"stem":"CLEVRTEX_clevr_000000","variant":"clevr","error":"x","time_unix":0}"#;
    for name in [
        ".clevrtex-runs.lock",
        "failures.jsonl",
        ".failures.jsonl.lock",
    ] {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("data");
        crate::util::hand_png_sample(&out, "clevr", 0, (32, 24), (32, 24));
        let vdir = out.join("clevrtex_clevr");
        if name == ".failures.jsonl.lock" {
            std::fs::write(vdir.join("failures.jsonl"), format!("{entry}\n")).unwrap();
        }
        let fifo = vdir.join(name);
        assert!(Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success());
        let mut c = generate(&fake_blender(), &out, &["-n", "1"]);
        c.env("FAKE_BLENDER_MODE", "crash");
        let o = output_within(c, 30);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(1), "{name}: {t}");
        assert!(
            t.contains(&format!("`{}` is not a regular file", fifo.display())),
            "{name}: {t}"
        );
    }
}

/// A lock's holder is read from a file in the dataset: its command is printed with its
/// control characters escaped. Before, generate's overlap error printed it raw (an ESC[2K
/// could erase the line; hostile pass 3, repro-12).
#[test]
fn a_lock_holders_command_is_printed_escaped() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("data");
    let vdir = out.join("clevrtex_clevr");
    std::fs::create_dir_all(&vdir).unwrap();
    let holder = serde_json::json!({
        "host": "elsewhere\u{1b}]0;title\u{7}", "pid": 4242, "pid_start": 1, "start": 0, "end": 4,
        "shard": [0, 1], "command": ["clevrtex", "\u{1b}[2K\rgenerate"],
    });
    std::fs::write(vdir.join(".clevrtex-run-0-4-0of1.lock"), holder.to_string()).unwrap();
    let mut c = generate(&fake_blender(), &out, &["-n", "2"]);
    c.env("FAKE_BLENDER_MODE", "crash");
    let o = output_within(c, 60);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(t.contains("overlap those of another run"), "{t}");
    assert!(t.contains(r"clevrtex \u{1b}[2K\u{d}generate"), "{t}");
    assert!(t.contains(r"elsewhere\u{1b}]0;title\u{7}"), "{t}");
    assert!(!t.contains('\x1b') && !t.contains('\x07'), "{t:?}");
}
