//! Blender's side of the trust boundary (issue 21, docs/security.md): its output is bounded,
//! a Blender behind a wrapper script works and is stopped with everything it started, and a
//! signal at any moment of a run gets its exit code.

use std::ffi::OsStr;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::util::{blender_or_skip, blender_wrapper, clevrtex, fake_blender, run_limited, text};

/// The `ready` line of the fake Blender, for wrappers that speak the protocol themselves:
/// `sh` that finds the tag among Blender's arguments and prints it.
const READY: &str = r#"tag=""
while [ $# -gt 0 ]; do
  if [ "$1" = "--tag" ]; then tag="$2"; shift; fi
  shift
done
echo "$tag {\"type\":\"ready\",\"bridge_version\":1,\"blender_version\":\"3.4.1\",\"cycles_devices\":[\"CPU\"]}""#;

fn generate_args(out: &Path, blender: &Path) -> Vec<std::ffi::OsString> {
    let mut v: Vec<std::ffi::OsString> = [
        "generate",
        "--variant",
        "clevr",
        "-n",
        "1",
        "--width",
        "32",
        "--height",
        "24",
        "--samples",
        "1",
        "--workers",
        "1",
        "--retries",
        "0",
        "--blender",
    ]
    .iter()
    .map(Into::into)
    .collect();
    v.push(blender.into());
    v.push("--out".into());
    v.push(out.into());
    v
}

/// A Blender that prints `y` lines without end to `--version` (what `doctor` and the flavour
/// check ask first): before the cap, `doctor` kept all of it (8.9 GB seen); now it keeps
/// 64 KiB and stops the program at the probe's deadline, well under 2 GB.
#[test]
fn a_blender_that_prints_without_end_costs_bounded_memory() {
    let dir = tempfile::tempdir().unwrap();
    let flood = blender_wrapper(dir.path(), "exec yes");
    let (code, t) = run_limited(
        &[
            OsStr::new("doctor"),
            OsStr::new("--blender"),
            flood.as_os_str(),
        ],
        &[],
        120,
    );
    assert_eq!(code, Some(1), "doctor ends with an error, not a crash: {t}");
    assert!(
        t.contains(&flood.display().to_string()),
        "names the program: {t}"
    );
}

/// A worker that prints a reply stream without a newline (3 GB of it): before the cap, the
/// line buffer grew until the allocation aborted the run; now the line is cut at 1 MiB and
/// the image fails with the worker's exit, reported in the ledger.
#[test]
fn a_worker_line_without_newline_is_cut_not_buffered() {
    let dir = tempfile::tempdir().unwrap();
    let fake = blender_wrapper(
        dir.path(),
        &format!(
            "if [ \"$1\" = --version ]; then echo 'Blender 3.4.1'; exit 0; fi\n{READY}\nread -r request\nhead -c 3000000000 /dev/zero | tr '\\0' x\nexit 1"
        ),
    );
    let out = dir.path().join("data");
    let args = generate_args(&out, &fake);
    let args: Vec<&OsStr> = args.iter().map(|a| a.as_os_str()).collect();
    let (code, t) = run_limited(&args, &[], 300);
    assert_eq!(
        code,
        Some(3),
        "the image fails, the run does not crash: {t}"
    );
    let ledger = std::fs::read_to_string(out.join("clevrtex_clevr/failures.jsonl")).unwrap();
    assert!(
        ledger.contains("more bytes]"),
        "the tail shows the cut line: {ledger}"
    );
    assert!(
        ledger.len() < 64 * 1024,
        "the ledger keeps a bounded tail: {} bytes",
        ledger.len()
    );
}

/// A Blender behind a wrapper script that does not `exec` (`module load blender; blender
/// "$@"`): the bridge used to refuse to start (its parent was the wrapper, not clevrtex); now
/// clevrtex as an ancestor is accepted, and the image renders.
#[test]
fn a_blender_behind_a_wrapper_script_renders() {
    let Some(blender) = blender_or_skip("a_blender_behind_a_wrapper_script_renders") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let wrapper = blender_wrapper(
        dir.path(),
        &format!(
            "# a site wrapper, no exec\n'{}' \"$@\"\nexit $?",
            blender.display()
        ),
    );
    let out_dir = dir.path().join("data");
    let out = clevrtex()
        .args(generate_args(&out_dir, &wrapper))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    assert!(out_dir
        .join("clevrtex_clevr/0/CLEVRTEX_clevr_000000_flat.png")
        .exists());
}

/// Whether process `pid` still runs (a zombie, dead but not yet reaped, does not).
fn running(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .ok()
        .and_then(|s| s.rsplit_once(") ").map(|(_, rest)| !rest.starts_with('Z')))
        .unwrap_or(false)
}

/// On a timeout the whole process group of the worker is killed: before, only the direct
/// child was, and what it had started (a wrapper's Blender) went on rendering.
#[test]
fn a_timeout_kills_everything_the_worker_started() {
    let dir = tempfile::tempdir().unwrap();
    let pidfile = dir.path().join("grandchild.pid");
    let wrapper = blender_wrapper(
        dir.path(),
        &format!(
            "if [ \"$1\" = --version ]; then exec '{fake}' --version; fi\nsleep 600 &\necho $! > '{pid}'\nFAKE_BLENDER_MODE=hang '{fake}' \"$@\"\nexit $?",
            fake = fake_blender().display(),
            pid = pidfile.display()
        ),
    );
    let out_dir = dir.path().join("data");
    let out = clevrtex()
        .args(generate_args(&out_dir, &wrapper))
        .args(["--timeout", "3"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(3), "{}", text(&out));
    let pid: u32 = std::fs::read_to_string(&pidfile)
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    let t = Instant::now();
    while running(pid) && t.elapsed() < Duration::from_secs(5) {
        std::thread::sleep(Duration::from_millis(100));
    }
    let alive = running(pid);
    if alive {
        let _ = Command::new("kill").arg(pid.to_string()).status();
    }
    assert!(
        !alive,
        "the worker's child {pid} outlived the timeout: {}",
        text(&out)
    );
}

/// SIGTERM and SIGINT at any moment of a run, the first milliseconds included, exit with 143
/// and 130: before the handler was installed first thing, a signal during the worker's start
/// surfaced as the error `interrupted` and exit code 1.
#[test]
fn a_signal_at_any_moment_gets_its_exit_code() {
    let dir = tempfile::tempdir().unwrap();
    for (signal, code) in [("TERM", 143), ("INT", 130)] {
        for delay_ms in [20, 150, 400, 900] {
            let out_dir = dir.path().join(format!("data-{signal}-{delay_ms}"));
            let mut child = clevrtex()
                .env("FAKE_BLENDER_MODE", "hang")
                .args(generate_args(&out_dir, &fake_blender()))
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap();
            std::thread::sleep(Duration::from_millis(delay_ms));
            let st = Command::new("kill")
                .args([format!("-{signal}"), child.id().to_string()])
                .status()
                .unwrap();
            assert!(st.success());
            let t = Instant::now();
            while child.try_wait().unwrap().is_none() {
                if t.elapsed() > Duration::from_secs(30) {
                    child.kill().unwrap();
                    panic!("SIG{signal} after {delay_ms} ms: still running after 30 s");
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            let o = child.wait_with_output().unwrap();
            assert_eq!(
                o.status.code(),
                Some(code),
                "SIG{signal} after {delay_ms} ms: {}",
                text(&o)
            );
        }
    }
}

/// A folder given as Blender is called a folder, with the program inside it suggested (it
/// used to say "blender not found", which sends the user looking for an install).
#[test]
fn a_folder_given_as_blender_is_named_a_folder() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let data = data.to_str().unwrap();
    for cmd in [
        &["doctor"][..],
        &["generate", "--variant", "clevr", "-n", "1", "--out", data][..],
    ] {
        let out = clevrtex()
            .args(cmd)
            .arg("--blender")
            .arg(dir.path())
            .output()
            .unwrap();
        let t = text(&out);
        assert_eq!(out.status.code(), Some(1), "{cmd:?}: {t}");
        assert!(
            t.contains("is a folder, not a Blender executable"),
            "{cmd:?}: {t}"
        );
        assert!(!t.contains("not found"), "{cmd:?}: {t}");
    }
}

/// An image too small for any object to cover a pixel says so, instead of "use fewer or
/// larger objects" (which no change of the configuration can satisfy at 1x1).
#[test]
fn a_tiny_image_is_blamed_for_its_rejects() {
    let Some(blender) = blender_or_skip("a_tiny_image_is_blamed_for_its_rejects") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("data");
    let out = clevrtex()
        .args([
            "generate",
            "--variant",
            "clevr",
            "-n",
            "1",
            "--width",
            "1",
            "--height",
            "1",
        ])
        .args(["--samples", "1", "--workers", "1", "--blender"])
        .arg(&blender)
        .arg("--out")
        .arg(&out_dir)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(3), "{}", text(&out));
    let ledger = std::fs::read_to_string(out_dir.join("clevrtex_clevr/failures.jsonl")).unwrap();
    assert!(ledger.contains("is too small"), "{ledger}");
    assert!(!ledger.contains("fewer or larger objects"), "{ledger}");
}

/// Issue 40: a worker is recycled between images, never during one: after `--recycle-after`
/// images, or past `--max-worker-memory` (here a bound every Blender passes), each with a
/// note; the dataset's masks and metadata are those of a run that never recycled, and the
/// summary gives the workers' peak memory. A bound that is no number of GiB is refused.
#[test]
fn workers_are_recycled_between_images_by_count_or_memory() {
    let Some(blender) = blender_or_skip("workers_are_recycled_between_images") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let run = |name: &str, extra: &[&str]| {
        let o = clevrtex()
            .args(["generate", "--variant", "clevr", "-n", "5", "--seed", "6"])
            .args(["--width", "32", "--height", "24", "--samples", "1"])
            .args(["--passes", "rgb,mask", "--workers", "1", "--blender"])
            .arg(&blender)
            .arg("--out")
            .arg(tmp.path().join(name))
            .args(extra)
            .env_remove("SLURM_ARRAY_TASK_ID")
            .env_remove("JOB_COMPLETION_INDEX")
            .output()
            .unwrap();
        let t = text(&o);
        assert_eq!(o.status.code(), Some(0), "{extra:?}: {t}");
        t
    };
    let plain = run("plain", &["--max-worker-memory", "1000"]);
    assert!(!plain.contains("was recycled"), "{plain}");
    assert!(
        plain.contains("MiB peak resident between images"),
        "{plain}"
    );
    let by_count = run("count", &["--recycle-after", "2"]);
    assert_eq!(
        by_count
            .matches("made 2 image(s)")
            .filter(|_| by_count.contains("(`--recycle-after`)"))
            .count(),
        2,
        "{by_count}"
    );
    assert!(by_count.contains("(3 start(s))"), "{by_count}");
    let by_memory = run("memory", &["--max-worker-memory", "0.001"]);
    assert_eq!(
        by_memory.matches("past `--max-worker-memory`").count(),
        5,
        "{by_memory}"
    );
    assert!(by_memory.contains("(5 start(s))"), "{by_memory}");
    for i in 0..5 {
        for suffix in ["_flat.png", ".json"] {
            let rel = format!("clevrtex_clevr/0/CLEVRTEX_clevr_{i:06}{suffix}");
            let want = std::fs::read(tmp.path().join("plain").join(&rel)).unwrap();
            for other in ["count", "memory"] {
                assert!(
                    std::fs::read(tmp.path().join(other).join(&rel)).unwrap() == want,
                    "{other}: {rel} differs from the run that never recycled"
                );
            }
        }
    }
    let o = clevrtex()
        .args([
            "generate",
            "--variant",
            "clevr",
            "-n",
            "1",
            "--max-worker-memory",
            "0",
        ])
        .arg("--out")
        .arg(tmp.path().join("bad"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("`--max-worker-memory 0` is out of range"),
        "{}",
        text(&o)
    );
}
