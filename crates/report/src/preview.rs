//! `clevrtex preview DIR --out sheet.png`: a contact sheet to look at a dataset, one row per
//! sample: RGB, the mask in distinct colours with each object's id at its `pixel_coords`, the
//! mask's outlines over the RGB, depth colour-mapped with a metre scale, normal, albedo and
//! shadow; passes the dataset lacks are left out. Each row is labelled with the stem, variant,
//! split and materials. Works on our layout and on the downloaded ClevrTex (same names).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use clevrtex_dataset::dataset::{self, Kind};
use clevrtex_dataset::layout;
use clevrtex_render::post::{decode_png_bytes, DecodedPng};
use clevrtex_scene::scene_file::MAX_IMAGE_SIDE;
use clevrtex_scene::Pass;
use image::{Rgb, RgbImage};
use plotters::prelude::*;
use serde_json::Value;

/// Which samples to draw and how (the options of `clevrtex preview`).
#[derive(Debug, Clone)]
pub struct Options {
    /// The dataset: an output folder of `clevrtex generate`, a `clevrtex_<variant>` folder, or
    /// the downloaded ClevrTex.
    pub dir: PathBuf,
    /// How many samples (the first N by index), unless `indices` names them.
    pub n: u32,
    /// These image indices.
    pub indices: Vec<u64>,
    /// Only this variant (when `dir` holds several).
    pub variant: Option<String>,
    /// Width of one cell in pixels.
    pub cell: u32,
}

impl Options {
    /// The options for the first `n` samples of `dir` (the report's preview sheet).
    pub fn first(dir: PathBuf, n: u32, cell: u32) -> Options {
        Options {
            dir,
            n,
            indices: Vec::new(),
            variant: None,
            cell,
        }
    }
}

/// A drawn sheet: the image, how many samples, the column titles, whether labels were drawn.
pub struct Sheet {
    /// The sheet.
    pub image: RgbImage,
    /// Rows.
    pub samples: usize,
    /// Column titles, in order.
    pub columns: Vec<&'static str>,
    /// Whether a font was found for the labels.
    pub labelled: bool,
    /// Cells left empty, one line each (`<stem>: <file>: <why>`): a sample whose files cannot
    /// be read, or whose RGB image and mask differ in size, is reported and the sheet goes on.
    pub problems: Vec<String>,
    /// Samples left out, one line each: their metadata cannot be read, parsed or checked
    /// ([`dataset::check_metadata`]).
    pub left_out: Vec<String>,
}

/// Columns of the sheet, in order.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Column {
    Rgb,
    Mask,
    Outlines,
    Depth,
    Normal,
    Albedo,
    Shadow,
}

impl Column {
    fn title(self) -> &'static str {
        match self {
            Column::Rgb => "rgb",
            Column::Mask => "mask (ids)",
            Column::Outlines => "outlines",
            Column::Depth => "depth (m)",
            Column::Normal => "normal",
            Column::Albedo => "albedo",
            Column::Shadow => "shadow",
        }
    }

    /// The pass the column needs.
    fn pass(self) -> Pass {
        match self {
            Column::Rgb => Pass::Rgb,
            Column::Mask | Column::Outlines => Pass::Mask,
            Column::Depth => Pass::Depth,
            Column::Normal => Pass::Normal,
            Column::Albedo => Pass::Albedo,
            Column::Shadow => Pass::Shadow,
        }
    }
}

const ALL: [Column; 7] = [
    Column::Rgb,
    Column::Mask,
    Column::Outlines,
    Column::Depth,
    Column::Normal,
    Column::Albedo,
    Column::Shadow,
];

/// One sample found: stem, folder, metadata.
struct Sample {
    stem: String,
    dir: PathBuf,
    meta: Value,
    /// The dataset's root, canonical: links leading out of it are not followed.
    root: PathBuf,
}

/// The colour of instance id `i`: the mask PNG's own palette (0 = background, black).
fn id_colour(i: u16) -> Rgb<u8> {
    Rgb(clevrtex_render::post::id_colour(i.min(255) as u8))
}

/// A perceptual-ish colour map (dark blue, purple, orange, yellow) of `t` in [0, 1].
fn colour_map(t: f64) -> Rgb<u8> {
    const STOPS: [[f64; 3]; 5] = [
        [13.0, 8.0, 135.0],
        [126.0, 3.0, 168.0],
        [204.0, 71.0, 120.0],
        [248.0, 149.0, 64.0],
        [240.0, 249.0, 33.0],
    ];
    let t = t.clamp(0.0, 1.0) * 4.0;
    let i = (t.floor() as usize).min(3);
    let f = t - i as f64;
    let c = |k: usize| (STOPS[i][k] + (STOPS[i + 1][k] - STOPS[i][k]) * f).round() as u8;
    Rgb([c(0), c(1), c(2)])
}

/// Find the samples to show, in index order. The dataset is walked by its one read side
/// (`clevrtex_dataset::dataset::Dataset::open`): a link out of the dataset, a FIFO or a device
/// is never followed or opened.
fn find_samples(args: &Options) -> anyhow::Result<(Vec<Sample>, Vec<String>)> {
    use clevrtex_dataset::dataset::{Dataset, DatasetError};
    let hint = "hint: pass the `--out` folder of `clevrtex generate`";
    let ds = Dataset::open(&args.dir).map_err(|e| {
        let cause = match e {
            DatasetError::Unreadable { cause, .. } => cause,
            DatasetError::NotAFolder { path } => std::io::Error::new(
                std::io::ErrorKind::NotADirectory,
                format!("`{}` is not a folder", path.display()),
            ),
        };
        anyhow::Error::new(cause).context(format!("cannot read `{}`\n{hint}", args.dir.display()))
    })?;
    let root = ds.root.clone();
    let mut found: Vec<(String, u64, String, PathBuf)> = Vec::new();
    let mut left_out = Vec::new();
    for vd in &ds.variants {
        if let Some((p, e)) = vd.unreadable.iter().find(|(p, _)| *p == vd.dir) {
            return Err(anyhow::anyhow!("{e}").context(format!("cannot read `{}`", p.display())));
        }
        // A sample's metadata not followed (a link out, a FIFO, a folder): said, and left out.
        for skip in vd.skipped_for_metadata().filter(|k| k.stem.is_some()) {
            left_out.push(skip.to_string());
        }
        for s in vd.samples.iter().filter(|s| s.has_metadata()) {
            if args.variant.as_ref().is_none_or(|v| *v == s.variant) {
                found.push((s.variant.clone(), s.index, s.stem.clone(), s.dir.clone()));
            }
        }
    }
    found.sort();
    let wanted: Vec<(String, u64, String, PathBuf)> = if args.indices.is_empty() {
        found.into_iter().take(args.n as usize).collect()
    } else {
        let mut out = Vec::new();
        for i in &args.indices {
            match found.iter().find(|f| f.1 == *i) {
                Some(f) => out.push(f.clone()),
                None => bail!(
                    "no sample with index {i} under `{}`\nhint: pass indices the dataset has (`clevrtex verify` lists them)",
                    args.dir.display()
                ),
            }
        }
        out
    };
    if wanted.is_empty() {
        bail!(
            "no samples (`CLEVRTEX_<variant>_<index>.json`) under `{}`{}\nhint: pass the `--out` folder of `clevrtex generate`",
            args.dir.display(),
            args.variant.as_ref().map(|v| format!(" for variant `{v}`")).unwrap_or_default()
        );
    }
    // A sample whose metadata cannot be read, parsed or checked is said and left out (exit 3);
    // the others are drawn.
    let mut samples = Vec::new();
    for (_, _, stem, dir) in wanted {
        let path = dir.join(layout::metadata_file(&stem));
        let meta = ds
            .read(&path, clevrtex_dataset::dataset::MAX_METADATA_BYTES)
            .and_then(|b| {
                serde_json::from_slice::<Value>(&b)
                    .map_err(|e| format!("is not valid metadata: {e}"))
            })
            .map_err(|why| format!("`{}` {why}", path.display()))
            .and_then(|meta| {
                let file = path.display().to_string();
                dataset::check_metadata(&meta, &file).map_err(|e| {
                    format!("`{file}` is not valid metadata: key `{}` {}", e.key, e.what)
                })?;
                Ok(meta)
            });
        match meta {
            Ok(meta) => samples.push(Sample {
                stem,
                dir,
                meta,
                root: root.clone(),
            }),
            Err(why) => left_out.push(why),
        }
    }
    if samples.is_empty() && !left_out.is_empty() {
        bail!(
            "no sample of `{}` can be drawn:\n  {}\nhint: check the dataset with `clevrtex verify`",
            args.dir.display(),
            left_out.join("\n  ")
        );
    }
    Ok((samples, left_out))
}

/// The file of `pass` of a sample, if it exists.
fn pass_path(s: &Sample, pass: Pass) -> Option<PathBuf> {
    let p = s.dir.join(layout::pass_file(&s.stem, pass));
    (dataset::classify(&s.root, &p) == Kind::File).then_some(p)
}

/// Why the file of `pass` of a sample is not read, when it exists but is a link out of the
/// dataset, a FIFO or a device.
fn pass_skipped(s: &Sample, pass: Pass) -> Option<String> {
    let p = s.dir.join(layout::pass_file(&s.stem, pass));
    match dataset::classify(&s.root, &p) {
        Kind::Skipped(why) if std::fs::symlink_metadata(&p).is_ok() => {
            Some(format!("`{}` {why}", p.display()))
        }
        _ => None,
    }
}

/// Most pixels a pass PNG of a sample may declare (the largest render size).
pub(crate) const MAX_PASS_PIXELS: u64 = (MAX_IMAGE_SIDE as u64) * (MAX_IMAGE_SIDE as u64);

/// The size a PNG declares in its header (`None` when `bytes` do not start like a PNG).
fn png_header_size(bytes: &[u8]) -> Option<(u32, u32)> {
    if bytes.len() < 24 || &bytes[12..16] != b"IHDR" {
        return None;
    }
    let be = |i: usize| u32::from_be_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
    Some((be(16), be(20)))
}

/// Refuse a pass PNG whose header declares more pixels, or a longer side, than a sample's
/// pass may have, before anything is decoded.
fn check_png_size(bytes: &[u8], path: &Path) -> anyhow::Result<()> {
    let Some((w, h)) = png_header_size(bytes) else {
        return Ok(());
    };
    let side = clevrtex_scene::scene_file::MAX_IMAGE_SIDE;
    if u64::from(w) * u64::from(h) > MAX_PASS_PIXELS || w > side || h > side {
        anyhow::bail!(
            "`{}` declares {w}x{h} pixels, more than a sample's pass may have ({side}x{side}): the file is damaged or not clevrtex's; regenerate or re-download the sample",
            path.display()
        );
    }
    Ok(())
}

/// Read and decode a sample's mask or depth PNG under `root` as untrusted data: through the
/// dataset reader (no link out of `root`, no FIFO, capped read), and its size checked from the
/// PNG header before the decoder allocates for it.
/// Its mode is checked from the header too (`dataset::png_mode_problem`): an RGB or 16-bit mask
/// is a named, left-out sample, never ids read from its colour bytes.
pub(crate) fn read_pass_png(root: &Path, path: &Path, pass: Pass) -> anyhow::Result<DecodedPng> {
    let bytes = dataset::read(root, path, dataset::MAX_FILE_BYTES)
        .map_err(|why| anyhow::anyhow!("`{}` {why}", path.display()))?;
    check_png_size(&bytes, path)?;
    if let Some(problem) = dataset::png_mode_problem(&bytes, pass) {
        anyhow::bail!("`{}` {problem}", path.display());
    }
    Ok(decode_png_bytes(&bytes, path)?)
}

/// Read and decode a sample's colour image (RGB, normal, albedo, shadow) under `root` like
/// [`read_pass_png`]: through the dataset reader, its size checked from its header first.
pub(crate) fn read_colour_png(root: &Path, path: &Path) -> anyhow::Result<RgbImage> {
    let bytes = dataset::read(root, path, dataset::MAX_FILE_BYTES)
        .map_err(|why| anyhow::anyhow!("`{}` {why}", path.display()))?;
    check_png_size(&bytes, path)?;
    Ok(image::load_from_memory(&bytes)
        .map_err(|e| anyhow::anyhow!("`{}`: {e}", path.display()))?
        .to_rgb8())
}

/// A cell is at most this many times as tall as it is wide: a sample of another shape (a
/// 1x8192 image, a few hundred bytes) is shrunk into the cell instead of scaled to the
/// cell's width (which took gigabytes).
const MAX_CELL_ASPECT: u32 = 2;

/// Scale `img` to `w` wide, or to `max_h` high if that is less (nearest neighbour: masks stay
/// exact), keeping its aspect.
fn scaled(img: &RgbImage, w: u32, max_h: u32) -> RgbImage {
    let (iw, ih) = (
        u64::from(img.width().max(1)),
        u64::from(img.height().max(1)),
    );
    let (w, max_h) = (u64::from(w), u64::from(max_h));
    let (w, h) = if ih * w / iw <= max_h {
        (w, (ih * w / iw).max(1))
    } else {
        ((iw * max_h / ih).max(1), max_h)
    };
    image::imageops::resize(
        img,
        w as u32,
        h as u32,
        image::imageops::FilterType::Nearest,
    )
}

/// One cell at its native size, and for depth the range drawn in metres (for the scale).
type Cell = (RgbImage, Option<(f64, f64)>);

/// The cell of column `col` of a sample; `None` when the sample lacks the pass.
fn cell(s: &Sample, col: Column) -> anyhow::Result<Option<Cell>> {
    if let Some(why) = pass_skipped(s, col.pass()) {
        anyhow::bail!("{why}");
    }
    let Some(path) = pass_path(s, col.pass()) else {
        // Absent and not listed: the sample lacks the pass. Listed (the metadata's `*_filename`,
        // or the image and mask, which every sample has): missing, or a folder in its place.
        let p = s.dir.join(layout::pass_file(&s.stem, col.pass()));
        let listed = matches!(col.pass(), Pass::Rgb | Pass::Mask)
            || s.meta[col.pass().metadata_key()].is_string();
        if dataset::classify(&s.root, &p) == Kind::Dir {
            anyhow::bail!("`{}` is a folder", p.display());
        }
        if listed {
            anyhow::bail!("`{}` is missing", p.display());
        }
        return Ok(None);
    };
    let to_rgb = |p: &Path| read_colour_png(&s.root, p);
    Ok(Some(match col {
        Column::Rgb | Column::Normal | Column::Albedo | Column::Shadow => (to_rgb(&path)?, None),
        Column::Mask | Column::Outlines => {
            let m = read_pass_png(&s.root, &path, Pass::Mask)?;
            let (w, h) = (m.width, m.height);
            let id = |x: u32, y: u32| m.data[(y * w + x) as usize];
            let mut img = if col == Column::Mask {
                RgbImage::from_fn(w, h, |x, y| id_colour(id(x, y)))
            } else {
                match pass_path(s, Pass::Rgb) {
                    Some(rgb) => {
                        let img = to_rgb(&rgb)?;
                        if img.dimensions() != (w, h) {
                            anyhow::bail!(
                                "`{}` is {}x{} but its mask `{}` is {w}x{h}: the outlines cannot be drawn",
                                rgb.display(),
                                img.width(),
                                img.height(),
                                path.display()
                            );
                        }
                        img
                    }
                    None => RgbImage::new(w, h),
                }
            };
            if col == Column::Outlines {
                for y in 0..h {
                    for x in 0..w {
                        let edge = (x + 1 < w && id(x + 1, y) != id(x, y))
                            || (y + 1 < h && id(x, y + 1) != id(x, y));
                        if edge {
                            img.put_pixel(x, y, Rgb([255, 255, 255]));
                        }
                    }
                }
            }
            (img, None)
        }
        Column::Depth => {
            let d = read_pass_png(&s.root, &path, Pass::Depth)?;
            let enc = &s.meta["passes"]["depth"];
            let scale = enc["scale"].as_f64().unwrap_or(1.0);
            let background = enc["background"].as_u64().unwrap_or(65535) as u16;
            let valid = |v: u16| v != background && v != 0;
            let (lo, hi) = d
                .data
                .iter()
                .filter(|&&v| valid(v))
                .fold((u16::MAX, 0), |(lo, hi), &v| (lo.min(v), hi.max(v)));
            let span = f64::from(hi.saturating_sub(lo)).max(1.0);
            let img = RgbImage::from_fn(d.width, d.height, |x, y| {
                let v = d.data[(y * d.width + x) as usize];
                if valid(v) {
                    colour_map(f64::from(v - lo) / span)
                } else {
                    Rgb([0, 0, 0])
                }
            });
            let range = (hi >= lo).then(|| (f64::from(lo) * scale, f64::from(hi) * scale));
            (img, range)
        }
    }))
}

/// Draw the sheet of `args` (without writing it).
pub fn draw(args: &Options) -> anyhow::Result<Sheet> {
    let (samples, left_out) = find_samples(args)?;
    // Columns: those some chosen sample has.
    let cols: Vec<Column> = ALL
        .into_iter()
        .filter(|c| samples.iter().any(|s| pass_path(s, c.pass()).is_some()))
        .collect();
    let cw = args.cell;
    // The row height from the first sample whose image's header can be read (a damaged one
    // is reported with its cells below, and does not stop the sheet).
    let first = samples
        .iter()
        .filter_map(|s| pass_path(s, Pass::Rgb).or_else(|| pass_path(s, Pass::Mask)))
        .find_map(|p| image::image_dimensions(&p).ok())
        .unwrap_or((4, 3));
    let ch = (u64::from(first.1) * u64::from(cw) / u64::from(first.0.max(1)))
        .clamp(1, u64::from(MAX_CELL_ASPECT * cw)) as u32;
    let (label_h, head_h, bar_w) = (18u32, 20u32, 10u32);
    let width = cols.len() as u32 * (cw + bar_w) + bar_w;
    let height = head_h + samples.len() as u32 * (label_h + ch + 6);
    let mut sheet = RgbImage::from_pixel(width, height, Rgb([24, 24, 24]));
    // Texts to draw, after the images: (x, y, text, size).
    let mut texts: Vec<(i32, i32, String, u32)> = Vec::new();
    let mut problems = Vec::new();
    for (c, col) in cols.iter().enumerate() {
        texts.push((
            (c as u32 * (cw + bar_w) + bar_w) as i32,
            3,
            col.title().into(),
            14,
        ));
    }
    for (r, s) in samples.iter().enumerate() {
        let y0 = head_h + r as u32 * (label_h + ch + 6);
        let materials: Vec<String> = s.meta["objects"]
            .as_array()
            .map(|o| {
                let mut m: Vec<String> = o
                    .iter()
                    .filter_map(|o| o["material"].as_str().map(str::to_string))
                    .collect();
                m.sort();
                m.dedup();
                m
            })
            .unwrap_or_default();
        texts.push((
            bar_w as i32,
            y0 as i32 + 2,
            format!(
                "{}  variant {}  split {}  ground {}  materials {}",
                s.stem,
                s.meta["variant"].as_str().unwrap_or("?"),
                s.meta["split"].as_str().unwrap_or("?"),
                s.meta["ground_material"].as_str().unwrap_or("?"),
                materials.join(", ")
            ),
            12,
        ));
        for (c, col) in cols.iter().enumerate() {
            let x0 = c as u32 * (cw + bar_w) + bar_w;
            let (img, depth_range) = match cell(s, *col) {
                Ok(Some(c)) => c,
                Ok(None) => continue,
                Err(e) => {
                    problems.push(format!("{}: {e:#}", s.stem));
                    continue;
                }
            };
            let (nw, nh) = (img.width(), img.height());
            let img = scaled(&img, cw, ch);
            image::imageops::replace(&mut sheet, &img, i64::from(x0), i64::from(y0 + label_h));
            if *col == Column::Mask {
                if let Some(objs) = s.meta["objects"].as_array() {
                    for (i, o) in objs.iter().enumerate() {
                        let p = &o["pixel_coords"];
                        if let (Some(px), Some(py)) = (p[0].as_f64(), p[1].as_f64()) {
                            let x = x0 as f64 + px * f64::from(img.width()) / f64::from(nw.max(1));
                            let y = f64::from(y0 + label_h)
                                + py * f64::from(img.height()) / f64::from(nh.max(1));
                            texts.push((x as i32 - 4, y as i32 - 6, (i + 1).to_string(), 12));
                        }
                    }
                }
            }
            if let Some((lo, hi)) = depth_range {
                // A vertical scale bar right of the cell: near (top) to far (bottom).
                let bx = x0 + cw + 1;
                for y in 0..img.height() {
                    let t = f64::from(y) / f64::from(img.height().max(2) - 1);
                    for x in bx..bx + bar_w - 2 {
                        sheet.put_pixel(x, y0 + label_h + y, colour_map(t));
                    }
                }
                texts.push((
                    x0 as i32 + 2,
                    (y0 + label_h) as i32 + 1,
                    format!("{lo:.1} m"),
                    11,
                ));
                texts.push((
                    x0 as i32 + 2,
                    (y0 + label_h + img.height()) as i32 - 13,
                    format!("{hi:.1} m"),
                    11,
                ));
            }
        }
    }
    let drew_text = crate::font::available();
    if drew_text {
        let (w, h) = sheet.dimensions();
        let mut buf = sheet.into_raw();
        {
            let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
            for (x, y, t, size) in &texts {
                let style = ("sans-serif", *size).into_font().color(&WHITE);
                root.draw_text(t, &style, (*x, *y))
                    .map_err(|e| anyhow::anyhow!("cannot draw text: {e}"))?;
            }
            root.present()
                .map_err(|e| anyhow::anyhow!("cannot draw text: {e}"))?;
        }
        sheet = RgbImage::from_raw(w, h, buf).expect("same size");
    }
    Ok(Sheet {
        image: sheet,
        samples: samples.len(),
        columns: cols.iter().map(|c| c.title()).collect(),
        labelled: drew_text,
        problems,
        left_out,
    })
}

/// Write a sheet to `out` as PNG, with the one atomic writer ([`clevrtex_dataset::atomic`]).
pub fn save(sheet: &RgbImage, out: &Path) -> anyhow::Result<()> {
    let mut png = Vec::new();
    sheet
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .context("cannot encode the sheet as PNG")?;
    // A missing folder on the way is made, as every other writer of an `--out` makes it.
    if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).with_context(|| {
            format!(
                "cannot create the folder `{}`\nhint: pass a writable place with `--out`",
                parent.display()
            )
        })?;
    }
    clevrtex_dataset::atomic::write(out, &png)
        .with_context(|| format!("cannot write `{}`", out.display()))
}
