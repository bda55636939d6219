//! `clevrtex generate` under a real SLURM: a single-host cluster from Debian's packages
//! (`munge`, `slurmctld`, `slurmd`, `slurm-client`), configured and started by the test in a
//! temporary folder (no systemd), runs `deploy/slurm/generate.sbatch` as a 4-task array. The
//! union of the tasks' output equals one `generate` of the same seed, and a task killed with
//! SIGKILL mid-run and requeued resumes, leaving a dataset that verifies and no orphan Blender.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use crate::util::{blender_or_skip, clevrtex, repo_root, text};

/// A running single-host cluster; stopped (daemons killed) when dropped.
struct Cluster {
    dir: tempfile::TempDir,
    pids: Vec<PathBuf>,
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn find(program: &str) -> Option<PathBuf> {
    ["/usr/sbin", "/usr/bin", "/sbin", "/bin"]
        .iter()
        .map(|d| Path::new(d).join(program))
        .find(|p| p.is_file())
}

fn run_ok(cmd: &mut Command) -> Output {
    let out = cmd.output().unwrap();
    assert!(out.status.success(), "{cmd:?}: {}", text(&out));
    out
}

impl Cluster {
    /// Start munged, slurmctld and slurmd; `None` (a visible skip) when SLURM is not installed
    /// or we are not root, unless `CLEVRTEX_REQUIRE_TOOLS=1` makes it required.
    fn start() -> Option<Cluster> {
        let missing: Vec<&str> = ["munged", "mungekey", "slurmctld", "slurmd", "sbatch"]
            .into_iter()
            .filter(|p| find(p).is_none())
            .collect();
        let root = Command::new("id")
            .arg("-u")
            .output()
            .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0");
        if !missing.is_empty() || !root {
            let why = if root {
                format!("missing {}", missing.join(", "))
            } else {
                "not root (slurmd must be)".to_string()
            };
            crate::util::skip(
                "slurm",
                crate::util::REQUIRE_TOOLS,
                &format!("SLURM unusable: {why}"),
                "install `munge slurmctld slurmd slurm-client` and run as root (.ci/run does)",
            );
            return None;
        }
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        for sub in ["state", "spool", "munge", "log"] {
            std::fs::create_dir_all(d.join(sub)).unwrap();
        }
        let mut cluster = Cluster {
            dir,
            pids: Vec::new(),
        };
        let d = cluster.dir.path().to_path_buf();
        run_ok(
            Command::new(find("mungekey").unwrap())
                .args(["-c", "-k"])
                .arg(d.join("munge/munge.key")),
        );
        run_ok(Command::new("chmod").arg("711").arg(d.join("munge")));
        run_ok(
            Command::new(find("munged").unwrap())
                .arg("--force")
                .arg(format!(
                    "--key-file={}",
                    d.join("munge/munge.key").display()
                ))
                .arg(format!("--socket={}", d.join("munge/sock").display()))
                .arg(format!("--pid-file={}", d.join("munge/pid").display()))
                .arg(format!("--log-file={}", d.join("log/munge.log").display()))
                .arg(format!("--seed-file={}", d.join("munge/seed").display())),
        );
        cluster.pids.push(d.join("munge/pid"));
        let host = String::from_utf8(run_ok(&mut Command::new("hostname")).stdout)
            .unwrap()
            .trim()
            .to_string();
        let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
        let plugin_dir = [
            "/usr/lib/x86_64-linux-gnu/slurm-wlm",
            "/usr/lib/aarch64-linux-gnu/slurm-wlm",
            "/usr/lib/slurm",
        ]
        .into_iter()
        .find(|p| Path::new(p).is_dir())
        .unwrap_or("/usr/lib/x86_64-linux-gnu/slurm-wlm");
        let conf = format!(
            "ClusterName=clevrtex-test\nSlurmctldHost={host}\nSlurmUser=root\nSlurmdUser=root\n\
             AuthType=auth/munge\nCredType=cred/munge\nAuthInfo=socket={sock}\n\
             SlurmctldPort={p1}\nSlurmdPort={p2}\nStateSaveLocation={d}/state\nSlurmdSpoolDir={d}/spool\n\
             SlurmctldPidFile={d}/slurmctld.pid\nSlurmdPidFile={d}/slurmd.pid\n\
             SlurmctldLogFile={d}/log/slurmctld.log\nSlurmdLogFile={d}/log/slurmd.log\n\
             ProctrackType=proctrack/linuxproc\nTaskPlugin=task/none\nSchedulerType=sched/backfill\n\
             SelectType=select/cons_tres\nSelectTypeParameters=CR_CPU\nMpiDefault=none\nReturnToService=2\n\
             JobCompType=jobcomp/none\nAccountingStorageType=accounting_storage/none\n\
             JobAcctGatherType=jobacct_gather/none\nSwitchType=switch/none\nPluginDir={plugin_dir}\n\
             KillWait=5\nNodeName={host} CPUs={cpus} RealMemory=2000 State=UNKNOWN\n\
             PartitionName=test Nodes=ALL Default=YES MaxTime=INFINITE State=UP\n",
            sock = d.join("munge/sock").display(),
            p1 = free_port(),
            p2 = free_port(),
            d = d.display(),
        );
        std::fs::write(d.join("slurm.conf"), conf).unwrap();
        run_ok(
            Command::new(find("slurmctld").unwrap())
                .arg("-f")
                .arg(d.join("slurm.conf"))
                .arg("-i"),
        );
        cluster.pids.push(d.join("slurmctld.pid"));
        run_ok(
            Command::new(find("slurmd").unwrap())
                .arg("-f")
                .arg(d.join("slurm.conf")),
        );
        cluster.pids.push(d.join("slurmd.pid"));
        // Wait for the node to be idle.
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            let o = cluster
                .cmd("sinfo")
                .args(["-h", "-o", "%t"])
                .output()
                .unwrap();
            if String::from_utf8_lossy(&o.stdout).trim() == "idle" {
                break;
            }
            assert!(
                Instant::now() < deadline,
                "the node never became idle: {}",
                cluster.logs()
            );
            std::thread::sleep(Duration::from_millis(300));
        }
        Some(cluster)
    }

    /// A SLURM client command using this cluster's config.
    fn cmd(&self, program: &str) -> Command {
        let mut c = Command::new(find(program).unwrap_or_else(|| PathBuf::from(program)));
        c.env("SLURM_CONF", self.dir.path().join("slurm.conf"));
        c
    }

    fn logs(&self) -> String {
        let mut s = String::new();
        for f in ["log/slurmctld.log", "log/slurmd.log"] {
            let t = std::fs::read_to_string(self.dir.path().join(f)).unwrap_or_default();
            let lines: Vec<&str> = t.lines().collect();
            s += &format!(
                "--- {f}\n{}\n",
                lines[lines.len().saturating_sub(30)..].join("\n")
            );
        }
        s
    }

    /// Submit the template as an array of `tasks`; returns the job id.
    fn submit(&self, tasks: u32, env: &[(&str, String)], logs: &Path) -> String {
        self.submit_array(&format!("0-{}", tasks - 1), env, logs)
    }

    /// Submit the template with `--array=<spec>`; returns the job id.
    fn submit_array(&self, spec: &str, env: &[(&str, String)], logs: &Path) -> String {
        let mut c = self.cmd("sbatch");
        c.args([
            "--parsable",
            &format!("--array={spec}"),
            "--cpus-per-task=1",
            "--mem=400M",
        ])
        .arg(format!("--output={}/task-%a.log", logs.display()))
        .arg("--chdir")
        .arg(logs)
        .arg(repo_root().join("deploy/slurm/generate.sbatch"));
        for (k, v) in env {
            c.env(k, v);
        }
        let out = run_ok(&mut c);
        String::from_utf8_lossy(&out.stdout).trim().to_string()
    }

    /// Wait (bounded) until job `id` has left the queue.
    fn wait(&self, id: &str, limit: Duration) {
        let deadline = Instant::now() + limit;
        loop {
            let o = self.cmd("squeue").args(["-h", "-j", id]).output().unwrap();
            if String::from_utf8_lossy(&o.stdout).trim().is_empty() {
                return;
            }
            assert!(
                Instant::now() < deadline,
                "job {id} still queued after {limit:?}: {}",
                self.logs()
            );
            std::thread::sleep(Duration::from_millis(500));
        }
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        for pid in self.pids.iter().rev() {
            if let Ok(p) = std::fs::read_to_string(pid) {
                let _ = Command::new("kill").arg(p.trim()).status();
            }
        }
        std::thread::sleep(Duration::from_millis(500));
        for pid in &self.pids {
            if let Ok(p) = std::fs::read_to_string(pid) {
                let _ = Command::new("kill").args(["-9", p.trim()]).status();
            }
        }
    }
}

/// Processes whose command line mentions `dir` (Blender workers run a bridge from there).
fn processes_under(dir: &Path) -> Vec<String> {
    let o = Command::new("pgrep")
        .arg("-af")
        .arg(dir.display().to_string())
        .output()
        .unwrap();
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(str::to_string)
        .collect()
}

/// Relative path -> bytes of every image, mask, depth and metadata file under `out`.
fn comparable_files(out: &Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    let mut m = std::collections::BTreeMap::new();
    let sub = out.join("clevrtex_clevr/0");
    for e in std::fs::read_dir(&sub).unwrap().flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if name.ends_with(".png") || name.ends_with(".json") {
            m.insert(name, std::fs::read(e.path()).unwrap());
        }
    }
    m
}

#[test]
fn slurm_array_union_equals_one_run_and_a_killed_task_resumes_after_requeue() {
    let Some(blender) = blender_or_skip("slurm_array_union_equals_one_run") else {
        return;
    };
    let Some(cluster) = Cluster::start() else {
        return;
    };
    let work = tempfile::tempdir().unwrap();
    let bin = PathBuf::from(env!("CARGO_BIN_EXE_clevrtex"));
    let extra = format!(
        "--width 48 --height 36 --samples 1 --passes rgb,mask,depth --blender {}",
        blender.display()
    );
    let tmp = work.path().join("tmp");
    std::fs::create_dir_all(&tmp).unwrap();
    let env = |out: &Path| {
        vec![
            ("OUT", out.display().to_string()),
            ("CLEVRTEX", bin.display().to_string()),
            ("VARIANT", "clevr".to_string()),
            ("COUNT", "12".to_string()),
            ("SEED", "4".to_string()),
            ("SHARDS", "4".to_string()),
            ("EXTRA_ARGS", extra.clone()),
            // Our own temporary folder: the bridge folders (and any Blender left behind) of
            // these tasks are told apart from other tests' by it.
            ("TMPDIR", tmp.display().to_string()),
        ]
    };

    // 1. A 4-task array of 12 images against one local run.
    let (out, logs) = (work.path().join("slurm"), work.path().join("logs"));
    std::fs::create_dir_all(&logs).unwrap();
    let t = Instant::now();
    let id = cluster.submit(4, &env(&out), &logs);
    cluster.wait(&id, Duration::from_secs(600));
    let slurm_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let local = work.path().join("local");
    let o = clevrtex()
        // One Cycles thread, as each array task has (`--cpus-per-task=1`): Cycles' images are
        // byte-identical at equal thread counts.
        .args(["generate", "--variant", "clevr", "-n", "12", "--seed", "4"])
        .args(["--workers", "1", "--threads", "1"])
        .args(extra.split(' '))
        .arg("--out")
        .arg(&local)
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("SLURM_ARRAY_TASK_COUNT")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    eprintln!(
        "slurm: 4-task array {slurm_s:.1} s, one local generate {:.1} s (ratio {:.2})",
        t.elapsed().as_secs_f64(),
        slurm_s / t.elapsed().as_secs_f64()
    );
    let task_logs: String = (0..4)
        .map(|k| std::fs::read_to_string(logs.join(format!("task-{k}.log"))).unwrap_or_default())
        .collect();
    let (a, b) = (comparable_files(&out), comparable_files(&local));
    assert_eq!(
        a.len(),
        48,
        "12 images, masks, depths and metadata files
{task_logs}"
    );
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (name, bytes) in &a {
        crate::util::assert_same_sample_file(name, bytes, &b[name]);
    }
    let v = clevrtex().arg("verify").arg(&out).output().unwrap();
    assert_eq!(v.status.code(), Some(0), "{}", text(&v));
    assert!(text(&v).contains("4 manifest(s)"), "{}", text(&v));

    // 2. Task 1 killed with SIGKILL mid-run, then requeued: it resumes.
    let (out2, logs2) = (work.path().join("slurm2"), work.path().join("logs2"));
    std::fs::create_dir_all(&logs2).unwrap();
    let id = cluster.submit(4, &env(&out2), &logs2);
    let first_of_task1 = out2.join("clevrtex_clevr/0/CLEVRTEX_clevr_000001.json");
    let deadline = Instant::now() + Duration::from_secs(300);
    while !first_of_task1.exists() {
        assert!(Instant::now() < deadline, "task 1 never wrote a sample");
        std::thread::sleep(Duration::from_millis(100));
    }
    run_ok(
        cluster
            .cmd("scancel")
            .args(["--signal=KILL", &format!("{id}_1")]),
    );
    // Until the killed task has left the queue (its processes are gone).
    cluster.wait(&format!("{id}_1"), Duration::from_secs(120));
    // Killed before its last image (index 9): the requeue has something to resume.
    assert!(!out2
        .join("clevrtex_clevr/0/CLEVRTEX_clevr_000009.json")
        .exists());
    // Requeue it, as an operator or a preemption would. SLURM delays a requeued job's start
    // (BeginTime); a test need not wait for it.
    for args in [
        vec!["requeue".to_string(), format!("{id}_1")],
        vec![
            "update".to_string(),
            format!("jobid={id}_1"),
            "StartTime=now".to_string(),
        ],
    ] {
        run_ok(cluster.cmd("scontrol").args(&args));
    }
    let t = Instant::now();
    cluster.wait(&id, Duration::from_secs(600));
    eprintln!(
        "slurm: the requeued task finished {:.1} s after the requeue",
        t.elapsed().as_secs_f64()
    );
    let v = clevrtex().arg("verify").arg(&out2).output().unwrap();
    assert_eq!(v.status.code(), Some(0), "{}\n{}", text(&v), cluster.logs());
    let left = processes_under(&tmp);
    assert!(left.is_empty(), "orphan processes: {left:?}");

    // 3. Task 2 resubmitted alone (`--array=2`) after its outputs are deleted: it renders
    // exactly shard 2 of 4 (indices 2, 6, 10), not every image as shard 0 of 1.
    let sub = out2.join("clevrtex_clevr/0");
    for e in std::fs::read_dir(&sub).unwrap().flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let index: Option<u64> = name
            .strip_prefix("CLEVRTEX_clevr_")
            .and_then(|r| r.get(..6))
            .and_then(|d| d.parse().ok());
        if index.is_some_and(|i| i % 4 == 2) {
            std::fs::remove_file(e.path()).unwrap();
        }
    }
    for e in std::fs::read_dir(out2.join("clevrtex_clevr"))
        .unwrap()
        .flatten()
    {
        let name = e.file_name().to_string_lossy().into_owned();
        if name.starts_with("MANIFEST") && name.contains("2of4") {
            std::fs::remove_file(e.path()).unwrap();
        }
    }
    let before: std::collections::BTreeSet<String> = std::fs::read_dir(&sub)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    let logs3 = work.path().join("logs3");
    std::fs::create_dir_all(&logs3).unwrap();
    let id = cluster.submit_array("2", &env(&out2), &logs3);
    cluster.wait(&id, Duration::from_secs(600));
    let after: std::collections::BTreeSet<String> = std::fs::read_dir(&sub)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    let made: Vec<String> = after
        .difference(&before)
        .filter(|n| n.ends_with(".json"))
        .cloned()
        .collect();
    assert_eq!(
        made,
        [
            "CLEVRTEX_clevr_000002.json",
            "CLEVRTEX_clevr_000006.json",
            "CLEVRTEX_clevr_000010.json"
        ],
        "{}",
        std::fs::read_to_string(logs3.join("task-2.log")).unwrap_or_default()
    );
    let v = clevrtex().arg("verify").arg(&out2).output().unwrap();
    assert_eq!(v.status.code(), Some(0), "{}", text(&v));
}

/// The GPU template (issue 35): no GPU and no GRES-configured SLURM here, so what is checked is
/// that it asks SLURM for GPUs and an array, and that its command, run as a task of a 4-task
/// array would run it, is one the real `clevrtex` accepts (it gets as far as looking for its
/// Blender: not a usage, shard or device-name error).
#[test]
fn gpu_template_requests_gpus_and_runs_a_valid_command() {
    let script = repo_root().join("deploy/slurm/generate-gpu.sbatch");
    let text_of = std::fs::read_to_string(&script).unwrap();
    let directives: Vec<&str> = text_of
        .lines()
        .filter_map(|l| l.strip_prefix("#SBATCH "))
        .collect();
    assert!(
        directives.iter().any(|d| d.starts_with("--gres=gpu:")),
        "{directives:?}"
    );
    assert!(
        directives.iter().any(|d| d.starts_with("--array=")),
        "{directives:?}"
    );
    assert!(directives.contains(&"--requeue"), "{directives:?}");
    let dir = tempfile::tempdir().unwrap();
    let o = Command::new("bash")
        .arg(&script)
        .env("OUT", dir.path().join("out"))
        .env("SHARDS", "4")
        .env("SLURM_ARRAY_TASK_ID", "2")
        .env("CLEVRTEX", env!("CARGO_BIN_EXE_clevrtex"))
        .env("BLENDER", "/no/such/blender")
        .env("COUNT", "12")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("blender not found at `/no/such/blender`"),
        "{}",
        text(&o)
    );
    // Without SHARDS it refuses, as the CPU template does.
    let o = Command::new("bash")
        .arg(&script)
        .env("OUT", dir.path().join("out"))
        .env_remove("SHARDS")
        .env("SLURM_ARRAY_TASK_ID", "2")
        .output()
        .unwrap();
    assert_ne!(o.status.code(), Some(0), "{}", text(&o));
    assert!(text(&o).contains("set SHARDS"), "{}", text(&o));
}

/// The suite as one array (issue 41): `SUITE=clevrtex SCALE=...` makes the template's tasks
/// split the whole suite, not each variant; the union is the whole suite (`verify`), the same
/// layouts, masks and metadata as one local run (`verify --against`).
#[test]
fn slurm_array_makes_the_whole_suite() {
    let Some(blender) = blender_or_skip("slurm_array_makes_the_whole_suite") else {
        return;
    };
    let Some(cluster) = Cluster::start() else {
        return;
    };
    let work = tempfile::tempdir().unwrap();
    let bin = PathBuf::from(env!("CARGO_BIN_EXE_clevrtex"));
    let extra = format!(
        "--width 32 --height 24 --samples 1 --passes rgb,mask --blender {}",
        blender.display()
    );
    let tmp = work.path().join("tmp");
    std::fs::create_dir_all(&tmp).unwrap();
    let (out, logs) = (work.path().join("slurm"), work.path().join("logs"));
    std::fs::create_dir_all(&logs).unwrap();
    let env = vec![
        ("OUT", out.display().to_string()),
        ("CLEVRTEX", bin.display().to_string()),
        ("SUITE", "clevrtex".to_string()),
        ("SCALE", "0.0001".to_string()),
        ("SHARDS", "2".to_string()),
        ("EXTRA_ARGS", extra.clone()),
        ("TMPDIR", tmp.display().to_string()),
    ];
    let id = cluster.submit(2, &env, &logs);
    cluster.wait(&id, Duration::from_secs(600));
    let task_logs: String = (0..2)
        .map(|k| std::fs::read_to_string(logs.join(format!("task-{k}.log"))).unwrap_or_default())
        .collect();
    // Each task made its share of every variant the shard holds images of.
    for k in 0..2 {
        let log = std::fs::read_to_string(logs.join(format!("task-{k}.log"))).unwrap_or_default();
        assert!(
            log.contains(&format!("shard {k}/2"))
                && log.contains("suite `clevrtex` at scale 0.0001"),
            "task {k}: {log}"
        );
    }
    let v = clevrtex().arg("verify").arg(&out).output().unwrap();
    assert_eq!(v.status.code(), Some(0), "{}\n{task_logs}", text(&v));
    assert!(
        text(&v).contains("suite `clevrtex` at scale 0.0001: whole (6 variants, 14 images)"),
        "{}",
        text(&v)
    );
    let local = work.path().join("local");
    let o = clevrtex()
        .args(["generate", "--suite", "clevrtex", "--scale", "0.0001"])
        .args(extra.split(' '))
        .arg("--out")
        .arg(&local)
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("SLURM_ARRAY_TASK_COUNT")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let v = clevrtex()
        .arg("verify")
        .arg(&out)
        .arg("--against")
        .arg(&local)
        .output()
        .unwrap();
    assert_eq!(v.status.code(), Some(0), "{}", text(&v));
    assert_eq!(
        text(&v).matches("same layouts, masks and metadata").count(),
        6,
        "{}",
        text(&v)
    );
}
