//! The encoder of each pass of the pass table ([`clevrtex_scene::passes`]): the bridge's
//! EXR layers (named by the table) in, the published PNG (of the table's kind) out.

use std::path::Path;

use clevrtex_scene::layout;
use clevrtex_scene::passes::Source;
use clevrtex_scene::{Pass, SceneFile};

use crate::error::{RenderError, Result};
use crate::exr_io::Channels;
use crate::job::reply_file;
use crate::output::Staged;
use crate::post::{self, ObjectPixels};
use crate::worker::RenderReply;

/// The float planes of layer `layer` (an index into the pass's `exr_layers`) of `pass`, one
/// per channel letter.
fn layer(ch: &Channels, pass: Pass, layer: usize) -> Result<Vec<&[f32]>> {
    pass.spec().exr_channels()[layer]
        .iter()
        .map(|name| ch.get(name))
        .collect()
}

/// Whether `ch` has every channel of layer `layer` of `pass`.
fn has_layer(ch: &Channels, pass: Pass, layer: usize) -> bool {
    pass.spec().exr_channels()[layer]
        .iter()
        .all(|name| ch.channels.contains_key(name))
}

/// The instance-id channel of the mask pass (also what the visibility render writes).
pub(crate) fn index_channel() -> String {
    Pass::Mask.spec().exr_channels()[0][0].clone()
}

/// The pixels of one encoded pass, 8- or 16-bit as its PNG kind says.
enum Pixels {
    Eight(Vec<u8>),
    Sixteen(Vec<u16>),
}

/// Encode `pass` (any but the copied RGB) from the final render's channels `fin`, the
/// no-shadow render's `ns` (shadow only) and the decoded instance ids.
fn encode(pass: Pass, fin: &Channels, ns: Option<&Channels>, ids: &[u8]) -> Result<Pixels> {
    Ok(match pass {
        Pass::Rgb => unreachable!("the RGB pass is the bridge's PNG, copied"),
        Pass::Mask => Pixels::Eight(ids.to_vec()),
        Pass::Depth => Pixels::Sixteen(post::encode_depth(layer(fin, pass, 0)?[0])),
        Pass::Normal => {
            let n = layer(fin, pass, 0)?;
            Pixels::Sixteen(post::encode_normal(n[0], n[1], n[2]))
        }
        Pass::Albedo => {
            let c = layer(fin, pass, 0)?;
            Pixels::Eight(post::encode_albedo(c[0], c[1], c[2]))
        }
        Pass::Shadow => {
            let ns = ns.expect("the shadow pass reads the no-shadow render");
            let (lit, un) = shadow_inputs(fin, ns)?;
            Pixels::Eight(post::encode_shadow(
                [&lit[0], &lit[1], &lit[2]],
                [&un[0], &un[1], &un[2]],
            ))
        }
    })
}

/// Three planes of float samples (R, G, B).
type Rgb = [Vec<f32>; 3];

/// The direct light with and without object shadows, per RGB channel: diffuse + glossy
/// (weighted by the colours of the final render) when the bridge wrote the glossy layers,
/// else diffuse direct light alone. The shadow pass's layers: 0 diffuse direct, 1 diffuse
/// colour, 2 glossy direct, 3 glossy colour.
fn shadow_inputs(fin: &Channels, ns: &Channels) -> Result<(Rgb, Rgb)> {
    let p = Pass::Shadow;
    let has_gloss = (1..4).all(|l| has_layer(fin, p, l)) && has_layer(ns, p, 2);
    let mut lit: Rgb = Default::default();
    let mut un: Rgb = Default::default();
    let (fin_dd, ns_dd) = (layer(fin, p, 0)?, layer(ns, p, 0)?);
    for k in 0..3 {
        if has_gloss {
            let (dc, gc) = (layer(fin, p, 1)?[k], layer(fin, p, 3)?[k]);
            lit[k] = post::direct_light(fin_dd[k], dc, layer(fin, p, 2)?[k], gc);
            un[k] = post::direct_light(ns_dd[k], dc, layer(ns, p, 2)?[k], gc);
        } else {
            lit[k] = fin_dd[k].to_vec();
            un[k] = ns_dd[k].to_vec();
        }
    }
    Ok((lit, un))
}

/// Decode the bridge's files, encode every requested pass into `staged`, and return the
/// per-object visibility measured on the final mask.
pub(crate) fn write_passes(
    reply: &RenderReply,
    work: &Path,
    scene: &SceneFile,
    passes: &[Pass],
    stem: &str,
    keep_exr: bool,
    staged: &mut Staged,
) -> Result<Vec<ObjectPixels>> {
    let exr_path = reply_file(reply, "passes", work)?;
    let ch = Channels::read(&exr_path)?;
    let (w, h) = (ch.width as u32, ch.height as u32);
    if (w, h) != (scene.render.width, scene.render.height) {
        return Err(RenderError::BadOutput {
            path: exr_path,
            problem: format!(
                "size {w}x{h} but the scene asks for {}x{}",
                scene.render.width, scene.render.height
            ),
        });
    }
    let n = scene.objects.len();
    let ids = post::instance_ids(ch.get(&index_channel())?, n, &exr_path)?;
    let objects = post::object_pixels(&ids, ch.width, n);
    let noshadow = match passes
        .iter()
        .any(|p| p.spec().source == Source::PassesAndNoShadowExr)
    {
        true => Some(Channels::read(&reply_file(reply, "noshadow", work)?)?),
        false => None,
    };
    for &pass in passes {
        let name = layout::pass_file(stem, pass);
        if pass.spec().source == Source::RgbPng {
            let from = reply_file(reply, "rgb", work)?;
            let bytes = std::fs::read(&from).map_err(|e| {
                RenderError::io(
                    "cannot read render output",
                    &from,
                    e,
                    "the Blender worker's temporary folder vanished; rerun",
                )
            })?;
            // Blender's timing stamps out: the same pixels give the same bytes.
            staged.write(&name, &post::strip_png_text(&bytes, &from)?)?;
            continue;
        }
        let kind = pass.spec().png;
        let bytes = match encode(pass, &ch, noshadow.as_ref(), &ids)? {
            Pixels::Eight(d) => post::encode_png(kind, w, h, &d, &[]),
            Pixels::Sixteen(d) => post::encode_png(kind, w, h, &[], &d),
        }
        .map_err(|e| RenderError::BadOutput {
            path: exr_path.clone(),
            problem: format!("cannot encode the {} PNG: {e}", pass.name()),
        })?;
        staged.write(&name, &bytes)?;
    }
    if keep_exr {
        let names = layout::exr_files(stem, passes.contains(&Pass::Shadow));
        staged.copy(&names[0], &exr_path)?;
        if let Some(ns) = names.get(1) {
            staged.copy(ns, &reply_file(reply, "noshadow", work)?)?;
        }
    }
    Ok(objects)
}
