//! Ctrl-C and SIGTERM, the one place the process's interrupt handling is installed.
//!
//! A command asks for the shared interrupt flag with [`flag`], saying what an interrupt means
//! to it ([`OnInterrupt`]); the handler is installed on the first call only and every call
//! hands out the same `Arc<AtomicBool>`, which the command gives to the render crate
//! (`WorkerOptions::interrupt`, `PoolOptions::interrupt`) or checks itself. SIGINT (Ctrl-C)
//! and SIGTERM (what `timeout`, SLURM at a time limit or preemption, and Kubernetes send) are
//! handled alike: workers stopped, finished outputs kept, no partial output. The exit code
//! says which came: 130 for SIGINT, 143 for SIGTERM ([`exit_code`]). Signals are received on
//! a thread of signal-hook's (no code of ours runs in a signal handler).

use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};

use signal_hook::consts::{SIGINT, SIGTERM};
use std::sync::{Arc, Mutex, OnceLock};

/// Exit code after Ctrl-C (128 + SIGINT).
pub const INTERRUPTED: u8 = 130;
/// Exit code after SIGTERM (128 + SIGTERM): a scheduler's time limit or preemption, `timeout`.
pub const TERMINATED: u8 = 143;

/// What an interrupt does in the running command.
#[derive(Debug, Clone, Copy)]
pub enum OnInterrupt {
    /// Set the flag and print `interrupt: <message> (Ctrl-C again to quit at once)`; a
    /// second interrupt exits with code 130 at once.
    Stop {
        /// What the command does now, e.g. "stopping Blender".
        message: &'static str,
    },
    /// Only set the flag: the command checks it between short steps, so stopping is quick
    /// and a second interrupt does nothing more.
    FlagOnly,
    /// Exit at once with 130 or 143: what a signal does before a command has said what it
    /// means to it (the handler is installed first thing, by [`install_early`]), and in
    /// commands that write nothing that a stop could leave half-done.
    Exit,
}

struct Handler {
    flag: Arc<AtomicBool>,
    on_interrupt: Mutex<OnInterrupt>,
}

static HANDLER: OnceLock<Handler> = OnceLock::new();
/// The last signal received (0: none yet).
static LAST_SIGNAL: AtomicI32 = AtomicI32::new(0);

/// The exit code of an interrupted run: 143 (128 + SIGTERM) after SIGTERM, else 130
/// (128 + SIGINT).
pub fn exit_code() -> u8 {
    if LAST_SIGNAL.load(Ordering::SeqCst) == SIGTERM {
        TERMINATED
    } else {
        INTERRUPTED
    }
}

/// Receive SIGINT and SIGTERM on a thread and pass them to [`on_signal`].
fn install() {
    // Failing to install (e.g. no threads left) only loses the clean stop on a signal.
    if let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM]) {
        let _ = std::thread::Builder::new()
            .name("signals".into())
            .spawn(move || {
                for sig in signals.forever() {
                    LAST_SIGNAL.store(sig, Ordering::SeqCst);
                    on_signal();
                }
            });
    }
}

/// Install the handler before anything else runs, so that a signal in the first moments
/// of a run exits with 130 / 143 (as [`OnInterrupt::Exit`]) instead of the default action's
/// death or, once a command is under way, a plain error.
pub fn install_early() {
    handler(OnInterrupt::Exit);
}

/// Whether SIGINT or SIGTERM has been received.
pub fn received() -> bool {
    LAST_SIGNAL.load(Ordering::SeqCst) != 0
}

fn handler(first: OnInterrupt) -> &'static Handler {
    HANDLER.get_or_init(|| {
        install();
        Handler {
            flag: Arc::new(AtomicBool::new(false)),
            on_interrupt: Mutex::new(first),
        }
    })
}

/// The process's interrupt flag, installing the Ctrl-C handler on the first call; `on` is
/// what an interrupt does from now on.
pub fn flag(on: OnInterrupt) -> Arc<AtomicBool> {
    let handler = handler(on);
    *handler
        .on_interrupt
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner()) = on;
    Arc::clone(&handler.flag)
}

/// What every handled signal does: set the flag and act as [`OnInterrupt`] says.
fn on_signal() {
    let Some(handler) = HANDLER.get() else {
        return;
    };
    let on = *handler
        .on_interrupt
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    match on {
        OnInterrupt::FlagOnly => handler.flag.store(true, Ordering::SeqCst),
        OnInterrupt::Exit => {
            handler.flag.store(true, Ordering::SeqCst);
            let what = if LAST_SIGNAL.load(Ordering::SeqCst) == SIGTERM {
                "terminated (SIGTERM)"
            } else {
                "interrupted"
            };
            // A probe of Blender's version may be running: it is killed, not orphaned.
            clevrtex_render::group::kill_tracked();
            eprintln!("\n{what}: nothing was under way; exiting");
            std::process::exit(i32::from(exit_code()));
        }
        OnInterrupt::Stop { message } => {
            if handler.flag.swap(true, Ordering::SeqCst) {
                clevrtex_render::group::kill_tracked();
                std::process::exit(i32::from(exit_code()));
            }
            let what = if LAST_SIGNAL.load(Ordering::SeqCst) == SIGTERM {
                "terminate (SIGTERM)"
            } else {
                "interrupt"
            };
            eprintln!("\n{what}: {message} (Ctrl-C again to quit at once)");
        }
    }
}
