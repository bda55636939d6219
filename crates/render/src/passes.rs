//! Decoding the bridge's files into the published pass encodings.

use std::path::Path;

use clevrtex_scene::{Pass, SceneFile};

use crate::error::{RenderError, Result};
use crate::exr_io::Channels;
use crate::job::reply_file;
use crate::output::{self, Staged};
use crate::post::{self, ObjectPixels, PngKind};
use crate::worker::RenderReply;

/// Three planes of float samples (R, G, B).
type Rgb = [Vec<f32>; 3];

/// The direct light with and without object shadows, per RGB channel: diffuse + glossy
/// (weighted by the colours of the final render) when the bridge wrote the glossy channels,
/// else diffuse direct light alone.
fn shadow_inputs(fin: &Channels, ns: &Channels) -> Result<(Rgb, Rgb)> {
    let name = |pass: &str, c: &str| format!("ViewLayer.{pass}.{c}");
    let has_gloss = ["GlossDir", "GlossCol", "DiffCol"]
        .iter()
        .all(|p| fin.channels.contains_key(&name(p, "R")))
        && ns.channels.contains_key(&name("GlossDir", "R"));
    let mut lit: Rgb = Default::default();
    let mut un: Rgb = Default::default();
    for (k, c) in ["R", "G", "B"].into_iter().enumerate() {
        if has_gloss {
            let (dc, gc) = (
                fin.get(&name("DiffCol", c))?,
                fin.get(&name("GlossCol", c))?,
            );
            lit[k] = post::direct_light(
                fin.get(&name("DiffDir", c))?,
                dc,
                fin.get(&name("GlossDir", c))?,
                gc,
            );
            un[k] = post::direct_light(
                ns.get(&name("DiffDir", c))?,
                dc,
                ns.get(&name("GlossDir", c))?,
                gc,
            );
        } else {
            lit[k] = fin.get(&name("DiffDir", c))?.to_vec();
            un[k] = ns.get(&name("DiffDir", c))?.to_vec();
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
    let ids = post::instance_ids(ch.get("ViewLayer.IndexOB.X")?, n, &exr_path)?;
    let objects = post::object_pixels(&ids, ch.width, n);
    let png = |kind, d8: &[u8], d16: &[u16]| {
        post::encode_png(kind, w, h, d8, d16).map_err(|e| RenderError::BadOutput {
            path: exr_path.clone(),
            problem: format!("cannot encode PNG: {e}"),
        })
    };
    let rgb3 = |c: &Channels, base: &str, names: [&str; 3]| -> Result<[Vec<f32>; 3]> {
        Ok([
            c.get(&format!("{base}.{}", names[0]))?.to_vec(),
            c.get(&format!("{base}.{}", names[1]))?.to_vec(),
            c.get(&format!("{base}.{}", names[2]))?.to_vec(),
        ])
    };
    for &pass in passes {
        let name = output::pass_file(stem, pass);
        match pass {
            Pass::Rgb => staged.copy(&name, &reply_file(reply, "rgb", work)?)?,
            Pass::Mask => staged.write(&name, &png(PngKind::Palette8, &ids, &[])?)?,
            Pass::Depth => {
                let d = post::encode_depth(ch.get("ViewLayer.Depth.Z")?);
                staged.write(&name, &png(PngKind::Gray16, &[], &d)?)?
            }
            Pass::Normal => {
                let [x, y, z] = rgb3(&ch, "ViewLayer.Normal", ["X", "Y", "Z"])?;
                let d = post::encode_normal(&x, &y, &z);
                staged.write(&name, &png(PngKind::Rgb16, &[], &d)?)?
            }
            Pass::Albedo => {
                let [r, g, b] = rgb3(&ch, "ViewLayer.DiffCol", ["R", "G", "B"])?;
                staged.write(
                    &name,
                    &png(PngKind::Rgb8, &post::encode_albedo(&r, &g, &b), &[])?,
                )?
            }
            Pass::Shadow => {
                let ns_path = reply_file(reply, "noshadow", work)?;
                let ns = Channels::read(&ns_path)?;
                let (lit, un) = shadow_inputs(&ch, &ns)?;
                let s = post::encode_shadow([&lit[0], &lit[1], &lit[2]], [&un[0], &un[1], &un[2]]);
                staged.write(&name, &png(PngKind::Gray8, &s, &[])?)?
            }
        }
    }
    if keep_exr {
        let names = output::exr_files(stem, passes.contains(&Pass::Shadow));
        staged.copy(&names[0], &exr_path)?;
        if let Some(ns) = names.get(1) {
            staged.copy(ns, &reply_file(reply, "noshadow", work)?)?;
        }
    }
    Ok(objects)
}
