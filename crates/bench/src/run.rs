//! `bench render`'s run ([`run`]): every Blender found first, the user materials checked once,
//! then for each Blender a session opened (`clevrtex_render::command_session`), its features
//! checked and the ladder measured ([`Bench::measure`]). The only place the bench starts
//! Blender; what it says goes to the caller's `say` (stdout) and `on_event` (stderr).

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use clevrtex_materials::Catalogue;
use clevrtex_render::command_session::{BlenderSession, Settings};
use clevrtex_render::{RenderReply, Worker};

use crate::measure::{runs_dir, Bench, Event, Plan, WorkerResult};
use crate::scenes::BenchScene;
use crate::{Render, Row, Setting};

/// The bench renders through a command session: restarts are warned about and Ctrl-C stops
/// Blender, as in every command.
struct SessionRender(BlenderSession);

impl Render for SessionRender {
    fn request(
        &mut self,
        call: &mut dyn FnMut(&mut Worker) -> WorkerResult,
    ) -> anyhow::Result<RenderReply> {
        Ok(self.0.request(call)?)
    }
}

/// What `bench render` runs with besides its plan, scenes and rungs.
pub struct Options<'a> {
    /// `--blender`, each given (empty: the default one).
    pub blenders: &'a [PathBuf],
    /// Cycles threads (0: Blender's choice).
    pub threads: u32,
    /// Restarts of a worker per render.
    pub retries: u32,
    /// Time limit for a worker to start.
    pub startup_timeout: Duration,
    /// `--levers`: the rungs need Cycles 4.x.
    pub levers: bool,
    /// `--quick` (said in the first header line).
    pub quick: bool,
    /// Output folder.
    pub out: &'a Path,
    /// Set by the command's Ctrl-C handler.
    pub interrupt: Arc<AtomicBool>,
}

/// Measure `settings` on `scenes` with each Blender of `opts` in turn: one row per (Blender,
/// scene, rung). `catalogue` gets its user materials checked (with the first Blender, before
/// anything renders); a header line per Blender goes to `say`.
pub fn run(
    opts: &Options,
    catalogue: &mut Catalogue,
    (plan, scenes, settings): (&Plan, &[BenchScene], &[Setting]),
    say: &mut dyn FnMut(String),
    on_event: &mut dyn FnMut(Event),
) -> anyhow::Result<Vec<Row>> {
    // Every Blender is found before anything renders: a typo in the last one must not cost
    // the first one's hours.
    let blenders = if opts.blenders.is_empty() {
        vec![clevrtex_render::blender::locate(None)?]
    } else {
        opts.blenders
            .iter()
            .map(|b| clevrtex_render::blender::locate(Some(b)))
            .collect::<Result<Vec<_>, _>>()?
    };
    // User materials are checked before anything renders (once: the checks do not depend on
    // the Blender), with the first Blender.
    let used: BTreeSet<String> = scenes
        .iter()
        .flat_map(|s| {
            std::iter::once(&s.scene.backdrop.material)
                .chain(s.scene.objects.iter().map(|o| &o.material))
                .map(|m| m.name.clone())
        })
        .collect();
    let _user = clevrtex_render::user_materials::check_before_run(
        catalogue,
        &used,
        &blenders[0],
        opts.startup_timeout,
        opts.interrupt.clone(),
    )?;
    let (n, width, height) = (plan.scenes, plan.width, plan.height);
    let mut rows = Vec::new();
    for (i, blender) in blenders.into_iter().enumerate() {
        let mut session = SessionRender(BlenderSession::new(Settings {
            blender,
            materials_json: catalogue.resolved_json(),
            threads: opts.threads,
            retries: opts.retries,
            idle_timeout: None,
            interrupt: opts.interrupt.clone(),
            startup_timeout: opts.startup_timeout,
        })?);
        let ready = session.0.ready()?;
        let blender_version = ready.blender_version;
        if opts.levers && !ready.features.light_tree {
            anyhow::bail!(
                "`--levers` needs Cycles 4.x levers, but Blender {blender_version} has none\nhint: pass only Blenders 4.x or 5.x with `--blender` (e.g. `.venv-bpy/bin/python` from `./scripts/setup.sh --bpy 4.5`)"
            );
        }
        say(format!(
            "bench render: {n} scene(s) at {width}x{height}, {} setting(s), references at {} fixed samples; Blender {blender_version}, {} Cycles thread(s){}",
            settings.len(),
            plan.reference_samples,
            if opts.threads == 0 { "auto".to_string() } else { opts.threads.to_string() },
            if opts.quick && i == 0 {
                "\nquick mode: small frames, 2 scenes and fewer rungs; compare settings with it, take per-image costs from a full run"
            } else {
                ""
            }
        ));
        let place = (opts.blenders.len() > 1).then_some(i);
        let runs = runs_dir(opts.out, place, &blender_version);
        rows.extend(
            Bench {
                blender: &mut session,
                catalogue,
                blender_version: &blender_version,
                out: opts.out,
                runs: &runs,
                on_event,
            }
            .measure(plan, scenes, settings)?,
        );
        session.0.close();
    }
    Ok(rows)
}

/// What `bench render` shows of `rows` (`n` scenes at `width` x `height`): the table, summary
/// and side-by-side to `say` first, then the plot drawn next to the CSV in `out` (with text
/// if `fonts`, a font is registered) and the lines naming both files.
pub fn report(
    rows: &[Row],
    (n, width, height): (usize, u32, u32),
    out: &Path,
    fonts: bool,
    say: &mut dyn FnMut(String),
) -> anyhow::Result<()> {
    use crate::summary;
    let agg = summary::aggregate(rows);
    say(summary::table(&agg) + &summary::summary(&agg) + &summary::side_by_side(rows));
    let text = summary::write_plot(&agg, n, width, height, out, fonts)?;
    let stem = summary::plot_stem(out);
    say(format!(
        "csv: {}\nplot: {} and {}{}\n",
        crate::csv::path(out).display(),
        stem.with_extension("png").display(),
        stem.with_extension("svg").display(),
        if text {
            ""
        } else {
            " (no system font found: drawn without text; install fonts-dejavu-core)"
        }
    ));
    Ok(())
}
