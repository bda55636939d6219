//! The devices a run's workers are spread over: for a GPU choice, a first worker is asked
//! which GPUs Cycles sees and [`device::plan`] chooses (its own module because it starts a
//! [`Worker`], which needs [`device`]: this keeps `device` below `worker`).

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use crate::device::{self, DeviceChoice, Placement};
use crate::error::{RenderError, Result};
use crate::worker::{Worker, WorkerOptions};

/// The devices for `choice`: the CPU for `cpu`, and for `auto` on a machine without GPU
/// device files; otherwise a first worker of `blender` (with `materials_json`, one thread,
/// `startup_timeout`) is asked which GPUs Cycles sees. For `auto`, a worker that does not
/// start means the CPU (the pool then reports the start failure itself). A GPU for which the
/// Blender ships no ready-made CUDA kernel is marked ([`device::mark_kernel_compiles`]).
pub fn plan_devices(
    choice: DeviceChoice,
    blender: &Path,
    materials_json: &str,
    startup_timeout: Duration,
    interrupt: &Arc<AtomicBool>,
) -> Result<Vec<Placement>> {
    if choice == DeviceChoice::Cpu
        || (choice == DeviceChoice::Auto && !device::gpu_hardware_present())
    {
        return Ok(vec![Placement::cpu()]);
    }
    let bridge = crate::bridge::BridgeDir::create(materials_json)?;
    let started = Worker::start(
        &WorkerOptions::new(blender.to_path_buf(), &bridge, Arc::clone(interrupt))
            .with_threads(1)
            .with_startup_timeout(startup_timeout),
    );
    let (gpus, kernels) = match started {
        Ok(worker) => {
            let ready = worker.ready();
            let found = (ready.gpus.clone(), ready.cuda_kernels.clone());
            worker.quit();
            found
        }
        Err(_) if choice == DeviceChoice::Auto => return Ok(vec![Placement::cpu()]),
        Err(e) => return Err(e),
    };
    let mut placements = device::plan(choice, &gpus).map_err(RenderError::DevicePlan)?;
    if placements.iter().any(Placement::is_gpu) {
        let caps = device::nvidia_compute_capabilities();
        device::mark_kernel_compiles(&mut placements, &kernels, &caps);
    }
    Ok(placements)
}
