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
/// start means the CPU (the pool then reports the start failure itself).
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
    let bridge = crate::BridgeDir::create(materials_json)?;
    let started = Worker::start(
        &WorkerOptions::new(blender.to_path_buf(), &bridge, Arc::clone(interrupt))
            .with_threads(1)
            .with_startup_timeout(startup_timeout),
    );
    let gpus = match started {
        Ok(worker) => {
            let gpus = worker.ready().gpus.clone();
            worker.quit();
            gpus
        }
        Err(_) if choice == DeviceChoice::Auto => return Ok(vec![Placement::cpu()]),
        Err(e) => return Err(e),
    };
    device::plan(choice, &gpus).map_err(RenderError::DevicePlan)
}
