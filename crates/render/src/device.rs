//! Which Cycles device each worker renders on (`--device auto|cpu|cuda|optix|hip`).
//!
//! The choice is made from the GPUs a first worker reports in its `ready` message
//! ([`crate::Ready::gpus`]): with N GPUs of the chosen kind, worker `i` is pinned to GPU
//! `i % N` by its index within that kind (the bridge enables exactly that one device), so a
//! machine with N GPUs spreads its workers evenly over them ([`default_workers`]: several per
//! GPU where there are cores to feed them), with no `CUDA_VISIBLE_DEVICES` juggling.

use serde::Deserialize;

/// A GPU as the bridge reports it (`gpus` of the `ready` reply).
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
pub struct Gpu {
    /// Cycles' device type: `CUDA`, `OPTIX`, `HIP`, `ONEAPI`, `METAL`.
    pub kind: String,
    /// The device's name, e.g. `NVIDIA H100 80GB HBM3`.
    pub name: String,
    /// Cycles' device id.
    #[serde(default)]
    pub id: String,
}

/// How long a worker may take over its renders, on top of the usual limits, on a GPU whose
/// CUDA kernel the driver must compile first ([`Placement::compiles_kernel`]): Cycles 4.5's
/// kernel did not finish compiling for an H100 in 9 minutes (docs/performance.md, "GPUs").
pub const KERNEL_COMPILE_GRACE: std::time::Duration = std::time::Duration::from_secs(3600);

/// The CUDA kernels a Blender's Cycles ships (`cuda_kernels` of the `ready` reply), as compute
/// capabilities 10 x major + minor (`sm_89` is 89, `sm_120` is 120).
#[derive(Debug, Clone, Default, PartialEq, Eq, Deserialize)]
pub struct CudaKernels {
    /// Ready-made kernels (`kernel_sm_XY.cubin`): each runs on exactly that capability.
    #[serde(default)]
    pub cubin: Vec<u32>,
    /// PTX (`kernel_compute_XY.ptx`), which the driver compiles for any later capability.
    #[serde(default)]
    pub ptx: Vec<u32>,
    /// The cubins of `cubin` that `scripts/cuda_kernels.py` compiled from the PTX ahead of
    /// time (listed in `lib/clevrtex-prepared.json`): Cycles loads them as its own.
    #[serde(default)]
    pub prepared: Vec<u32>,
}

/// How Cycles gets its CUDA kernel for a GPU ([`CudaKernels::load_for`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KernelLoad {
    /// A cubin made for this compute capability ships: nothing to compile.
    Shipped,
    /// A cubin for this compute capability was compiled ahead of time by
    /// `scripts/cuda_kernels.py` (`setup.sh --cuda-arch`): nothing to compile at run time.
    Prepared,
    /// The driver compiles the PTX of this (older) capability at the first render.
    Compiled {
        /// The PTX's compute capability (10 x major + minor).
        from: u32,
    },
    /// Neither: Cycles cannot render on this GPU.
    Missing,
}

impl CudaKernels {
    /// What Cycles does on a GPU of compute capability `cc` (10 x major + minor), as its CUDA
    /// device's `compile_kernel` does: the cubin of exactly `cc`, else the newest PTX not newer
    /// than `cc`, compiled by the driver.
    pub fn load_for(&self, cc: u32) -> KernelLoad {
        if self.cubin.contains(&cc) && self.prepared.contains(&cc) {
            KernelLoad::Prepared
        } else if self.cubin.contains(&cc) {
            KernelLoad::Shipped
        } else if let Some(from) = self.ptx.iter().copied().filter(|p| *p <= cc).max() {
            KernelLoad::Compiled { from }
        } else {
            KernelLoad::Missing
        }
    }

    /// `sm_50, sm_52, ...; PTX compute_75`, for messages.
    pub fn describe(&self) -> String {
        let list = |v: &[u32], p: &str| -> String {
            v.iter()
                .map(|c| format!("{p}{c}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        format!(
            "cubins {}{}; PTX {}",
            if self.cubin.is_empty() {
                "none".into()
            } else {
                list(&self.cubin, "sm_")
            },
            if self.prepared.is_empty() {
                String::new()
            } else {
                format!(" ({} prepared)", list(&self.prepared, "sm_"))
            },
            if self.ptx.is_empty() {
                "none".into()
            } else {
                list(&self.ptx, "compute_")
            }
        )
    }
}

/// `major.minor` as 10 x major + minor (`9.0` is 90, `12.0` is 120); `None` if not that form.
fn capability(text: &str) -> Option<u32> {
    let (major, minor) = text.trim().split_once('.')?;
    let (major, minor): (u32, u32) = (major.parse().ok()?, minor.parse().ok()?);
    (minor < 10 && major < 100).then_some(major * 10 + minor)
}

/// (name, compute capability) per line of `nvidia-smi --query-gpu=name,compute_cap
/// --format=csv,noheader` (`NVIDIA H100 80GB HBM3, 9.0`); lines of another form are skipped.
pub fn parse_compute_capabilities(text: &str) -> Vec<(String, u32)> {
    text.lines()
        .filter_map(|l| {
            let (name, cc) = l.rsplit_once(',')?;
            Some((name.trim().to_string(), capability(cc)?))
        })
        .collect()
}

/// The NVIDIA GPUs' compute capabilities, by name, as `nvidia-smi` reports them (empty where
/// it is missing or fails: then nothing is known, and nothing is assumed).
pub fn nvidia_compute_capabilities() -> Vec<(String, u32)> {
    std::process::Command::new("nvidia-smi")
        .args(["--query-gpu=name,compute_cap", "--format=csv,noheader"])
        .stderr(std::process::Stdio::null())
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| parse_compute_capabilities(&String::from_utf8_lossy(&o.stdout)))
        .unwrap_or_default()
}

/// For each CUDA or OptiX GPU of `gpus` whose compute capability `caps` gives (by name), how
/// Cycles gets its kernel from `kernels`: `(gpu, capability, load)`.
pub fn kernel_loads<'g>(
    gpus: &'g [Gpu],
    kernels: &CudaKernels,
    caps: &[(String, u32)],
) -> Vec<(&'g Gpu, u32, KernelLoad)> {
    gpus.iter()
        .filter(|g| g.kind == "CUDA" || g.kind == "OPTIX")
        .filter_map(|g| {
            let cc = caps.iter().find(|(name, _)| *name == g.name)?.1;
            Some((g, cc, kernels.load_for(cc)))
        })
        .collect()
}

/// Mark the placements whose GPU needs its kernel compiled ([`Placement::compiles_kernel`]).
pub fn mark_kernel_compiles(
    placements: &mut [Placement],
    kernels: &CudaKernels,
    caps: &[(String, u32)],
) {
    for p in placements.iter_mut().filter(|p| p.is_gpu()) {
        let gpu = Gpu {
            kind: p.kind.clone(),
            name: p.name.clone(),
            id: String::new(),
        };
        if let Some((_, cc, KernelLoad::Compiled { from })) =
            kernel_loads(std::slice::from_ref(&gpu), kernels, caps).first()
        {
            p.compiles_kernel = Some(format!(
                "compute capability {}.{}: this Blender ships {}, so the driver compiles PTX compute_{from}",
                cc / 10,
                cc % 10,
                kernels.describe()
            ));
        }
    }
}

/// The warning `generate` and `render` print when a worker's GPU needs its kernel compiled.
pub fn kernel_compile_warning(placements: &[Placement]) -> Option<String> {
    let p = placements.iter().find(|p| p.compiles_kernel.is_some())?;
    Some(format!(
        "warning: `{}` has no ready-made Cycles kernel in this Blender ({}); each worker's first \
         render waits while the driver compiles it (many minutes: over 9 on an H100 with bpy \
         4.5), so its time limits are raised by {} min; CUDA_CACHE_MAXSIZE is set to 4 GiB so the \
         driver keeps the result for later runs on this machine\nhint: compile the kernel once, \
         ahead of time, with `./scripts/setup.sh --bpy 4.5 --cuda-arch {}` (no GPU needed; \
         docs/performance.md, \"GPUs\"), or warm the cache once per node before a large job \
         (`clevrtex generate -n 1 --device {} --out /tmp/warm`)",
        p.name,
        p.compiles_kernel.as_deref().unwrap_or_default(),
        KERNEL_COMPILE_GRACE.as_secs() / 60,
        // The note starts `compute capability 9.0: ...` (`mark_kernel_compiles`).
        p.compiles_kernel
            .as_deref()
            .and_then(|n| n.strip_prefix("compute capability "))
            .and_then(|n| n.split(':').next())
            .and_then(capability)
            .map(|c| c.to_string())
            .unwrap_or_else(|| "XY".into()),
        p.kind.to_ascii_lowercase()
    ))
}

/// What `--device` asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DeviceChoice {
    /// The best GPU kind found (OptiX, then CUDA, then HIP, then oneAPI), else the CPU.
    #[default]
    Auto,
    /// The CPU.
    Cpu,
    /// NVIDIA GPUs through CUDA.
    Cuda,
    /// NVIDIA GPUs through OptiX (RTX cores).
    Optix,
    /// AMD GPUs through HIP.
    Hip,
}

impl DeviceChoice {
    /// Every choice with its command-line name.
    pub const ALL: [(DeviceChoice, &'static str); 5] = [
        (DeviceChoice::Auto, "auto"),
        (DeviceChoice::Cpu, "cpu"),
        (DeviceChoice::Cuda, "cuda"),
        (DeviceChoice::Optix, "optix"),
        (DeviceChoice::Hip, "hip"),
    ];

    /// Parse a command-line name (case-insensitive).
    pub fn parse(name: &str) -> Option<DeviceChoice> {
        Self::ALL
            .iter()
            .find(|(_, n)| n.eq_ignore_ascii_case(name.trim()))
            .map(|(c, _)| *c)
    }

    /// The command-line name.
    pub fn name(self) -> &'static str {
        Self::ALL.iter().find(|(c, _)| *c == self).unwrap().1
    }

    /// Cycles' device type for an explicit GPU choice.
    fn kind(self) -> Option<&'static str> {
        match self {
            DeviceChoice::Cuda => Some("CUDA"),
            DeviceChoice::Optix => Some("OPTIX"),
            DeviceChoice::Hip => Some("HIP"),
            DeviceChoice::Auto | DeviceChoice::Cpu => None,
        }
    }
}

/// GPU kinds in the order `auto` prefers them.
const AUTO_ORDER: [&str; 4] = ["OPTIX", "CUDA", "HIP", "ONEAPI"];

/// Where one worker renders: `CPU`, or the `index`-th GPU of Cycles' type `kind`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Placement {
    /// `CPU`, `CUDA`, `OPTIX`, `HIP`, ...
    pub kind: String,
    /// Index among the GPUs of `kind` (0 for the CPU).
    pub index: usize,
    /// The GPU's name (empty for the CPU).
    pub name: String,
    /// Set where Blender ships no CUDA kernel for this NVIDIA GPU, so that Cycles has the
    /// driver compile one from PTX at a worker's first render (minutes; see
    /// [`CudaKernels::load_for`]): what is missing, for messages. The pool then allows that
    /// first render [`KERNEL_COMPILE_GRACE`] more.
    pub compiles_kernel: Option<String>,
}

impl Placement {
    /// The CPU.
    pub fn cpu() -> Placement {
        Placement {
            kind: "CPU".into(),
            index: 0,
            name: String::new(),
            compiles_kernel: None,
        }
    }

    /// Whether this is a GPU.
    pub fn is_gpu(&self) -> bool {
        self.kind != "CPU"
    }

    /// The bridge's `--device` argument, e.g. `CUDA:1` or `CPU`.
    pub fn arg(&self) -> String {
        if self.is_gpu() {
            format!("{}:{}", self.kind, self.index)
        } else {
            "CPU".into()
        }
    }

    /// For messages: `CPU` or `OPTIX 1 (NVIDIA H100)`.
    pub fn describe(&self) -> String {
        if self.is_gpu() {
            format!("{} {} ({})", self.kind, self.index, self.name)
        } else {
            "CPU".into()
        }
    }
}

impl Default for Placement {
    fn default() -> Self {
        Placement::cpu()
    }
}

/// The devices to spread workers over for `choice`, given the GPUs a worker reported: one
/// [`Placement`] per GPU of the chosen kind, or the CPU alone. An explicit GPU kind that is
/// absent is an error naming what was found.
pub fn plan(choice: DeviceChoice, gpus: &[Gpu]) -> Result<Vec<Placement>, String> {
    let of_kind = |kind: &str| -> Vec<Placement> {
        gpus.iter()
            .filter(|g| g.kind == kind)
            .enumerate()
            .map(|(index, g)| Placement {
                kind: kind.to_string(),
                index,
                name: g.name.clone(),
                compiles_kernel: None,
            })
            .collect()
    };
    match choice {
        DeviceChoice::Cpu => Ok(vec![Placement::cpu()]),
        DeviceChoice::Auto => Ok(AUTO_ORDER
            .iter()
            .map(|k| of_kind(k))
            .find(|v| !v.is_empty())
            .unwrap_or_else(|| vec![Placement::cpu()])),
        explicit => {
            let kind = explicit.kind().expect("a GPU choice");
            let found = of_kind(kind);
            if found.is_empty() {
                let seen: Vec<String> = gpus
                    .iter()
                    .map(|g| format!("{} `{}`", g.kind, g.name))
                    .collect();
                Err(format!(
                    "`--device {}`: Blender reports no {kind} device (found: {})\nhint: use `--device auto` (the best found, else the CPU) or `--device cpu`; `clevrtex doctor` lists the devices",
                    explicit.name(),
                    if seen.is_empty() { "no GPU".to_string() } else { seen.join(", ") }
                ))
            } else {
                Ok(found)
            }
        }
    }
}

/// Whether this machine shows any GPU a Cycles kernel could use (`/dev/nvidiactl` for CUDA
/// and OptiX, `/dev/kfd` for HIP): `--device auto` asks Blender for its devices only then, so a
/// CPU-only machine pays no extra Blender start.
pub fn gpu_hardware_present() -> bool {
    ["/dev/nvidiactl", "/dev/kfd"]
        .iter()
        .any(|p| std::path::Path::new(p).exists())
}

/// Most workers the default puts on one GPU: the most measured to pay (1, 2 and 4 workers on
/// an H200 made 884, 1,689 and 2,574 `full` images/hour; docs/performance.md, "GPUs").
pub const MAX_DEFAULT_WORKERS_PER_GPU: usize = 4;

/// Most workers per GPU that `--workers` may ask for without a warning. More workers keep a GPU
/// busier while each builds its scene on the CPU, but 8 per GPU has not been measured yet
/// (`scripts/gpu_check.sh`'s sweep measures it): the default stays
/// [`MAX_DEFAULT_WORKERS_PER_GPU`] until it measures faster.
pub const MAX_WORKERS_PER_GPU: usize = 8;

/// Cycles threads per worker when `--threads` is not given: the machine's `cores` shared evenly
/// by the `workers` (at least 1), on GPUs as on the CPU. On a GPU the threads run each worker's
/// host work (scene build, displacement, BVH, the visibility pass), so a worker given all the
/// cores would contend with its neighbours for them.
pub fn default_threads(cores: usize, workers: usize) -> u32 {
    u32::try_from((cores / workers.max(1)).max(1)).unwrap_or(u32::MAX)
}

/// The warning `generate` and `render` print when `workers` put more than
/// [`MAX_WORKERS_PER_GPU`] on one of the GPUs of `placements` (round robin,
/// [`placement_for`]); `None` on the CPU or within the bound.
pub fn workers_per_gpu_warning(placements: &[Placement], workers: usize) -> Option<String> {
    let gpus = placements.iter().filter(|p| p.is_gpu()).count();
    if gpus == 0 {
        return None;
    }
    let most = workers.div_ceil(placements.len());
    (most > MAX_WORKERS_PER_GPU).then(|| {
        format!(
            "warning: {workers} workers put {most} on one GPU; more than {MAX_WORKERS_PER_GPU} per \
             GPU has never been measured to pay, and each worker holds its own scene in the \
             GPU's memory\nhint: compare with `--workers {}` ({MAX_WORKERS_PER_GPU} per GPU) on a \
             few images (`--estimate`)",
            MAX_WORKERS_PER_GPU * placements.len()
        )
    })
}

/// The default number of workers for `placements` on a machine of `cores` cores: on GPUs,
/// one per 4 cores per GPU, at least 1 and at most [`MAX_DEFAULT_WORKERS_PER_GPU`] per GPU;
/// `cpu_default` on the CPU.
///
/// A worker leaves its GPU idle while it builds the scene, renders the visibility pass on the
/// CPU, redraws rejected layouts and writes the files: on an H200 with 16 cores, rendering
/// `full` at 320x240, 64 spp, Cycles' GPU render was 14.8 s of one worker's 60.3 s, and 1, 2
/// and 4 workers on the one GPU made 884, 1689 and 2574 images/hour (docs/performance.md,
/// "GPUs"). Each such worker wants CPU for that serial work, hence the 4 cores per worker.
pub fn default_workers(placements: &[Placement], cpu_default: usize, cores: usize) -> usize {
    let gpus = placements.iter().filter(|p| p.is_gpu()).count();
    if gpus == 0 {
        return cpu_default;
    }
    let per_gpu = (cores / (4 * gpus)).clamp(1, MAX_DEFAULT_WORKERS_PER_GPU);
    placements.len() * per_gpu
}

/// The device of worker `slot`: round robin over `placements`.
pub fn placement_for(placements: &[Placement], slot: usize) -> Placement {
    if placements.is_empty() {
        Placement::cpu()
    } else {
        placements[slot % placements.len()].clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gpu(kind: &str, name: &str) -> Gpu {
        Gpu {
            kind: kind.into(),
            name: name.into(),
            id: String::new(),
        }
    }

    #[test]
    fn auto_prefers_optix_then_cuda_and_falls_back_to_cpu() {
        let two = [
            gpu("CUDA", "A"),
            gpu("CUDA", "B"),
            gpu("OPTIX", "A"),
            gpu("OPTIX", "B"),
        ];
        let p = plan(DeviceChoice::Auto, &two).unwrap();
        assert_eq!(p.len(), 2);
        assert!(p.iter().all(|p| p.kind == "OPTIX"));
        assert_eq!((p[0].index, p[1].index), (0, 1));
        assert_eq!(p[1].arg(), "OPTIX:1");
        let hip = [gpu("HIP", "R")];
        assert_eq!(plan(DeviceChoice::Auto, &hip).unwrap()[0].kind, "HIP");
        assert_eq!(
            plan(DeviceChoice::Auto, &[]).unwrap(),
            vec![Placement::cpu()]
        );
    }

    #[test]
    fn explicit_kinds_pick_their_gpus_or_fail_naming_what_exists() {
        let gpus = [gpu("CUDA", "A"), gpu("OPTIX", "A"), gpu("CUDA", "B")];
        let cuda = plan(DeviceChoice::Cuda, &gpus).unwrap();
        assert_eq!(
            cuda.iter().map(|p| p.name.as_str()).collect::<Vec<_>>(),
            ["A", "B"]
        );
        assert_eq!(
            plan(DeviceChoice::Cpu, &gpus).unwrap(),
            vec![Placement::cpu()]
        );
        let err = plan(DeviceChoice::Hip, &gpus).unwrap_err();
        assert!(
            err.contains("no HIP device") && err.contains("CUDA `A`"),
            "{err}"
        );
        let err = plan(DeviceChoice::Optix, &[]).unwrap_err();
        assert!(err.contains("found: no GPU"), "{err}");
    }

    #[test]
    fn workers_default_to_one_per_4_cores_per_gpu_and_are_spread_round_robin() {
        let gpus = [gpu("CUDA", "A"), gpu("CUDA", "B"), gpu("CUDA", "C")];
        let p = plan(DeviceChoice::Auto, &gpus).unwrap();
        // Few cores: one worker per GPU.
        assert_eq!(default_workers(&p, 2, 2), 3);
        assert_eq!(default_workers(&p, 2, 12), 3);
        // 24 cores over 3 GPUs: 2 per GPU; 96 cores: capped at 4 per GPU.
        assert_eq!(default_workers(&p, 2, 24), 6);
        assert_eq!(default_workers(&p, 2, 96), 12);
        let one = plan(DeviceChoice::Cuda, &gpus[..1]).unwrap();
        assert_eq!(default_workers(&one, 2, 16), 4);
        assert_eq!(default_workers(&[Placement::cpu()], 2, 16), 2);
        // Six workers over three GPUs: two on each.
        let mut on = [0; 3];
        for slot in 0..6 {
            on[placement_for(&p, slot).index] += 1;
        }
        assert_eq!(on, [2, 2, 2]);
        assert_eq!(placement_for(&p, 4).index, 1);
        assert_eq!(placement_for(&[], 4), Placement::cpu());
    }

    #[test]
    fn gpu_workers_share_the_cores_as_threads_and_up_to_8_per_gpu_pass_quietly() {
        let one = plan(DeviceChoice::Cuda, &[gpu("CUDA", "H200")]).unwrap();
        // 16 cores, one GPU: the default 4 workers get 4 threads each; 8 workers get 2.
        let w = default_workers(&one, 2, 16);
        assert_eq!((w, default_threads(16, w)), (4, 4));
        assert_eq!(default_threads(16, 8), 2);
        // Never 0 threads, however many workers; the CPU splits the cores the same way.
        assert_eq!(default_threads(2, 4), 1);
        assert_eq!(default_threads(0, 0), 1);
        assert_eq!(default_threads(16, 2), 8);
        // Up to 8 per GPU: no warning; 9 on one GPU (of 17 over two): a warning naming 8.
        assert_eq!(workers_per_gpu_warning(&one, 8), None);
        let w = workers_per_gpu_warning(&one, 9).unwrap();
        assert!(
            w.contains("9 workers put 9 on one GPU") && w.contains("--workers 8"),
            "{w}"
        );
        let two = plan(DeviceChoice::Cuda, &[gpu("CUDA", "A"), gpu("CUDA", "B")]).unwrap();
        assert_eq!(workers_per_gpu_warning(&two, 16), None);
        let w = workers_per_gpu_warning(&two, 17).unwrap();
        assert!(
            w.contains("put 9 on one GPU") && w.contains("--workers 16"),
            "{w}"
        );
        // The CPU has no such bound.
        assert_eq!(workers_per_gpu_warning(&[Placement::cpu()], 64), None);
        // The default never exceeds the measured 4 per GPU, even with many cores.
        assert_eq!(default_workers(&one, 2, 256), MAX_DEFAULT_WORKERS_PER_GPU);
        const { assert!(MAX_DEFAULT_WORKERS_PER_GPU <= MAX_WORKERS_PER_GPU) };
    }

    #[test]
    fn choices_parse_case_insensitively() {
        assert_eq!(DeviceChoice::parse("OptiX"), Some(DeviceChoice::Optix));
        assert_eq!(DeviceChoice::parse("metal"), None);
        assert_eq!(DeviceChoice::Hip.name(), "hip");
    }

    /// bpy 4.5's kernels (`compat.cuda_kernels()` there): cubins up to sm_89 and sm_120, PTX
    /// compute_75.
    fn bpy45() -> CudaKernels {
        CudaKernels {
            cubin: vec![30, 35, 37, 50, 52, 60, 61, 70, 75, 86, 89, 120],
            ptx: vec![75],
            prepared: vec![],
        }
    }

    #[test]
    fn cycles_compiles_ptx_only_where_no_cubin_matches_exactly() {
        let k = bpy45();
        assert_eq!(k.load_for(89), KernelLoad::Shipped);
        assert_eq!(k.load_for(120), KernelLoad::Shipped);
        // An A100 (8.0) and an H100 (9.0): no cubin of their own, the sm_75 one does not run.
        assert_eq!(k.load_for(80), KernelLoad::Compiled { from: 75 });
        assert_eq!(k.load_for(90), KernelLoad::Compiled { from: 75 });
        // Older than every PTX, and a build with no kernels (Debian's Blender).
        assert_eq!(k.load_for(72), KernelLoad::Missing);
        assert_eq!(CudaKernels::default().load_for(90), KernelLoad::Missing);
        // The newest PTX not newer than the GPU.
        let two = CudaKernels {
            cubin: vec![],
            ptx: vec![52, 75, 100],
            prepared: vec![],
        };
        assert_eq!(two.load_for(90), KernelLoad::Compiled { from: 75 });
        assert_eq!(two.load_for(60), KernelLoad::Compiled { from: 52 });
        // After `scripts/cuda_kernels.py --cuda-arch 90`: a cubin of its own, marked prepared.
        let mut k = bpy45();
        k.cubin.push(90);
        k.prepared.push(90);
        assert_eq!(k.load_for(90), KernelLoad::Prepared);
        assert_eq!(k.load_for(89), KernelLoad::Shipped);
        assert_eq!(k.load_for(80), KernelLoad::Compiled { from: 75 });
        assert!(
            k.describe()
                .contains("sm_120, sm_90 (sm_90 prepared); PTX compute_75"),
            "{}",
            k.describe()
        );
    }

    #[test]
    fn compute_capabilities_parse_from_nvidia_smi() {
        let out = "NVIDIA H100 80GB HBM3, 9.0\nNVIDIA A100-SXM4-40GB, 8.0\nNVIDIA GeForce RTX 5090, 12.0\n[N/A]\nodd, 9\nbad, x.y\n";
        assert_eq!(
            parse_compute_capabilities(out),
            vec![
                ("NVIDIA H100 80GB HBM3".to_string(), 90),
                ("NVIDIA A100-SXM4-40GB".to_string(), 80),
                ("NVIDIA GeForce RTX 5090".to_string(), 120),
            ]
        );
    }

    #[test]
    fn gpus_without_a_ready_made_kernel_are_marked_and_warned_about() {
        let gpus = [
            gpu("OPTIX", "NVIDIA H100 80GB HBM3"),
            gpu("OPTIX", "NVIDIA RTX 4090"),
        ];
        let caps = vec![
            ("NVIDIA H100 80GB HBM3".to_string(), 90),
            ("NVIDIA RTX 4090".to_string(), 89),
        ];
        let mut p = plan(DeviceChoice::Optix, &gpus).unwrap();
        mark_kernel_compiles(&mut p, &bpy45(), &caps);
        let note = p[0].compiles_kernel.as_deref().unwrap();
        assert!(
            note.contains("compute capability 9.0") && note.contains("compute_75"),
            "{note}"
        );
        assert_eq!(p[1].compiles_kernel, None);
        let w = kernel_compile_warning(&p).unwrap();
        assert!(
            w.contains("NVIDIA H100 80GB HBM3") && w.contains("CUDA_CACHE_MAXSIZE"),
            "{w}"
        );
        assert!(w.contains("--device optix") && w.contains("60 min"), "{w}");
        assert!(
            w.contains("`./scripts/setup.sh --bpy 4.5 --cuda-arch 90`"),
            "{w}"
        );
        assert_eq!(kernel_compile_warning(&p[1..]), None);
        // Unknown capability (no nvidia-smi): nothing is assumed.
        let mut q = plan(DeviceChoice::Optix, &gpus).unwrap();
        mark_kernel_compiles(&mut q, &bpy45(), &[]);
        assert!(q.iter().all(|p| p.compiles_kernel.is_none()));
        assert_eq!(kernel_compile_warning(&[Placement::cpu()]), None);
    }
}
