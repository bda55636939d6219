//! The encoder of each pass of the pass table ([`clevrtex_scene::passes`]): the bridge's
//! EXR layers (named by the table) in, the published PNG (of the table's kind) out.

use std::path::PathBuf;

use clevrtex_dataset::layout;
use clevrtex_scene::passes::Source;
use clevrtex_scene::{Pass, SceneFile};

use crate::error::{RenderError, Result};
use crate::exr_io::Channels;
use crate::output::Staged;
use crate::post::{self, ObjectPixels};

/// The float planes of layer `layer` (an index into the pass's `exr_layers`) of `pass`, one
/// per channel letter.
fn layer(ch: &Channels, pass: Pass, layer: usize) -> Result<Vec<&[f32]>> {
    pass.spec().exr_channels()[layer]
        .iter()
        .map(|name| ch.get(name))
        .collect()
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
/// shadow pass's render (shadow only) and the decoded instance ids.
fn encode(pass: Pass, fin: &Channels, shadow: Option<&Channels>, ids: &[u8]) -> Result<Pixels> {
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
            let s = shadow.expect("the shadow pass reads its own render");
            // Direct light on white diffuse surfaces with white lights: `DiffDir` is the
            // light's luminance, without object shadows in red, with them in green
            // (`builder.OneRenderShadow`). Filtered within each instance of the final mask.
            let c = layer(s, pass, 0)?;
            Pixels::Eight(post::encode_shadow(
                c[1],
                c[0],
                ids,
                fin.width,
                post::SHADOW_FILTER,
            ))
        }
    })
}

/// The file of a role (`passes`, `shadow`, `rgb`) the bridge reported, checked (the worker's
/// [`crate::RenderReply::file`] in its scratch folder).
type BridgeFile<'a> = &'a dyn Fn(&str) -> Result<PathBuf>;

/// Read the shadow pass's EXR (`role` in the bridge's files), checking its size.
fn read_shadow_exr(file: BridgeFile, role: &str, size: (usize, usize)) -> Result<Channels> {
    let path = file(role)?;
    let ch = Channels::read_sized(&path, size)?;
    if (ch.width, ch.height) != size {
        return Err(RenderError::BadOutput {
            path,
            problem: format!(
                "size {}x{} but the final render is {}x{}",
                ch.width, ch.height, size.0, size.1
            ),
        });
    }
    Ok(ch)
}

/// Decode the bridge's files (each role's path from `file`), encode every requested pass
/// into `staged`, and return the per-object visibility measured on the final mask.
pub(crate) fn write_passes(
    file: BridgeFile,
    scene: &SceneFile,
    passes: &[Pass],
    stem: &str,
    keep_exr: bool,
    staged: &mut Staged,
) -> Result<Vec<ObjectPixels>> {
    let exr_path = file("passes")?;
    let asked = (scene.render.width as usize, scene.render.height as usize);
    let ch = Channels::read_sized(&exr_path, asked)?;
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
    let shadow = match passes.iter().any(|p| p.spec().source == Source::ShadowExr) {
        true => Some(read_shadow_exr(file, "shadow", (ch.width, ch.height))?),
        false => None,
    };
    for &pass in passes {
        let name = layout::pass_file(stem, pass);
        if pass.spec().source == Source::RgbPng {
            let from = file("rgb")?;
            let bytes = std::fs::read(&from).map_err(|e| {
                RenderError::io(
                    "cannot read render output",
                    &from,
                    e,
                    "the Blender worker's temporary folder vanished; rerun",
                )
            })?;
            // Checked from its header as the EXRs are: an image of another size than the one
            // asked for fails the image (`verify` would call the sample broken).
            match clevrtex_dataset::png::size(&bytes) {
                Some(size) if size == (w, h) => {}
                found => {
                    return Err(RenderError::BadOutput {
                        path: from,
                        problem: match found {
                            Some((pw, ph)) => {
                                format!("the RGB image is {pw}x{ph} but the scene asks for {w}x{h}")
                            }
                            None => "the RGB image is not a PNG (no PNG header)".to_string(),
                        },
                    })
                }
            }
            // Blender's timing stamps out: the same pixels give the same bytes.
            staged.write(&name, &post::strip_png_text(&bytes, &from)?)?;
            continue;
        }
        let kind = pass.spec().png;
        let bytes = match encode(pass, &ch, shadow.as_ref(), &ids)? {
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
        if names.len() == 2 {
            staged.copy(&names[1], &file("shadow")?)?;
        }
    }
    Ok(objects)
}
