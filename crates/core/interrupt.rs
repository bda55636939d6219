//! Ctrl-C, the one place the process's interrupt handling is installed.
//!
//! A command asks for the shared interrupt flag with [`flag`], saying what an interrupt means
//! to it ([`OnInterrupt`]); the handler is installed on the first call only and every call
//! hands out the same `Arc<AtomicBool>`, which the command gives to the render crate
//! (`WorkerOptions::interrupt`, `PoolOptions::interrupt`) or checks itself. The handler only
//! calls [`on_signal`]: another signal (e.g. SIGTERM) is added here by routing it there too,
//! and no command changes.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use crate::exit;

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
}

struct Handler {
    flag: Arc<AtomicBool>,
    on_interrupt: Mutex<OnInterrupt>,
}

static HANDLER: OnceLock<Handler> = OnceLock::new();

/// The process's interrupt flag, installing the Ctrl-C handler on the first call; `on` is
/// what an interrupt does from now on.
pub fn flag(on: OnInterrupt) -> Arc<AtomicBool> {
    let handler = HANDLER.get_or_init(|| {
        // Failing to install the handler (e.g. one is already set) only loses clean Ctrl-C.
        let _ = ctrlc::set_handler(on_signal);
        Handler {
            flag: Arc::new(AtomicBool::new(false)),
            on_interrupt: Mutex::new(on),
        }
    });
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
        OnInterrupt::Stop { message } => {
            if handler.flag.swap(true, Ordering::SeqCst) {
                std::process::exit(i32::from(exit::INTERRUPTED));
            }
            eprintln!("\ninterrupt: {message} (Ctrl-C again to quit at once)");
        }
    }
}
