//! The Kubernetes Indexed Job (`deploy/k8s/`): no cluster here, so what can be checked is: the
//! YAML parses (with PyYAML, as kubectl's parser would) into an Indexed Job whose image, user
//! and command are the ones the Dockerfile builds, and whose arguments the real `clevrtex`
//! accepts; and `generate` with `JOB_COMPLETION_INDEX=k` for every `k` makes the same union
//! as one run.

use std::path::Path;

use serde_json::Value;

use crate::util::{blender_or_skip, clevrtex, repo_root, test_python_or_skip, text};

#[test]
fn indexed_job_yaml_names_the_dockerfiles_image_and_a_valid_command() {
    check_job("indexed_job_yaml", "deploy/k8s/indexed-job.yaml", "");
}

/// The GPU variant (issue 35) passes the same checks, with the Dockerfile's `gpu` target as its
/// image; each pod holds one GPU and runs four CUDA workers on it (a worker leaves its GPU idle
/// while it builds the scene on the CPU), with the cores they use.
#[test]
fn gpu_indexed_job_names_the_gpu_image_one_gpu_and_four_workers_per_pod() {
    let Some(job) = check_job(
        "gpu_indexed_job_yaml",
        "deploy/k8s/indexed-job-gpu.yaml",
        "-gpu",
    ) else {
        return;
    };
    let c = &job["spec"]["template"]["spec"]["containers"][0];
    for side in ["limits", "requests"] {
        assert_eq!(c["resources"][side]["nvidia.com/gpu"], 1, "{side}: {c}");
    }
    let args: Vec<&str> = c["args"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a.as_str().unwrap())
        .collect();
    let after = |flag: &str| args.iter().position(|a| *a == flag).map(|i| args[i + 1]);
    assert_eq!(after("--workers"), Some("4"), "{args:?}");
    assert_eq!(after("--device"), Some("cuda"), "{args:?}");
    // Every worker's threads have a requested core: workers x threads = the CPU request.
    let threads: u32 = after("--threads").unwrap().parse().unwrap();
    assert_eq!(
        c["resources"]["requests"]["cpu"],
        (4 * threads).to_string(),
        "{c}"
    );
    let dockerfile = std::fs::read_to_string(repo_root().join("deploy/k8s/Dockerfile")).unwrap();
    assert!(
        dockerfile.contains("FROM debian:bookworm-slim AS gpu"),
        "{dockerfile}"
    );
    assert!(
        dockerfile.contains("--target gpu -t clevrtex:"),
        "{dockerfile}"
    );
    assert!(
        dockerfile.contains("cuda_kernels.py --cuda-arch"),
        "{dockerfile}"
    );
    // The CPU image stays the default target (the last stage).
    let last = dockerfile.rfind("\nFROM ").unwrap();
    assert!(
        dockerfile[last..].starts_with("\nFROM debian:bookworm-slim AS cpu"),
        "{dockerfile}"
    );
}

/// The checks every Job of `yaml` passes: an Indexed Job with a PVC, CLEVRTEX_SHARD_COUNT equal
/// to `completions`, the Dockerfile's image (`clevrtex:VERSION<tag>`) and user, and arguments the
/// real `clevrtex` accepts. The Job, or `None` when skipped.
fn check_job(name: &str, yaml: &str, tag: &str) -> Option<Value> {
    let python = test_python_or_skip(name, "yaml")?;
    let yaml = repo_root().join(yaml);
    let o = std::process::Command::new(&python)
        .args([
            "-c",
            "import json, sys, yaml; print(json.dumps(list(yaml.safe_load_all(open(sys.argv[1])))))",
        ])
        .arg(&yaml)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let docs: Vec<Value> = serde_json::from_slice(&o.stdout).unwrap();
    let job = docs.iter().find(|d| d["kind"] == "Job").expect("a Job");
    let pvc = docs
        .iter()
        .find(|d| d["kind"] == "PersistentVolumeClaim")
        .expect("a PVC");
    let spec = &job["spec"];
    assert_eq!(spec["completionMode"], "Indexed");
    assert!(spec["backoffLimitPerIndex"].as_u64().is_some());
    let completions = spec["completions"].as_u64().unwrap();
    let pod = &spec["template"]["spec"];
    let c = &pod["containers"][0];
    let env: Vec<(String, String)> = c["env"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| {
            (
                e["name"].as_str().unwrap().to_string(),
                // Entries from the downward API (`valueFrom`) have no literal value.
                e["value"].as_str().unwrap_or_default().to_string(),
            )
        })
        .collect();
    assert!(
        env.contains(&("CLEVRTEX_SHARD_COUNT".into(), completions.to_string())),
        "CLEVRTEX_SHARD_COUNT must equal completions: {env:?}"
    );
    assert_eq!(
        pod["volumes"][0]["persistentVolumeClaim"]["claimName"],
        pvc["metadata"]["name"]
    );

    // The image and user are the Dockerfile's.
    let dockerfile = std::fs::read_to_string(repo_root().join("deploy/k8s/Dockerfile")).unwrap();
    let image = c["image"].as_str().unwrap();
    assert_eq!(
        image,
        format!("clevrtex:{}{tag}", env!("CARGO_PKG_VERSION"))
    );
    assert!(dockerfile.contains(&format!("-t {image} ")), "{dockerfile}");
    assert!(dockerfile.contains("ENTRYPOINT [\"/usr/local/bin/clevrtex\"]"));
    let uid = pod["securityContext"]["runAsUser"].as_u64().unwrap();
    assert!(dockerfile.contains(&format!("USER {uid}")), "{dockerfile}");

    // The real binary accepts the arguments: with pod 0's index it gets as far as looking for
    // Blender (not a usage error, not a shard error).
    let args: Vec<String> = c["args"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a.as_str().unwrap().to_string())
        .collect();
    assert_eq!(args[0], "generate");
    let dir = tempfile::tempdir().unwrap();
    let args: Vec<String> = args
        .iter()
        .map(|a| {
            if a == "/data" {
                dir.path().display().to_string()
            } else {
                a.clone()
            }
        })
        .collect();
    let o = clevrtex()
        .args(&args)
        .args(["--blender", "/no/such/blender"])
        .env("JOB_COMPLETION_INDEX", "0")
        .envs(env.iter().map(|(k, v)| (k.as_str(), v.as_str())))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("blender not found at `/no/such/blender`"),
        "{}",
        text(&o)
    );
    Some(job.clone())
}

/// Images, masks, depth and metadata of one output folder.
fn comparable(out: &Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(out.join("clevrtex_clevr/0"))
        .unwrap()
        .flatten()
        .filter(|e| {
            let n = e.file_name().to_string_lossy().into_owned();
            n.ends_with(".png") || n.ends_with(".json")
        })
        .map(|e| {
            (
                e.file_name().to_string_lossy().into_owned(),
                std::fs::read(e.path()).unwrap(),
            )
        })
        .collect()
}

#[test]
fn job_completion_index_shards_make_the_same_union_as_one_run() {
    let Some(blender) = blender_or_skip("job_completion_index_shards") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let run = |out: &Path, index: Option<u64>| {
        let mut c = clevrtex();
        c.args(["generate", "--variant", "clevr", "-n", "6", "--seed", "9"])
            .args([
                "--width",
                "40",
                "--height",
                "30",
                "--samples",
                "1",
                "--workers",
                "1",
            ])
            .args(["--passes", "rgb,mask,depth", "--blender"])
            .arg(&blender)
            .arg("--out")
            .arg(out)
            .env_remove("SLURM_ARRAY_TASK_ID")
            .env_remove("JOB_COMPLETION_INDEX");
        if let Some(k) = index {
            c.env("JOB_COMPLETION_INDEX", k.to_string())
                .env("CLEVRTEX_SHARD_COUNT", "3");
        }
        let o = c.output().unwrap();
        assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    };
    let (pods, one) = (dir.path().join("pods"), dir.path().join("one"));
    for k in 0..3 {
        run(&pods, Some(k));
    }
    run(&one, None);
    let (a, b) = (comparable(&pods), comparable(&one));
    assert_eq!(a.len(), 24);
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (name, bytes) in &a {
        crate::util::assert_same_sample_file(name, bytes, &b[name]);
    }
    let v = clevrtex().arg("verify").arg(&pods).output().unwrap();
    assert_eq!(v.status.code(), Some(0), "{}", text(&v));
    assert!(text(&v).contains("3 manifest(s)"), "{}", text(&v));
}

/// The Job as JSON, parsed by PyYAML; `None` when the test Python lacks it (skipped).
fn job_json(name: &str) -> Option<Value> {
    let python = test_python_or_skip(name, "yaml")?;
    let yaml = repo_root().join("deploy/k8s/indexed-job.yaml");
    let o = std::process::Command::new(&python)
        .args([
            "-c",
            "import json, sys, yaml; print(json.dumps(list(yaml.safe_load_all(open(sys.argv[1])))))",
        ])
        .arg(&yaml)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let docs: Vec<Value> = serde_json::from_slice(&o.stdout).unwrap();
    docs.into_iter().find(|d| d["kind"] == "Job")
}

#[test]
fn indexed_job_has_a_tmp_emptydir_and_preemption_does_not_use_up_retries() {
    let Some(job) = job_json("indexed_job_tmp_and_pod_failure_policy") else {
        return;
    };
    let pod = &job["spec"]["template"]["spec"];
    // /tmp is an emptyDir volume mounted in the container.
    let tmp_volume = pod["volumes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|v| v["emptyDir"].is_object())
        .unwrap_or_else(|| panic!("no emptyDir volume: {pod}"));
    let mounts = pod["containers"][0]["volumeMounts"].as_array().unwrap();
    assert!(
        mounts
            .iter()
            .any(|m| m["mountPath"] == "/tmp" && m["name"] == tmp_volume["name"]),
        "/tmp is not the emptyDir: {mounts:?}"
    );
    // Preemption (SIGTERM -> exit 143, or the DisruptionTarget condition) is ignored, so it
    // does not count against backoffLimitPerIndex.
    let rules = job["spec"]["podFailurePolicy"]["rules"]
        .as_array()
        .unwrap_or_else(|| panic!("no podFailurePolicy rules: {}", job["spec"]));
    assert!(
        rules.iter().any(|r| r["action"] == "Ignore"
            && r["onExitCodes"]["operator"] == "In"
            && r["onExitCodes"]["values"]
                .as_array()
                .is_some_and(|v| v.iter().any(|c| c == 143))),
        "no Ignore rule for exit code 143: {rules:?}"
    );
    assert!(
        rules.iter().any(|r| r["action"] == "Ignore"
            && r["onPodConditions"]
                .as_array()
                .is_some_and(|c| c.iter().any(|c| c["type"] == "DisruptionTarget"))),
        "no Ignore rule for DisruptionTarget: {rules:?}"
    );
}

/// The pods' host in clevrtex's owner tags and range locks is the job and the completion
/// index (`CLEVRTEX_HOST`), not the pod name: a pod restarted for the same index (a new pod
/// name) then finds a killed pod's temporaries and lock in the shared folder stale, instead of
/// taking them for another live host's. Before, the pod name was the host.
#[test]
fn indexed_job_names_the_host_by_job_and_index_not_by_pod() {
    let Some(job) = job_json("indexed_job_names_the_host_by_job_and_index") else {
        return;
    };
    let env = job["spec"]["template"]["spec"]["containers"][0]["env"]
        .as_array()
        .unwrap()
        .clone();
    let by_name = |n: &str| -> Option<&Value> { env.iter().find(|e| e["name"] == n) };
    let host = by_name("CLEVRTEX_HOST").unwrap_or_else(|| panic!("no CLEVRTEX_HOST: {env:?}"));
    let value = host["value"].as_str().unwrap_or_default();
    // Both parts come from the pod's own metadata, defined before the value that uses them.
    let pos = |n: &str| env.iter().position(|e| e["name"] == n).unwrap();
    for (var, field) in [
        (
            "CLEVRTEX_JOB_NAME",
            "metadata.labels['batch.kubernetes.io/job-name']",
        ),
        (
            "CLEVRTEX_JOB_INDEX",
            "metadata.annotations['batch.kubernetes.io/job-completion-index']",
        ),
    ] {
        assert!(value.contains(&format!("$({var})")), "{value}");
        let e = by_name(var).unwrap_or_else(|| panic!("no {var}: {env:?}"));
        assert_eq!(e["valueFrom"]["fieldRef"]["fieldPath"], field, "{var}");
        assert!(pos(var) < pos("CLEVRTEX_HOST"), "{var} must come first");
    }
    // And clevrtex reads that variable.
    let src =
        std::fs::read_to_string(crate::util::repo_root().join("crates/dataset/src/atomic.rs"))
            .unwrap();
    assert!(src.contains("pub const HOST_ENV: &str = \"CLEVRTEX_HOST\""));
}
