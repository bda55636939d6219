//! What a run of `generate` or `render` shows on the terminal: the progress bar (its text,
//! lines and summary are `clevrtex_render::run_text`'s).

use std::io::IsTerminal;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

pub(crate) fn progress_bar(total: u64) -> ProgressBar {
    let target = if std::io::stderr().is_terminal() {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    };
    let bar = ProgressBar::with_draw_target(Some(total), target);
    bar.set_style(
        ProgressStyle::with_template("{bar:24} {pos}/{len} images, {msg}, ETA {eta}")
            .expect("valid template"),
    );
    bar.set_message("0 img/h, 0 rejects, 0 failed");
    bar.enable_steady_tick(Duration::from_millis(500));
    bar
}
