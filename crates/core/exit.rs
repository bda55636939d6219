//! Exit codes and error reporting, in one place.
//!
//! | code | meaning |
//! |------|---------|
//! | 0    | success |
//! | 1    | error (bad input, failed render, I/O); the message says what and what to do |
//! | 2    | usage error: the command line could not be parsed (unknown flag, missing or malformed argument) |
//! | 3    | finished, but some items failed (see the ledger / report) |
//! | 130  | interrupted by Ctrl-C; finished outputs are kept, no partial output is left |
//! | 143  | stopped by SIGTERM (scheduler time limit, preemption, `timeout`): as 130 |

/// Success.
pub const OK: u8 = 0;
/// Any error.
pub const ERROR: u8 = 1;
/// Bad command-line usage.
pub const USAGE: u8 = 2;
/// The run finished but some items failed.
pub const PARTIAL: u8 = 3;
// 130 and 143 belong to the signal handling: `interrupt::INTERRUPTED`, `interrupt::TERMINATED`
// (so that `interrupt` needs nothing from here and this file reads top-down).

/// Shown at the end of `--help`.
pub const EXIT_CODES_HELP: &str = "Exit codes: 0 ok, 1 error, 2 usage error, 3 finished with some failed items, 130 interrupted (Ctrl-C), 143 stopped by SIGTERM";

/// What a subcommand returns: `Ok(code)` for a finished run (0 or [`PARTIAL`]).
pub type CmdResult = anyhow::Result<u8>;

/// Marker error: the user pressed Ctrl-C. Maps to exit code 130.
#[derive(Debug)]
pub struct Interrupted;

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("interrupted; finished outputs were kept and no partial output was left")
    }
}

impl std::error::Error for Interrupted {}

/// Print an error (with its chain of causes) to stderr and pick the exit code.
pub fn report(result: CmdResult) -> u8 {
    match result {
        Ok(code) => code,
        Err(err) => {
            // A message may quote any file's text (a manifest, a scene file, a lock): its
            // control and bidirectional characters escaped, whatever the command forgot.
            let text = format!("{err:#}");
            eprintln!("error: {}", clevrtex_scene::text::printable_lines(&text));
            // A command that stopped because of a signal, whatever error the stop surfaced
            // as (a worker's start cut short, a render's `interrupted`), exits with the
            // signal's code, not 1.
            if err.downcast_ref::<Interrupted>().is_some() || crate::interrupt::received() {
                crate::interrupt::exit_code()
            } else {
                ERROR
            }
        }
    }
}

/// A render error as the command's error: an interrupt becomes [`Interrupted`] (exit code
/// 130), anything else keeps its message and hint.
pub fn command_error(err: clevrtex_render::RenderError) -> anyhow::Error {
    match err {
        clevrtex_render::RenderError::Interrupted => anyhow::Error::new(Interrupted),
        e => e.into(),
    }
}

/// [`command_error`] for an error that may hold a render error (a library's `anyhow` error).
pub fn command_error_any(err: anyhow::Error) -> anyhow::Error {
    match err.downcast::<clevrtex_render::RenderError>() {
        Ok(e) => command_error(e),
        Err(e) => e,
    }
}
