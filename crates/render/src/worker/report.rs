//! What a worker reports besides its replies: the bridge's timings of a request, the tails of
//! Blender's output kept for error reports, and the lines `doctor` prints of a `ready` reply.

use std::collections::VecDeque;

use serde::Deserialize;

use super::protocol::Ready;
use crate::error::Tails;

/// Lines of stdout and of stderr kept for error reports.
const TAIL_LINES: usize = 25;
/// Longest line kept in the error tails.
const MAX_TAIL_LINE: usize = 4096;

/// Timings the bridge reports for one request, in seconds.
#[derive(Debug, Clone, Copy, Default, Deserialize)]
pub struct BridgeTimings {
    /// Building (or updating) the Blender scene; 0 when the build was reused.
    #[serde(default)]
    pub build_s: f64,
    /// Cycles rendering.
    #[serde(default)]
    pub render_s: f64,
    /// CPU seconds of the whole Blender process (all threads) during the final render (not
    /// the shadow pass's); `None` from bridges older than this field and for visibility renders.
    #[serde(default)]
    pub render_cpu_s: Option<f64>,
    /// Writing the output files.
    #[serde(default)]
    pub write_s: f64,
    /// The shadow pass's two direct-light renders, together (0 without the pass).
    #[serde(default)]
    pub shadow_render_s: f64,
}

/// The last lines of Blender's stdout (its chatter, not the replies) and stderr.
#[derive(Debug, Default)]
pub(super) struct OutputTails {
    stdout: VecDeque<String>,
    stderr: VecDeque<String>,
}

impl OutputTails {
    /// Keep `line` of stdout.
    pub(super) fn push_stdout(&mut self, line: &str) {
        push_tail(&mut self.stdout, line);
    }

    /// Keep `line` of stderr.
    pub(super) fn push_stderr(&mut self, line: &str) {
        push_tail(&mut self.stderr, line);
    }

    /// The lines kept, for an error report.
    pub(super) fn snapshot(&self) -> Tails {
        Tails {
            stdout: self.stdout.iter().cloned().collect(),
            stderr: self.stderr.iter().cloned().collect(),
        }
    }
}

fn push_tail(tail: &mut VecDeque<String>, line: &str) {
    if tail.len() == TAIL_LINES {
        tail.pop_front();
    }
    let mut end = line.len().min(MAX_TAIL_LINE);
    while !line.is_char_boundary(end) {
        end -= 1;
    }
    if end < line.len() {
        tail.push_back(format!(
            "{} [... {} more bytes]",
            &line[..end],
            line.len() - end
        ));
    } else {
        tail.push_back(line.to_string());
    }
}

impl Ready {
    /// For `doctor`: one line per NVIDIA GPU (named by `caps`, see
    /// [`crate::device::nvidia_compute_capabilities`]) on whether this Blender ships its CUDA
    /// kernel or has the driver compile one at the first render; none without such GPUs.
    pub fn cuda_kernel_lines(&self, caps: &[(String, u32)]) -> Vec<String> {
        use crate::device::KernelLoad;
        let mut seen = std::collections::BTreeSet::new();
        crate::device::kernel_loads(&self.gpus, &self.cuda_kernels, caps)
            .into_iter()
            .filter(|(g, _, _)| seen.insert(g.name.clone()))
            .map(|(g, cc, load)| {
                let what = match load {
                    KernelLoad::Shipped => format!("shipped (sm_{cc}): nothing to compile"),
                    KernelLoad::Prepared => format!(
                        "prepared (sm_{cc}, compiled ahead of time by `scripts/cuda_kernels.py`): nothing to compile"
                    ),
                    KernelLoad::Compiled { from } => format!(
                        "will be compiled: none for sm_{cc}, so the driver compiles PTX compute_{from} at each worker's first render unless its cache holds it (many minutes; prepare it once with `./scripts/setup.sh --bpy 4.5 --cuda-arch {cc}`)"
                    ),
                    KernelLoad::Missing => format!("none for sm_{cc} and no PTX: Cycles cannot use it"),
                };
                format!(
                    "cuda kernel for `{}` ({}.{}): {what}; this Blender ships {}",
                    g.name,
                    cc / 10,
                    cc % 10,
                    self.cuda_kernels.describe()
                )
            })
            .collect()
    }

    /// `gpus: ...; oidn: yes; path guiding: yes; light tree: yes`, for `doctor`.
    pub fn features_line(&self) -> String {
        let gpus: Vec<String> = self
            .gpus
            .iter()
            .map(|g| format!("{} `{}`", g.kind, g.name))
            .collect();
        let yes_no = |b: bool| if b { "yes" } else { "no" };
        let f = &self.features;
        format!(
            "gpus: {}; oidn: {}; path guiding: {}; light tree: {}",
            if gpus.is_empty() {
                "none".to_string()
            } else {
                gpus.join(", ")
            },
            yes_no(f.oidn),
            yes_no(f.path_guiding),
            yes_no(f.light_tree)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `doctor`'s line per NVIDIA GPU: shipped, prepared (`scripts/cuda_kernels.py`) or will
    /// be compiled, as the bridge's `ready` reports the kernels.
    #[test]
    fn doctor_says_per_gpu_whether_its_kernel_is_shipped_prepared_or_compiled() {
        let ready: Ready = serde_json::from_str(
            r#"{"type": "ready", "bridge_version": 1, "blender_version": "4.5.3",
                "cycles_devices": ["CPU", "CUDA"],
                "gpus": [{"kind": "CUDA", "name": "H100"}, {"kind": "CUDA", "name": "A100"},
                         {"kind": "CUDA", "name": "L4"}],
                "cuda_kernels": {"cubin": [75, 89, 90], "ptx": [75], "prepared": [90]}}"#,
        )
        .unwrap();
        let caps = [
            ("H100".to_string(), 90),
            ("A100".to_string(), 80),
            ("L4".to_string(), 89),
        ];
        let lines = ready.cuda_kernel_lines(&caps);
        assert_eq!(lines.len(), 3, "{lines:?}");
        assert!(
            lines[0].contains("`H100` (9.0): prepared (sm_90"),
            "{}",
            lines[0]
        );
        assert!(
            lines[1].contains("`A100` (8.0): will be compiled: none for sm_80")
                && lines[1].contains("--cuda-arch 80"),
            "{}",
            lines[1]
        );
        assert!(
            lines[2].contains("`L4` (8.9): shipped (sm_89)"),
            "{}",
            lines[2]
        );
    }
}
