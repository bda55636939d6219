//! The ladder of render settings `clevrtex bench render` tries, grouped into curves (one
//! curve per sampling mode in the plot).

use clevrtex_scene::quality::{Levers, Quality, Sampling};

/// One rung: a named setting on a curve.
#[derive(Debug, Clone, PartialEq)]
pub struct Setting {
    /// Curve (sampling mode): `fixed`, `adaptive`, `adaptive-lowbounce`, `adaptive-clamp`,
    /// `preset`.
    pub mode: &'static str,
    /// Short unique label, e.g. `fixed-64`, `original-512`, `preset-standard`.
    pub label: String,
    /// The settings.
    pub sampling: Sampling,
}

/// Bounces cut to what a matte, mostly diffuse ClevrTex scene plausibly needs: a bias
/// (darker indirect light) traded for time.
const LOW_BOUNCES: Sampling = Sampling {
    max_bounces: 4,
    diffuse_bounces: 2,
    glossy_bounces: 2,
    transmission_bounces: 4,
    transparent_max_bounces: 4,
    ..Sampling::ORIGINAL
};

fn fixed(samples: u32) -> Setting {
    let label = if samples == Sampling::ORIGINAL.samples {
        format!("original-{samples}")
    } else {
        format!("fixed-{samples}")
    };
    Setting {
        mode: "fixed",
        label,
        sampling: Sampling {
            samples,
            ..Sampling::ORIGINAL
        },
    }
}

fn adaptive(mode: &'static str, base: Sampling, samples: u32, threshold: f32) -> Setting {
    Setting {
        mode,
        label: format!("{mode}-{samples}-t{threshold}"),
        sampling: Sampling {
            samples,
            adaptive_threshold: Some(threshold),
            ..base
        },
    }
}

fn preset(q: Quality) -> Setting {
    Setting {
        mode: "preset",
        label: format!("preset-{}", q.name()),
        sampling: q.settings(),
    }
}

fn lever(mode: &'static str, samples: u32, levers: Levers) -> Setting {
    Setting {
        mode,
        label: format!("{mode}-{samples}"),
        sampling: Sampling {
            samples,
            levers,
            ..Sampling::ORIGINAL
        },
    }
}

/// The rungs of Cycles 4.x's levers (only where the Blender has them: `clevrtex bench` asks the
/// worker): fixed samples with the light tree off (4.x turns it on by default), with path
/// guiding, with the blue-noise pattern, and OIDN-denoised RGB (opt-in).
pub fn lever_rungs(quick: bool) -> Vec<Setting> {
    let samples: &[u32] = if quick { &[16, 64] } else { &[16, 64, 256] };
    let mut out = Vec::new();
    for &s in samples {
        let off = Levers {
            light_tree: Some(false),
            ..Levers::NONE
        };
        out.push(lever("notree", s, off));
        out.push(lever(
            "guiding",
            s,
            Levers {
                path_guiding: Some(true),
                ..Levers::NONE
            },
        ));
        out.push(lever(
            "bluenoise",
            s,
            Levers {
                blue_noise: Some(true),
                ..Levers::NONE
            },
        ));
    }
    let denoised: &[u32] = if quick {
        &[4, 8, 16, 32, 64]
    } else {
        &[4, 8, 16, 32, 64, 256]
    };
    for &s in denoised {
        out.push(lever(
            "oidn",
            s,
            Levers {
                denoise: true,
                ..Levers::NONE
            },
        ));
        out.push(lever(
            "oidn-notree",
            s,
            Levers {
                light_tree: Some(false),
                denoise: true,
                ..Levers::NONE
            },
        ));
    }
    // The `fast` preset (denoised, Cycles 4.x only), unless a rung above has its settings.
    if !out.iter().any(|s| s.sampling == Quality::Fast.settings()) {
        out.push(preset(Quality::Fast));
    }
    out
}

/// The ladder. `quick` keeps the rungs that decide the presets (the original's 512 fixed
/// samples, the adaptive curve up to it, the presets below `high`) and drops the rest.
pub fn ladder(quick: bool) -> Vec<Setting> {
    let o = Sampling::ORIGINAL;
    let clamp = Sampling {
        clamp_indirect: 1.0,
        ..o
    };
    let mut out = Vec::new();
    let fixed_samples: &[u32] = if quick {
        &[4, 16, 64, 256, 512]
    } else {
        &[4, 16, 64, 128, 256, 512, 1024]
    };
    out.extend(fixed_samples.iter().map(|&s| fixed(s)));
    let adaptive_rungs: &[(u32, f32)] = if quick {
        &[(16, 0.1), (64, 0.05), (256, 0.02)]
    } else {
        &[
            (16, 0.1),
            (64, 0.05),
            (256, 0.02),
            (512, 0.01),
            (1024, 0.02),
            (1024, 0.005),
        ]
    };
    out.extend(
        adaptive_rungs
            .iter()
            .map(|&(s, t)| adaptive("adaptive", o, s, t)),
    );
    let variant_rungs: &[(u32, f32)] = if quick {
        &[(512, 0.01)]
    } else {
        &[(64, 0.05), (256, 0.02), (512, 0.01)]
    };
    for &(s, t) in variant_rungs {
        out.push(adaptive("adaptive-lowbounce", LOW_BOUNCES, s, t));
        out.push(adaptive("adaptive-clamp", clamp, s, t));
    }
    let presets: &[Quality] = if quick {
        &[Quality::Draft, Quality::Standard]
    } else {
        &[Quality::Draft, Quality::Standard, Quality::High]
    };
    // A preset equal to a rung already measured is not rendered twice: the summary finds
    // presets by their settings.
    for &q in presets {
        if !out.iter().any(|s| s.sampling == q.settings()) {
            out.push(preset(q));
        }
    }
    out
}

/// The rungs to run: the ladder (with `levers`, also the lever rungs), less those with more
/// samples than `max_samples` and, given `only`, those whose label contains none of its words.
pub fn select(
    quick: bool,
    levers: bool,
    max_samples: Option<u32>,
    only: Option<&[String]>,
) -> anyhow::Result<Vec<Setting>> {
    let settings: Vec<Setting> = ladder(quick)
        .into_iter()
        .chain(if levers {
            lever_rungs(quick)
        } else {
            Vec::new()
        })
        .filter(|s| max_samples.is_none_or(|m| s.sampling.samples <= m))
        .filter(|s| only.is_none_or(|l| l.iter().any(|w| s.label.contains(w.trim()))))
        .collect();
    if settings.is_empty() {
        anyhow::bail!("no rung of the ladder is left after `--max-samples`/`--only`\nhint: raise `--max-samples` or widen `--only`");
    }
    Ok(settings)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_are_unique_and_the_original_is_a_rung() {
        for quick in [false, true] {
            let l = ladder(quick);
            let mut labels: Vec<&str> = l.iter().map(|s| s.label.as_str()).collect();
            labels.sort();
            let n = labels.len();
            labels.dedup();
            assert_eq!(labels.len(), n, "duplicate labels in {labels:?}");
            let orig = l.iter().find(|s| s.label == "original-512").unwrap();
            assert_eq!(orig.sampling, Sampling::ORIGINAL);
            for q in [Quality::Draft, Quality::Standard] {
                assert!(l.iter().any(|s| s.sampling == q.settings()), "{q} missing");
            }
            // `fast` denoises: a lever rung (Cycles 4.x), never in the ladder 3.4 renders,
            // and measured beside the 64-sample default it is judged against.
            assert!(!l.iter().any(|s| s.sampling.levers.denoise));
            assert!(lever_rungs(quick)
                .iter()
                .any(|s| s.sampling == Quality::Fast.settings()));
            assert!(l.iter().any(|s| s.label == "fixed-64"));
        }
    }
}
