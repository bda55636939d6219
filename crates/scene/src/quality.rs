//! Quality presets: named Cycles settings chosen from the error-against-time curve that
//! `clevrtex bench render` measures (`docs/notes/performance.md`, section `bench`).
//!
//! A preset changes only the sampling and light-path fields of [`RenderSettings`]
//! (samples, adaptive threshold, bounces, indirect clamp); resolution, filter and colour
//! management stay as the config says.
//!
//! ```
//! use clevrtex_scene::{quality::Quality, Config};
//!
//! let mut render = Config::builtin("full").unwrap().base.render;
//! Quality::Standard.apply(&mut render);
//! assert_eq!(render.samples, Quality::Standard.settings().samples);
//! assert_eq!("draft".parse::<Quality>().unwrap(), Quality::Draft);
//! ```

use crate::scene_file::RenderSettings;

/// A named quality level.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Quality {
    /// Previews and layout checks: visibly noisy.
    Draft,
    /// Cycles 4.x only: few samples, the RGB denoised by OpenImageDenoise; the 64-sample
    /// default's error for at most half its CPU time (measured, see `docs/performance.md`).
    /// A Blender without OIDN (Debian's 3.4) refuses it rather than render noisy images.
    Fast,
    /// Datasets: reaches the error of the original generator's 512 fixed samples in at
    /// most half its time (measured, see `docs/performance.md`).
    Standard,
    /// Lower noise than the original, at about its cost.
    High,
    /// Ground truth for error measurements: many samples, the original's light paths.
    Reference,
}

/// The sampling and light-path fields a preset sets.
// The same fields as the scene file's `RenderSettings` by design (copied by `of`): it cannot be
// flattened into it (serde's `flatten` does not go with `deny_unknown_fields`, which untrusted
// scene files need).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sampling {
    /// Samples per pixel (the maximum when adaptive sampling is on).
    pub samples: u32,
    /// Adaptive-sampling noise threshold; `None` = fixed samples.
    pub adaptive_threshold: Option<f32>,
    /// Total max bounces.
    pub max_bounces: u32,
    /// Diffuse bounces.
    pub diffuse_bounces: u32,
    /// Glossy bounces.
    pub glossy_bounces: u32,
    /// Transmission bounces.
    pub transmission_bounces: u32,
    /// Transparent bounces.
    pub transparent_max_bounces: u32,
    /// Indirect light clamp (0 = off).
    pub clamp_indirect: f32,
    /// Cycles 4.x levers (light tree, path guiding, blue noise, denoising).
    pub levers: Levers,
}

/// The render levers of Cycles 4.x that 3.4 lacks ([`RenderSettings`]' `light_tree`,
/// `path_guiding`, `blue_noise`, `denoise`); `None`: the version's default.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Levers {
    /// The light tree (4.0+; on by default there).
    pub light_tree: Option<bool>,
    /// Path guiding (CPU only).
    pub path_guiding: Option<bool>,
    /// Blue-noise sampling pattern (4.2+).
    pub blue_noise: Option<bool>,
    /// OpenImageDenoise on the RGB only.
    pub denoise: bool,
}

impl Levers {
    /// Every lever at the version's default, no denoising.
    pub const NONE: Levers = Levers {
        light_tree: None,
        path_guiding: None,
        blue_noise: None,
        denoise: false,
    };
}

impl Sampling {
    /// The original generator's setting (the public generator's `clevrtex-gen/generate.py`
    /// defaults, karazijal/clevrtex-generation): 512 fixed samples, max bounces 12
    /// (diffuse 4, glossy 4, transmission 12, transparent 8), no clamping, no adaptive
    /// sampling.
    pub const ORIGINAL: Sampling = Sampling {
        samples: 512,
        adaptive_threshold: None,
        max_bounces: 12,
        diffuse_bounces: 4,
        glossy_bounces: 4,
        transmission_bounces: 12,
        transparent_max_bounces: 8,
        clamp_indirect: 0.0,
        levers: Levers::NONE,
    };

    /// Copy these fields into `render`.
    pub fn apply(&self, render: &mut RenderSettings) {
        render.samples = self.samples;
        render.adaptive_threshold = self.adaptive_threshold;
        render.max_bounces = self.max_bounces;
        render.diffuse_bounces = self.diffuse_bounces;
        render.glossy_bounces = self.glossy_bounces;
        render.transmission_bounces = self.transmission_bounces;
        render.transparent_max_bounces = self.transparent_max_bounces;
        render.clamp_indirect = self.clamp_indirect;
        render.light_tree = self.levers.light_tree;
        render.path_guiding = self.levers.path_guiding;
        render.blue_noise = self.levers.blue_noise;
        render.denoise = self.levers.denoise;
    }

    /// The same fields read from `render`.
    pub fn of(render: &RenderSettings) -> Sampling {
        Sampling {
            samples: render.samples,
            adaptive_threshold: render.adaptive_threshold,
            max_bounces: render.max_bounces,
            diffuse_bounces: render.diffuse_bounces,
            glossy_bounces: render.glossy_bounces,
            transmission_bounces: render.transmission_bounces,
            transparent_max_bounces: render.transparent_max_bounces,
            clamp_indirect: render.clamp_indirect,
            levers: Levers {
                light_tree: render.light_tree,
                path_guiding: render.path_guiding,
                blue_noise: render.blue_noise,
                denoise: render.denoise,
            },
        }
    }
}

impl Quality {
    /// Every preset, cheapest first.
    pub const ALL: [Quality; 5] = [
        Quality::Draft,
        Quality::Fast,
        Quality::Standard,
        Quality::High,
        Quality::Reference,
    ];

    /// The preset's name as used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Quality::Draft => "draft",
            Quality::Fast => "fast",
            Quality::Standard => "standard",
            Quality::High => "high",
            Quality::Reference => "reference",
        }
    }

    /// The settings of the preset. Why these values: `docs/notes/performance.md`, section `bench`.
    pub fn settings(self) -> Sampling {
        let o = Sampling::ORIGINAL;
        match self {
            // Fixed: at 16 samples Cycles' automatic minimum keeps adaptive sampling from
            // stopping any pixel (measured: bit-identical images), so a threshold buys nothing.
            Quality::Draft => Sampling { samples: 16, ..o },
            // OIDN on the RGB (albedo and normal as its guides); masks, depth, normals and the
            // shadow pass are never denoised. Samples: the fewest whose denoised error stays at
            // the 64-sample default's (`clevrtex bench render --levers`, docs/performance.md).
            Quality::Fast => Sampling {
                samples: FAST_SAMPLES,
                levers: Levers {
                    denoise: true,
                    ..Levers::NONE
                },
                ..o
            },
            // Adaptive sampling stops the quiet pixels (plain backdrops, CAMO) early; on
            // busy textures it changes little (measured in docs/notes/performance.md).
            Quality::Standard => Sampling {
                samples: 512,
                adaptive_threshold: Some(0.01),
                ..o
            },
            Quality::High => Sampling {
                samples: 1024,
                adaptive_threshold: Some(0.005),
                ..o
            },
            Quality::Reference => Sampling { samples: 2048, ..o },
        }
    }

    /// Whether the preset needs OpenImageDenoise (Cycles 4.x; Debian's Blender 3.4 lacks it).
    pub fn needs_oidn(self) -> bool {
        self.settings().levers.denoise
    }

    /// Set the sampling and light-path fields of `render` to this preset's.
    pub fn apply(self, render: &mut RenderSettings) {
        self.settings().apply(render);
    }
}

impl std::fmt::Display for Quality {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Samples of the `fast` preset (denoised).
const FAST_SAMPLES: u32 = 16;

/// A quality name that is not a preset.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown quality `{0}`\nhint: use one of draft, fast, standard, high, reference")]
pub struct UnknownQuality(pub String);

impl std::str::FromStr for Quality {
    type Err = UnknownQuality;

    fn from_str(s: &str) -> Result<Quality, UnknownQuality> {
        Quality::ALL
            .into_iter()
            .find(|q| q.name() == s.trim())
            .ok_or_else(|| UnknownQuality(s.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_unknown_names_are_errors() {
        for q in Quality::ALL {
            assert_eq!(q.name().parse::<Quality>(), Ok(q));
        }
        let e = "ultra".parse::<Quality>().unwrap_err();
        assert_eq!(
            e.to_string(),
            "unknown quality `ultra`\nhint: use one of draft, fast, standard, high, reference"
        );
    }

    #[test]
    fn presets_get_more_expensive_and_keep_the_original_light_paths() {
        let s: Vec<Sampling> = Quality::ALL.iter().map(|q| q.settings()).collect();
        for w in s.windows(2) {
            // `fast` denoises: dearer than `draft` at the same samples.
            let denoise = |p: &Sampling| u32::from(p.levers.denoise);
            assert!((w[0].samples, denoise(&w[0])) < (w[1].samples, denoise(&w[1])));
        }
        for p in &s {
            assert_eq!(p.max_bounces, Sampling::ORIGINAL.max_bounces);
            assert_eq!(p.diffuse_bounces, Sampling::ORIGINAL.diffuse_bounces);
            assert_eq!(p.clamp_indirect, 0.0);
        }
        assert_eq!(Quality::Reference.settings().adaptive_threshold, None);
    }

    #[test]
    fn only_fast_denoises_and_it_uses_fewer_samples_than_the_default() {
        let default = crate::Config::builtin("full").unwrap().base.render;
        for q in Quality::ALL {
            assert_eq!(q.needs_oidn(), q == Quality::Fast, "{q}");
        }
        let fast = Quality::Fast.settings();
        assert!(fast.samples < default.samples / 2, "{fast:?}");
        assert_eq!(fast.adaptive_threshold, None);
        // Only denoising changes among the levers: the light tree stays at the parity default.
        assert_eq!(
            fast.levers,
            Levers {
                denoise: true,
                ..Levers::NONE
            }
        );
    }

    #[test]
    fn apply_then_of_gives_the_preset_back() {
        let mut r = crate::Config::builtin("full").unwrap().base.render;
        let (w, h) = (r.width, r.height);
        for q in Quality::ALL {
            q.apply(&mut r);
            assert_eq!(Sampling::of(&r), q.settings());
            assert_eq!((r.width, r.height), (w, h));
        }
    }
}
