//! Blender processes run in their own process group, and are killed as a group: a Blender
//! behind a wrapper script (`module load blender; blender "$@"`, no `exec`) is a grandchild of
//! ours, and killing only the direct child would leave it rendering.

use std::process::{Child, Command};
use std::sync::Mutex;

/// Groups started with [`track`] and not yet killed by [`kill_group`]: what [`kill_tracked`]
/// kills when the process exits at once on a signal.
static TRACKED: Mutex<Vec<u32>> = Mutex::new(Vec::new());

/// Start `cmd` as the leader of a new process group (whose id is then its pid). Also keeps a
/// Ctrl-C in the terminal from reaching Blender: we stop the workers ourselves, so no
/// half-written output is left behind.
pub fn own_group(cmd: &mut Command) {
    std::os::unix::process::CommandExt::process_group(cmd, 0);
}

/// What the spawning thread is sent: a command, and where its child goes.
type SpawnRequest = (Command, std::sync::mpsc::Sender<std::io::Result<Child>>);

/// Start `cmd` from one thread that lives as long as this process. The bridge asks the kernel
/// to kill Blender when its parent dies (`PR_SET_PDEATHSIG`, worker.py), and Linux counts the
/// *thread* that started a process as its parent: a worker started by a pool's thread was
/// killed when that thread ended, so a worker could not outlive the run that started it
/// (`crate::kept`: a suite's variants share their workers). Falls back to starting `cmd`
/// here when that thread cannot be made.
pub fn spawn_lasting(cmd: Command) -> std::io::Result<Child> {
    static SPAWNER: std::sync::OnceLock<Option<Mutex<std::sync::mpsc::Sender<SpawnRequest>>>> =
        std::sync::OnceLock::new();
    let spawner = SPAWNER.get_or_init(|| {
        let (tx, rx) = std::sync::mpsc::channel::<SpawnRequest>();
        std::thread::Builder::new()
            .name("clevrtex-spawner".into())
            .spawn(move || {
                for (mut cmd, back) in rx {
                    let _ = back.send(cmd.spawn());
                }
            })
            .ok()
            .map(|_| Mutex::new(tx))
    });
    let mut cmd = cmd;
    if let Some(tx) = spawner {
        let (back, child) = std::sync::mpsc::channel();
        let sent = tx
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .send((cmd, back));
        match sent {
            Ok(()) => {
                if let Ok(result) = child.recv() {
                    return result;
                }
                return Err(std::io::Error::other("the spawning thread ended"));
            }
            Err(std::sync::mpsc::SendError((c, _))) => cmd = c,
        }
    }
    cmd.spawn()
}

/// SIGKILL the process group that `child` leads (see [`own_group`]), then reap `child`.
///
/// The group is signalled before `child` is reaped, so its id cannot have been reused; a
/// group whose leader already exited (a wrapper that left its Blender running) is still
/// signalled, since a group's id is not reused while any member lives.
pub fn kill_group(child: &mut Child) {
    TRACKED
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .retain(|&id| id != child.id());
    if let Some(pgid) = i32::try_from(child.id())
        .ok()
        .and_then(rustix::process::Pid::from_raw)
    {
        let _ = rustix::process::kill_process_group(pgid, rustix::process::Signal::KILL);
    }
    let _ = child.kill();
    let _ = child.wait();
}

/// Note that `child` (a group leader, [`own_group`]) is to be killed by [`kill_tracked`] if
/// the process exits before [`kill_group`] kills it. Only for children that always end in
/// [`kill_group`] (a group id is reused once its members are gone).
pub fn track(child: &Child) {
    TRACKED
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .push(child.id());
}

/// SIGKILL every group [`track`]ed and not yet killed: for a process about to exit at once
/// (a signal before a command has said what it means to it), which would leave them running.
pub fn kill_tracked() {
    let ids = std::mem::take(&mut *TRACKED.lock().unwrap_or_else(|p| p.into_inner()));
    for id in ids {
        if let Some(pgid) = i32::try_from(id)
            .ok()
            .and_then(rustix::process::Pid::from_raw)
        {
            let _ = rustix::process::kill_process_group(pgid, rustix::process::Signal::KILL);
        }
    }
}
