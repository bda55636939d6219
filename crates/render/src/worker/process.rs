//! A worker's Blender process and its life: started in its own process group with a private
//! `TMPDIR`, its stdout and stderr read by two threads (so Blender can never block on a full
//! pipe), every wait bounded by a deadline, an idle limit and the interrupt flag, and killed
//! and reaped on expiry, on garbage and when dropped.
//!
//! Only stdout lines starting with the worker's tag are replies; every other line is
//! Blender's chatter, kept as a tail for error reports ([`OutputTails`]).

use std::io::{BufRead, BufReader, Read, Write};
use std::path::PathBuf;
use std::process::{Child, ChildStdin, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use super::report::OutputTails;
use super::WorkerOptions;
use crate::error::{RenderError, Result, Tails};

/// Longest line of Blender's output that is kept (protocol replies are a few KB).
const MAX_LINE: usize = 1 << 20;
/// Reply lines waiting to be read: a worker that floods the reply stream blocks on its pipe
/// instead of filling our memory.
const MAX_PENDING_REPLIES: usize = 64;
/// How often a wait re-checks the child's status and the interrupt flag.
const POLL: Duration = Duration::from_millis(50);
/// After stdout closes, how long to wait for the exit status before killing.
const EXIT_GRACE: Duration = Duration::from_secs(3);

enum Event {
    Reply(String),
    Eof,
}

impl std::fmt::Debug for Event {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Event::Reply(r) => write!(f, "Reply({r})"),
            Event::Eof => f.write_str("Eof"),
        }
    }
}

/// A running Blender process with the bridge. Dropping it kills the process.
#[derive(Debug)]
pub(super) struct Process {
    program: PathBuf,
    child: Child,
    stdin: Option<ChildStdin>,
    events: Receiver<Event>,
    tails: Arc<Mutex<OutputTails>>,
    interrupt: Arc<AtomicBool>,
    dead: bool,
    streams_closed: Arc<AtomicBool>,
    /// Milliseconds after `epoch` of the last line Blender printed (on either stream).
    activity: Arc<AtomicU64>,
    epoch: Instant,
    idle_timeout: Option<Duration>,
    /// Blender's `TMPDIR`: removed when the process is dropped, after `Drop` killed Blender.
    _tmp: tempfile::TempDir,
}

impl Process {
    /// Start Blender as `opts` say, with the bridge's arguments `bridge_args`, replies marked
    /// by `tag`.
    pub(super) fn spawn(
        opts: &WorkerOptions,
        tag: &str,
        bridge_args: &[std::ffi::OsString],
    ) -> Result<Process> {
        let flavour = crate::blender::flavour(&opts.blender);
        let mut cmd =
            crate::blender::worker_command(&opts.blender, flavour, &opts.script, bridge_args);
        cmd.stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        // Blender's own temporary files (`blender_*` folders, left behind whenever a worker is
        // killed) go into a private folder removed with the worker, or by the next run if we
        // are killed ourselves.
        let tmp = crate::tmp::private_dir("clevrtex-blender-")?;
        cmd.env("TMPDIR", tmp.path());
        // The bridge asks the kernel to kill it when we die, even by SIGKILL, and checks that
        // we are still its parent (see worker.py).
        cmd.env("CLEVRTEX_PARENT_PID", std::process::id().to_string());
        // On a GPU, let the driver keep a compiled Cycles kernel (up to CUDA's 4 GiB maximum;
        // its default is smaller than the kernel), so only a machine's first run compiles it
        // (`device::kernel_compile_warning`). A value the user set wins.
        if opts.device.is_gpu() && std::env::var_os("CUDA_CACHE_MAXSIZE").is_none() {
            cmd.env("CUDA_CACHE_MAXSIZE", "4294967296");
        }
        // Own process group: a Ctrl-C in the terminal reaches only us, and a kill reaches a
        // wrapper script's Blender too (`group`).
        crate::group::own_group(&mut cmd);
        // From a thread that outlives the pool's (a worker may serve a later run).
        let mut child = crate::group::spawn_lasting(cmd).map_err(|source| {
            if source.kind() == std::io::ErrorKind::NotFound {
                RenderError::BlenderNotFound {
                    tried: Some(opts.blender.clone()),
                }
            } else {
                RenderError::Spawn {
                    program: opts.blender.clone(),
                    cause: source,
                }
            }
        })?;
        let tails = Arc::new(Mutex::new(OutputTails::default()));
        let epoch = Instant::now();
        let activity = Arc::new(AtomicU64::new(0));
        let touch = {
            let activity = Arc::clone(&activity);
            move || activity.store(epoch.elapsed().as_millis() as u64, Ordering::Relaxed)
        };
        let (tx, events) = mpsc::sync_channel(MAX_PENDING_REPLIES);
        let stdout = child.stdout.take().expect("piped");
        let stderr = child.stderr.take().expect("piped");
        {
            let tails = Arc::clone(&tails);
            let prefix = format!("{tag} ");
            let touch = touch.clone();
            std::thread::spawn(move || {
                read_lines(stdout, |line| {
                    touch();
                    if let Some(rest) = line.strip_prefix(&prefix) {
                        let _ = tx.send(Event::Reply(rest.to_string()));
                    } else if line.starts_with(prefix.trim_end()) {
                        let _ = tx.send(Event::Reply(String::new()));
                    } else {
                        tails.lock().unwrap().push_stdout(line);
                    }
                });
                let _ = tx.send(Event::Eof);
            });
        }
        let streams_closed = Arc::new(AtomicBool::new(false));
        {
            let tails = Arc::clone(&tails);
            let closed = Arc::clone(&streams_closed);
            std::thread::spawn(move || {
                read_lines(stderr, |line| {
                    touch();
                    tails.lock().unwrap().push_stderr(line)
                });
                closed.store(true, Ordering::SeqCst);
            });
        }
        let stdin = child.stdin.take();
        Ok(Process {
            program: opts.blender.clone(),
            child,
            stdin,
            events,
            tails,
            interrupt: Arc::clone(&opts.interrupt),
            dead: false,
            streams_closed,
            activity,
            epoch,
            idle_timeout: None,
            _tmp: tmp,
        })
    }

    /// See [`super::Worker::set_idle_timeout`].
    pub(super) fn set_idle_timeout(&mut self, idle: Option<Duration>) {
        self.idle_timeout = idle;
    }

    /// Whether the process died (crash, timeout, protocol error) or was killed.
    pub(super) fn is_dead(&self) -> bool {
        self.dead
    }

    /// The Blender process's id.
    pub(super) fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Current output tails. After the process died, waits briefly for its last stderr
    /// lines (the reader thread may still be draining the pipe).
    pub(super) fn tails(&self) -> Tails {
        if self.dead {
            let deadline = Instant::now() + Duration::from_secs(1);
            while !self.streams_closed.load(Ordering::SeqCst) && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(10));
            }
        }
        self.tails.lock().unwrap().snapshot()
    }

    /// Write `msg` as one line to Blender's stdin. A broken pipe means the process died: it
    /// is reported with its status and tails.
    pub(super) fn send(&mut self, msg: &serde_json::Value, doing: &str) -> Result<()> {
        let mut line = msg.to_string();
        line.push('\n');
        let ok = match self.stdin.as_mut() {
            Some(stdin) => stdin
                .write_all(line.as_bytes())
                .and_then(|_| stdin.flush())
                .is_ok(),
            None => false,
        };
        if ok {
            return Ok(());
        }
        Err(self.exited(doing))
    }

    /// Wait for the next reply line (without its tag) until `deadline`, watching for exit,
    /// silence past the idle limit and interrupts; the process is killed on each of them.
    pub(super) fn next_reply(&mut self, deadline: Instant, doing: &str) -> Result<String> {
        let waited = Instant::now();
        loop {
            if self.interrupt.load(Ordering::SeqCst) {
                self.kill();
                return Err(RenderError::Interrupted);
            }
            let now = Instant::now();
            let last = self.epoch + Duration::from_millis(self.activity.load(Ordering::Relaxed));
            let idle = now.saturating_duration_since(last.max(waited));
            if let Some(limit) = self.idle_timeout.filter(|l| idle >= *l) {
                self.kill();
                return Err(RenderError::Timeout {
                    program: self.program.clone(),
                    doing: format!(
                        "{doing}, silent for {:.0} s (idle limit {:.0} s)",
                        idle.as_secs_f64(),
                        limit.as_secs_f64()
                    ),
                    after: waited.elapsed(),
                    tails: Box::new(self.tails()),
                });
            }
            if now >= deadline {
                self.kill();
                return Err(RenderError::Timeout {
                    program: self.program.clone(),
                    doing: doing.to_string(),
                    after: waited.elapsed(),
                    tails: Box::new(self.tails()),
                });
            }
            match self.events.recv_timeout(POLL.min(deadline - now)) {
                Ok(Event::Reply(text)) => return Ok(text),
                Ok(Event::Eof) | Err(RecvTimeoutError::Disconnected) => {
                    return Err(self.exited(doing));
                }
                Err(RecvTimeoutError::Timeout) => {}
            }
        }
    }

    /// Kill the process for a reply `line` that breaks the protocol (`problem`), and report
    /// it (the line cut to 200 bytes) with the tails.
    pub(super) fn garbled(
        &mut self,
        doing: &str,
        mut line: String,
        problem: String,
    ) -> RenderError {
        self.kill();
        if line.len() > 200 {
            let mut cut = 200;
            while !line.is_char_boundary(cut) {
                cut -= 1;
            }
            line.truncate(cut);
            line.push_str("...");
        }
        RenderError::Protocol {
            program: self.program.clone(),
            doing: doing.to_string(),
            line,
            problem,
            tails: Box::new(self.tails()),
        }
    }

    /// The process closed its output or its input: wait briefly for its status and report
    /// its exit with the tails.
    fn exited(&mut self, doing: &str) -> RenderError {
        let status = self.wait_exit(EXIT_GRACE);
        RenderError::Exited {
            program: self.program.clone(),
            doing: doing.to_string(),
            status,
            tails: Box::new(self.tails()),
        }
    }

    /// Close Blender's stdin and wait up to `grace` for it to exit; kill it if it lingers.
    pub(super) fn close(&mut self, grace: Duration) {
        self.stdin = None;
        let deadline = Instant::now() + grace;
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.child.try_wait() {
                self.dead = true;
                return;
            }
            std::thread::sleep(POLL);
        }
        self.kill();
    }

    /// Wait up to `grace` for the process to exit (killing it after), returning its status.
    fn wait_exit(&mut self, grace: Duration) -> Option<std::process::ExitStatus> {
        self.dead = true;
        self.stdin = None;
        let deadline = Instant::now() + grace;
        loop {
            match self.child.try_wait() {
                Ok(Some(status)) => return Some(status),
                Ok(None) if Instant::now() < deadline => std::thread::sleep(POLL),
                _ => {
                    self.kill();
                    return None;
                }
            }
        }
    }

    /// Kill the process and its whole process group (a wrapper's Blender, anything Blender
    /// started), and reap it (idempotent).
    fn kill(&mut self) {
        self.dead = true;
        self.stdin = None;
        crate::group::kill_group(&mut self.child);
    }
}

impl Drop for Process {
    fn drop(&mut self) {
        self.kill();
    }
}

/// Call `f` on each line (lossy UTF-8, without the line ending) until EOF or a read error.
///
/// Blender's output is not trusted: a line longer than [`MAX_LINE`] bytes is cut there (the
/// rest of it is read and dropped, never buffered), so output without a newline costs at
/// most that much memory; a cut reply is then not valid JSON and ends as a protocol error.
fn read_lines(stream: impl Read, mut f: impl FnMut(&str)) {
    let mut reader = BufReader::new(stream);
    let mut buf = Vec::new();
    loop {
        buf.clear();
        let mut cut = false;
        let ended = loop {
            let chunk = match reader.fill_buf() {
                Ok([]) | Err(_) => break false,
                Ok(chunk) => chunk,
            };
            let (take, newline) = match chunk.iter().position(|&b| b == b'\n') {
                Some(i) => (i + 1, true),
                None => (chunk.len(), false),
            };
            let room = MAX_LINE.saturating_sub(buf.len());
            cut |= take > room;
            buf.extend_from_slice(&chunk[..take.min(room)]);
            reader.consume(take);
            if newline {
                break true;
            }
        };
        if buf.is_empty() && !ended {
            return;
        }
        let text = String::from_utf8_lossy(&buf);
        let line = text.trim_end_matches(['\n', '\r']);
        if cut {
            f(&format!("{line} [line cut at {MAX_LINE} bytes]"));
        } else {
            f(line);
        }
        if !ended {
            return;
        }
    }
}
