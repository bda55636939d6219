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
    run_ok(generate(
        &blender,
        &out,
        &["--start", "2", "-n", "2", "--allow-split-mismatch"],
    ));
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
    run_ok(generate(
        &blender,
        &moved,
        &["--start", "2", "-n", "2", "--allow-split-mismatch"],
    ));
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
    let a = hanging(
        &out,
        &["-n", "6", "--shard", "0/2", "--allow-split-mismatch"],
    );
    let b = hanging(
        &out,
        &["-n", "6", "--shard", "1/2", "--allow-split-mismatch"],
    );
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
            let mut c = generate(
                &fake_blender(),
                &out,
                &["--start", "2", "-n", "4", "--allow-split-mismatch"],
            );
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

/// The start time of process `pid` (field 22 of `/proc/<pid>/stat`, clock ticks since boot):
/// the third part of an owner tag.
fn start_time(pid: u32) -> u64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap();
    let rest = &stat[stat.rfind(')').unwrap() + 1..];
    rest.split_whitespace().nth(19).unwrap().parse().unwrap()
}

/// Issue 42, finding 1: `verify --remove-broken` during a live `generate` deleted the live
/// writer's half-renamed sample (and listed the live pid among "killed runs"). Now every index
/// in a live run's range lock and every temporary of a live owner is left alone, named; once
/// the run is gone they are removed.
#[test]
fn remove_broken_leaves_a_live_run_s_samples_and_temporaries_alone() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let sub = out.join("clevrtex_clevr/0");
    std::fs::create_dir_all(&sub).unwrap();
    let mut gone = Command::new("true").spawn().unwrap();
    let dead_pid = gone.id();
    gone.wait().unwrap();
    // The live run sweeps the folder of killed runs' temporaries once, when it first takes a
    // job of it: this one gone means it has, and what the test leaves below stays for verify.
    let swept = sub.join(format!(
        "CLEVRTEX_clevr_000000.png.h42.{dead_pid}.1.clevrtex-tmp"
    ));
    std::fs::write(&swept, b"half").unwrap();
    let live = Hanging(Some(
        generate(&fake_blender(), &out, &["-n", "4"])
            .env("FAKE_BLENDER_MODE", "hang")
            .env("CLEVRTEX_HOST", "h42")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    ));
    wait_for(&lock(&out, ".clevrtex-run-0-4-0of1.lock"));
    let start = std::time::Instant::now();
    while swept.exists() {
        assert!(
            start.elapsed() < std::time::Duration::from_secs(60),
            "the live run never swept its folder"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let pid = live.id();
    // Sample 1 as the live writer leaves it between two renames (its metadata comes last).
    std::fs::write(sub.join("CLEVRTEX_clevr_000001.png"), b"being written").unwrap();
    // A temporary of the live writer, and one of a dead one.
    let live_tmp = sub.join(format!(
        "CLEVRTEX_clevr_000002.png.h42.{pid}.{}.clevrtex-tmp",
        start_time(pid)
    ));
    std::fs::write(&live_tmp, b"half").unwrap();
    let dead_tmp = sub.join(format!(
        "CLEVRTEX_clevr_000003.png.h42.{dead_pid}.1.clevrtex-tmp"
    ));
    std::fs::write(&dead_tmp, b"half").unwrap();
    // Sample 4: broken, of a finished run whose writer is gone: removed.
    std::fs::write(sub.join("CLEVRTEX_clevr_000004.png"), b"broken").unwrap();
    let manifest = serde_json::json!({
        "format": "clevrtex-manifest", "version": 1, "variant": "clevr", "seed": 4,
        "config_hash": "0", "start": 4, "end": 6, "total": 6, "shard": [0, 1],
        "passes": ["rgb", "mask"], "tool_version": "0", "blender_version": "",
        "command": ["clevrtex", "generate", "--start", "4", "-n", "2"],
        "finished": true, "files": {}
    });
    std::fs::write(lock(&out, "MANIFEST-4-6-0of1.json"), manifest.to_string()).unwrap();
    let remove = || {
        let o = clevrtex()
            .args(["verify", "--remove-broken"])
            .arg(&out)
            .env("CLEVRTEX_HOST", "h42")
            .output()
            .unwrap();
        (o.status.code(), text(&o))
    };
    let (code, t) = remove();
    assert_eq!(code, Some(3), "{t}");
    assert!(
        sub.join("CLEVRTEX_clevr_000001.png").is_file(),
        "a live run's sample was removed: {t}"
    );
    assert!(
        live_tmp.is_file(),
        "a live run's temporary was removed: {t}"
    );
    assert!(!dead_tmp.exists(), "{t}");
    assert!(!sub.join("CLEVRTEX_clevr_000004.png").exists(), "{t}");
    assert!(
        t.contains(&format!(
            "clevr: left alone sample(s) 1: a live run is writing them (pid {pid} on host `h42` (indices 0..4, shard 0/1))"
        )),
        "{t}"
    );
    assert!(
        t.contains(
            "temporary files of runs still writing (or of another host; never removed) (1):"
        ),
        "{t}"
    );
    assert!(
        t.contains("temporary files left by killed runs (1):"),
        "{t}"
    );
    // The run is gone (killed: its lock stays, stale): its leftovers are removed now.
    signal(live, "KILL");
    let (code, t) = remove();
    assert_eq!(code, Some(3), "{t}");
    assert!(!sub.join("CLEVRTEX_clevr_000001.png").exists(), "{t}");
    assert!(!live_tmp.exists(), "{t}");
}

/// Issue 42, finding 1: a `generate` whose samples another process deleted while it ran said
/// `[4/4] wrote`, exited 0 and wrote a manifest marked finished. It now checks its samples
/// again before the manifest: it fails (exit 1) naming them, and the manifest is unfinished.
#[test]
fn generate_fails_when_its_samples_vanish_before_its_manifest() {
    let Some(blender) =
        blender_or_skip("generate_fails_when_its_samples_vanish_before_its_manifest")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let mut child = generate(&blender, &out, &["-n", "4"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let sub = out.join("clevrtex_clevr/0");
    wait_for(&sub.join("CLEVRTEX_clevr_000000.json"));
    for suffix in [".json", ".png", "_flat.png"] {
        std::fs::remove_file(sub.join(format!("CLEVRTEX_clevr_000000{suffix}"))).unwrap();
    }
    assert!(
        child.try_wait().unwrap().is_none(),
        "the run ended before the test removed its sample"
    );
    let o = child.wait_with_output().unwrap();
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(
        t.contains("1 sample(s) of this run are gone from") && t.contains("(index 0)"),
        "{t}"
    );
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(lock(&out, "MANIFEST-0-4-0of1.json")).unwrap())
            .unwrap();
    assert_eq!(m["finished"], false, "{m}");
    assert!(sub.join("CLEVRTEX_clevr_000003.json").is_file(), "{t}");
}
