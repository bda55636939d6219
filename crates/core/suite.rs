//! `generate --suite`: a benchmark suite ([`clevrtex_scene::suite`]) made variant after
//! variant into one folder, each variant's part of this shard of the whole suite made (or,
//! with `--estimate`, planned) as one `generate` run, with the suite's plan recorded first
//! (`clevrtex_dataset::suite`). The variants' runs share their Blender workers
//! ([`clevrtex_render::kept`]): a worker started for one variant renders the next.

use std::cell::Cell;

use crate::cmd_generate::{run_part, GenerateArgs, Part};
use crate::exit::{self, CmdResult};

/// Make (or plan) suite `name` at `scale` as `args` say.
pub(crate) fn run(args: &GenerateArgs, name: &str, scale: f64) -> CmdResult {
    let suite = clevrtex_scene::suite::find(name).map_err(anyhow::Error::msg)?;
    let plan = suite.plan(scale, args.seed).map_err(anyhow::Error::msg)?;
    let shard = clevrtex_scene::shard::resolve(args.shard.as_deref(), args.shard_count)?;
    let out = &args.run.out;
    // The numbers given as flags before anything is written (`SUITE.json` included).
    crate::run::checked_numbers(&args.run)?;
    if !args.estimate {
        // Nothing is written into a folder of another suite or with a foreign variant; the
        // check and the write under the suite's lock, so of two suites started at once into
        // one folder the second is refused and its plan never written.
        clevrtex_dataset::suite::claim(out, &plan)?;
    }
    println!(
        "suite `{}` at scale {}: {} images ({}), seed {}, shard {}/{}",
        plan.suite,
        plan.scale,
        plan.images(),
        plan.variants
            .iter()
            .map(|v| format!("{} {}", v.variant, v.total))
            .collect::<Vec<_>>()
            .join(", "),
        plan.seed,
        shard.k,
        shard.n
    );
    let sum = Cell::new((0.0, 0.0));
    let keep = std::sync::Arc::new(clevrtex_render::kept::KeptWorkers::new());
    let mut code = exit::OK;
    for v in &plan.variants {
        let images = clevrtex_render::generate::Part {
            start: 0,
            count: v.total,
            total: Some(v.total),
            shard: plan.variant_shard(v, shard),
            seed: v.seed,
        };
        let part = Part {
            variant: &v.variant,
            images,
            suite: Some(&plan.suite),
        };
        if images.shard.count(0, v.total) == 0 {
            continue;
        }
        let c = run_part(args, &part, args.estimate.then_some(&sum), Some(&keep))?;
        if c != exit::OK && c != exit::PARTIAL {
            // Interrupted: the later variants are not started.
            return Ok(c);
        }
        code = code.max(c);
    }
    // The workers quit before the suite's last line.
    let reused = keep.reused();
    keep.close();
    if args.estimate {
        let (wall, held) = sum.get();
        println!(
            "suite `{}`, this shard's {} images on this machine: wall {}, {held:.2} hours held (the variants' predictions above, added)",
            plan.suite,
            plan.variants
                .iter()
                .map(|v| plan.variant_shard(v, shard).count(0, v.total))
                .sum::<u64>(),
            clevrtex_render::run_text::format_duration(wall)
        );
    } else {
        println!(
            "suite `{}`: {reused} worker(s) carried on from one variant to the next instead of starting Blender again; check the whole suite with `clevrtex verify {}`",
            plan.suite,
            out.display()
        );
    }
    Ok(code)
}
