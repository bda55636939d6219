//! Which Cycles device each worker renders on (`--device auto|cpu|cuda|optix|hip`).
//!
//! The choice is made from the GPUs a first worker reports in its `ready` message
//! ([`crate::Ready::gpus`]): with N GPUs of the chosen kind, worker `i` is pinned to GPU
//! `i % N` by its index within that kind (the bridge enables exactly that one device), so a
//! machine with N GPUs runs N workers, one per GPU, with no `CUDA_VISIBLE_DEVICES` juggling.

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
}

impl Placement {
    /// The CPU.
    pub fn cpu() -> Placement {
        Placement {
            kind: "CPU".into(),
            index: 0,
            name: String::new(),
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

/// The default number of workers for `placements`: one per GPU, or `cpu_default` on the CPU.
pub fn default_workers(placements: &[Placement], cpu_default: usize) -> usize {
    if placements.iter().any(Placement::is_gpu) {
        placements.len()
    } else {
        cpu_default
    }
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
    fn workers_default_to_the_gpu_count_and_are_spread_round_robin() {
        let gpus = [gpu("CUDA", "A"), gpu("CUDA", "B"), gpu("CUDA", "C")];
        let p = plan(DeviceChoice::Auto, &gpus).unwrap();
        assert_eq!(default_workers(&p, 2), 3);
        assert_eq!(default_workers(&[Placement::cpu()], 2), 2);
        assert_eq!(placement_for(&p, 4).index, 1);
        assert_eq!(placement_for(&[], 4), Placement::cpu());
    }

    #[test]
    fn choices_parse_case_insensitively() {
        assert_eq!(DeviceChoice::parse("OptiX"), Some(DeviceChoice::Optix));
        assert_eq!(DeviceChoice::parse("metal"), None);
        assert_eq!(DeviceChoice::Hip.name(), "hip");
    }
}
