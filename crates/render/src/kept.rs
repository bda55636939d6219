//! Blender workers kept between the pool runs of one command ([`KeptWorkers`]): `generate
//! --suite` runs each variant as its own pool run (its own manifest, lock and ledger), and
//! without this each run started its workers again (~12 s of a 2-core machine per Blender 3.4
//! start).
//!
//! A worker fixes at start only its Blender, the bridge and its catalogue (`materials.json`),
//! its Cycles threads and its device (`worker.py`'s command line); everything else (the
//! scene, size, samples, passes, materials drawn) comes with each request. So a run takes a
//! kept worker started with exactly its own start-up options ([`WorkerOptions::starts_like`])
//! and hands its live workers back when it ends; a worker of another catalogue (e.g. another
//! variant's user-material copies), thread count or device is closed, never reused.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use crate::bridge::BridgeDir;
use crate::device::{DeviceChoice, Placement};
use crate::error::Result;
use crate::session::Session;
use crate::worker::WorkerOptions;

/// A kept session with the images its worker has made (for `--recycle-after`).
type KeptSession = (Session, (u32, u64));

/// Workers (and the bridge folder they run from) kept between the pool runs of one command.
/// Dropping it ends the kept workers (killed after an interrupt, else asked to quit).
#[derive(Debug, Default)]
pub struct KeptWorkers {
    inner: Mutex<Inner>,
}

#[derive(Debug, Default)]
struct Inner {
    /// The bridge folder of the kept workers, with the catalogue written into it.
    bridge: Option<(String, Arc<BridgeDir>)>,
    /// The device plan of a `--device` and Blender (a GPU probe starts a Blender).
    devices: Option<(DeviceChoice, PathBuf, Vec<Placement>)>,
    /// Live sessions handed back by the last run.
    sessions: Vec<KeptSession>,
    /// Workers taken by a run instead of starting one.
    reused: u64,
}

impl KeptWorkers {
    /// No workers kept yet.
    pub fn new() -> KeptWorkers {
        KeptWorkers::default()
    }

    fn inner(&self) -> std::sync::MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The bridge folder for a run with catalogue `materials_json`: the kept one when its
    /// catalogue is the same, else a fresh one (and the kept workers, which read the other
    /// catalogue, are closed).
    pub fn bridge(&self, materials_json: &str) -> Result<Arc<BridgeDir>> {
        let mut inner = self.inner();
        if let Some((json, dir)) = &inner.bridge {
            if json == materials_json {
                return Ok(Arc::clone(dir));
            }
        }
        for (mut s, _) in inner.sessions.drain(..) {
            s.close();
        }
        let dir = Arc::new(BridgeDir::create(materials_json)?);
        inner.bridge = Some((materials_json.to_string(), Arc::clone(&dir)));
        Ok(dir)
    }

    /// The device plan kept for `choice` and `blender`, or `plan()`'s, kept.
    pub fn devices(
        &self,
        choice: DeviceChoice,
        blender: &std::path::Path,
        plan: impl FnOnce() -> Result<Vec<Placement>>,
    ) -> Result<Vec<Placement>> {
        if let Some((c, b, d)) = &self.inner().devices {
            if *c == choice && b == blender {
                return Ok(d.clone());
            }
        }
        let devices = plan()?;
        self.inner().devices = Some((choice, blender.to_path_buf(), devices.clone()));
        Ok(devices)
    }

    /// A kept session whose worker was started with `options` (see
    /// [`WorkerOptions::starts_like`]), with the images its worker has made; `None` when
    /// there is none.
    pub fn take(&self, options: &WorkerOptions) -> Option<KeptSession> {
        let mut inner = self.inner();
        let i = inner
            .sessions
            .iter()
            .position(|(s, _)| s.current().is_some() && s.options().starts_like(options))?;
        inner.reused += 1;
        Some(inner.sessions.swap_remove(i))
    }

    /// Keep `session` (with the images its worker made) for the next run; a session without
    /// a live worker is closed instead.
    pub fn put(&self, mut session: Session, images: (u32, u64)) {
        if session.current().is_some() {
            self.inner().sessions.push((session, images));
        } else {
            session.close();
        }
    }

    /// Workers kept now.
    pub fn len(&self) -> usize {
        self.inner().sessions.len()
    }

    /// Whether no worker is kept now.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Workers runs took from here instead of starting one, so far.
    pub fn reused(&self) -> u64 {
        self.inner().reused
    }

    /// End every kept worker (asked to quit; killed after an interrupt).
    pub fn close(&self) {
        let sessions: Vec<_> = self.inner().sessions.drain(..).collect();
        for (mut s, _) in sessions {
            s.close();
        }
    }
}

impl Drop for KeptWorkers {
    fn drop(&mut self) {
        self.close();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicBool;
    use std::time::Duration;

    /// A kept worker serves only a run whose workers would start alike: another thread count,
    /// device, catalogue, Blender or interrupt flag is another worker.
    #[test]
    fn only_a_worker_started_alike_is_taken() {
        let keep = KeptWorkers::new();
        let bridge = keep.bridge("{\"materials\":{}}").unwrap();
        // The same catalogue: the same bridge folder; another: a fresh one.
        assert!(Arc::ptr_eq(
            &bridge,
            &keep.bridge("{\"materials\":{}}").unwrap()
        ));
        let other_bridge = BridgeDir::create("{\"materials\":{\"x\":{}}}").unwrap();
        let flag = Arc::new(AtomicBool::new(false));
        let base = WorkerOptions::new("/usr/bin/blender".into(), &bridge, Arc::clone(&flag))
            .with_threads(1);
        assert!(base.starts_like(&base.clone().with_startup_timeout(Duration::from_secs(1))));
        let gpu = Placement {
            kind: "CUDA".into(),
            index: 0,
            name: "gpu".into(),
            compiles_kernel: None,
        };
        for other in [
            base.clone().with_threads(2),
            base.clone().with_device(gpu),
            WorkerOptions::new("/usr/bin/blender".into(), &other_bridge, Arc::clone(&flag))
                .with_threads(1),
            WorkerOptions::new("/opt/blender".into(), &bridge, Arc::clone(&flag)).with_threads(1),
            WorkerOptions::new("/usr/bin/blender".into(), &bridge, Arc::default()).with_threads(1),
        ] {
            assert!(!base.starts_like(&other), "{other:?}");
        }
        // Nothing kept: nothing taken, nothing counted.
        assert!(keep.take(&base).is_none());
        assert!(keep.is_empty());
        assert_eq!(keep.reused(), 0);
    }
}
