//! `clevrtex._native`: the Rust half of the Python package `clevrtex` (the Python half, in
//! `python/clevrtex/`, turns torch tensors into numpy arrays, brings other dtypes and layouts
//! to ones read here, and keeps the running statistics). Numpy arrays are read in place, not
//! copied; scoring and decoding run with the GIL released, in parallel over images.

use std::path::Path;

use clevrtex_eval::dataset::discover_gt;
use clevrtex_eval::error::MAX_SLOTS;
use clevrtex_eval::metrics::squared_errors;
use clevrtex_eval::predict::argmax_by;
use clevrtex_eval::resize::{crop_box, crop_resize_bilinear_rgb, crop_resize_nearest};
use clevrtex_eval::{read, score_image, EvalError, Metric, Split};
use clevrtex_scene::Pass;
use numpy::{PyReadonlyArray, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyBytes;
use rayon::prelude::*;

fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

fn eval_error(e: EvalError) -> PyErr {
    match e {
        EvalError::Io { .. } => PyOSError::new_err(e.to_string()),
        other => value_error(other),
    }
}

/// Soft masks or images: `(batch, channels, pixels)` float32 or float64, C-contiguous.
#[derive(FromPyObject)]
enum Floats<'py> {
    F32(PyReadonlyArray3<'py, f32>),
    F64(PyReadonlyArray3<'py, f64>),
}

/// The numpy memory of a [`Floats`] array, borrowed without a copy.
#[derive(Clone, Copy)]
enum FloatSlice<'a> {
    F32(&'a [f32]),
    F64(&'a [f64]),
}

/// Predictions: segment ids or soft masks.
#[derive(FromPyObject)]
enum Pred<'py> {
    Ids(Ids<'py>),
    Masks(Floats<'py>),
}

/// The C-order slice of a numpy array (`as_slice` also takes Fortran order, read wrongly here).
fn c_slice<'a, T: numpy::Element, D: numpy::ndarray::Dimension>(
    a: &'a PyReadonlyArray<'_, T, D>,
) -> PyResult<(&'a [T], Vec<usize>)> {
    let shape = a.shape().to_vec();
    match a.as_slice() {
        Ok(s) if a.is_c_contiguous() => Ok((s, shape)),
        _ => Err(value_error("internal: an array is not C-contiguous")),
    }
}

impl<'py> Floats<'py> {
    fn slice(&self) -> PyResult<(FloatSlice<'_>, Vec<usize>)> {
        Ok(match self {
            Floats::F32(a) => c_slice(a).map(|(s, d)| (FloatSlice::F32(s), d))?,
            Floats::F64(a) => c_slice(a).map(|(s, d)| (FloatSlice::F64(s), d))?,
        })
    }
}

/// Defines, for each (variant, integer type), the segment-id arrays as numpy hands them over
/// ([`Ids`]), their borrowed memory ([`IdSlice`]) and the dispatch between the two, so the list
/// of id dtypes is written once.
macro_rules! ids {
    ($($v:ident($t:ty)),*) => {
        /// Segment ids as numpy hands them over: `(batch, pixels)`, C-contiguous, any integer
        /// dtype (the Python half converts everything else: bools, integral floats, other byte
        /// orders).
        #[derive(FromPyObject)]
        enum Ids<'py> {
            $($v(PyReadonlyArray2<'py, $t>),)*
        }

        /// The numpy memory of an [`Ids`] array, borrowed without a copy (`Send`, so the
        /// scoring can read it with the GIL released).
        #[derive(Clone, Copy)]
        enum IdSlice<'a> {
            $($v(&'a [$t]),)*
        }

        impl<'py> Ids<'py> {
            fn slice(&self) -> PyResult<(IdSlice<'_>, Vec<usize>)> {
                Ok(match self {
                    $(Ids::$v(a) => c_slice(a).map(|(s, d)| (IdSlice::$v(s), d))?,)*
                })
            }
        }

        impl IdSlice<'_> {
            /// Ids `range` as `u32` labels, or `None` when one lies outside `0..MAX_SLOTS`.
            fn labels(self, range: std::ops::Range<usize>) -> Option<Vec<u32>> {
                match self {
                    $(IdSlice::$v(v) => labels(&v[range]),)*
                }
            }

            /// Smallest and largest id, for the message when one is out of range.
            fn min_max(self) -> Option<(i128, i128)> {
                match self {
                    $(IdSlice::$v(v) => min_max(v),)*
                }
            }
        }

        $(impl Id for $t {
            #[inline(always)]
            fn wide(self) -> u64 {
                self as u64
            }
        })*
    };
}
ids!(
    U8(u8),
    U16(u16),
    U32(u32),
    U64(u64),
    I8(i8),
    I16(i16),
    I32(i32),
    I64(i64)
);

/// An integer segment id type.
trait Id: Copy + Ord + Into<i128> {
    /// The id as `u64`; a negative id wraps to a huge one, so one comparison checks the range.
    fn wide(self) -> u64;
}

/// Ids as `u32` labels, or `None` when one lies outside `0..MAX_SLOTS`.
fn labels<T: Id>(v: &[T]) -> Option<Vec<u32>> {
    const { assert!(MAX_SLOTS.is_power_of_two()) };
    // Any bit at or above MAX_SLOTS's is out of range; OR-ing them vectorises (a flag set per
    // id in the conversion loop does not).
    let high = v.iter().fold(0u64, |acc, &x| {
        acc | (x.wide() >> MAX_SLOTS.trailing_zeros())
    });
    (high == 0).then(|| v.iter().map(|&x| x.wide() as u32).collect())
}

/// Smallest and largest id of `v` (`None` when empty).
fn min_max<T: Id>(v: &[T]) -> Option<(i128, i128)> {
    let lo = v.iter().copied().min()?;
    let hi = v.iter().copied().max()?;
    Some((lo.into(), hi.into()))
}

impl IdSlice<'_> {
    /// Every image's labels (`batch` images of `pixels`), or the error naming `what` and the
    /// offending id when one lies outside `0..MAX_SLOTS`.
    fn batch_labels(self, batch: usize, pixels: usize, what: &str) -> PyResult<Vec<Vec<u32>>> {
        let per: Option<Vec<Vec<u32>>> = (0..batch)
            .into_par_iter()
            .map(|b| self.labels(b * pixels..(b + 1) * pixels))
            .collect();
        per.ok_or_else(|| {
            let (lo, hi) = self.min_max().unwrap_or((0, 0));
            let bad = if lo < 0 { lo } else { hi };
            value_error(format!(
                "`{what}` holds segment id `{bad}`, outside 0..{MAX_SLOTS}"
            ))
        })
    }
}

/// A soft-mask or image value, read as `f32` (a float64 rounds to nearest, as numpy's
/// `astype(float32)`, so both dtypes score alike).
trait Value: Copy {
    fn f32(self) -> f32;
}

impl Value for f32 {
    #[inline(always)]
    fn f32(self) -> f32 {
        self
    }
}

impl Value for f64 {
    #[inline(always)]
    fn f32(self) -> f32 {
        self as f32
    }
}

/// The argmax over `k` soft masks `m` (`(k, n)`) of one image, eval's kernel
/// ([`argmax_by`]) with every value compared as `f32`.
fn argmax<T: Value>(m: &[T], k: usize, n: usize, no_background: bool) -> Vec<u32> {
    argmax_by(m, k, n, no_background, T::f32)
}

/// Per true label, the squared error of `pred` against `truth` images (`(3, pixels)` each,
/// planar), and the total: eval's kernel ([`squared_errors`]; difference and square in f32,
/// sums in f64 in pixel order; docs/eval.md).
fn squared_error<T: Value>(t: &[u32], tr: &[T], pr: &[T], slots: usize) -> (Vec<f64>, f64) {
    let pixels = t.len();
    let (total, per_true) = squared_errors(t, slots, |start, e| {
        for c in 0..3 {
            let range = c * pixels + start..c * pixels + start + e.len();
            for ((e, p), t) in e.iter_mut().zip(&pr[range.clone()]).zip(&tr[range]) {
                let d = p.f32() - t.f32();
                *e += (d * d) as f64;
            }
        }
    });
    (per_true, total)
}

/// One image's scores: every metric (indexed like `metric_names()`), the matched IoU and size
/// of each true slot, and each true slot's squared error when images were given.
type ImageOut = (Vec<Option<f64>>, Vec<f64>, Vec<u64>, Option<Vec<f64>>);

/// Score a batch, reading the numpy arrays in place. `truth`: `(batch, pixels)` integer ids.
/// `pred`: `(batch, pixels)` ids, or `(batch, K, pixels)` float32/float64 soft masks (argmax,
/// first index on ties, NaN the maximum; `no_background` puts `1 - sum` in front).
/// `min_slots`: the matching's size at least (the public evaluator pads both sides to
/// `max(true slots, predicted slots)`); with `pad_to_truth`, at least the batch's largest true
/// id + 1 too. `true_rgb` / `pred_rgb`: `(batch, 3, pixels)` floats (planar, as torch holds
/// them) for the MSE. `truth_name`, `pred_name`: what to call them in an error.
#[pyfunction]
#[pyo3(signature = (truth, pred, no_background, min_slots, pad_to_truth, true_rgb=None, pred_rgb=None, truth_name="true_masks", pred_name="pred"))]
#[allow(clippy::too_many_arguments)]
fn score(
    py: Python<'_>,
    truth: Ids<'_>,
    pred: Pred<'_>,
    no_background: bool,
    min_slots: usize,
    pad_to_truth: bool,
    true_rgb: Option<Floats<'_>>,
    pred_rgb: Option<Floats<'_>>,
    truth_name: &str,
    pred_name: &str,
) -> PyResult<Vec<ImageOut>> {
    let (t, t_shape) = truth.slice()?;
    let (batch, pixels) = (t_shape[0], t_shape[1]);
    let (p_ids, p_masks) = match &pred {
        Pred::Ids(ids) => {
            let (p, shape) = ids.slice()?;
            if shape != t_shape {
                return Err(value_error("internal: `pred` does not fit `truth`"));
            }
            (Some(p), None)
        }
        Pred::Masks(m) => {
            let (m, shape) = m.slice()?;
            if (shape[0], shape[2]) != (batch, pixels) {
                return Err(value_error("internal: the masks do not fit `truth`"));
            }
            (None, Some((m, shape[1])))
        }
    };
    fn rgb<'a>(x: &'a Option<Floats<'_>>, fit: [usize; 3]) -> PyResult<Option<FloatSlice<'a>>> {
        let Some(x) = x else { return Ok(None) };
        let (s, shape) = x.slice()?;
        if shape != fit {
            return Err(value_error("internal: the images do not fit the masks"));
        }
        Ok(Some(s))
    }
    let fit = [batch, 3, pixels];
    let images = match (rgb(&true_rgb, fit)?, rgb(&pred_rgb, fit)?) {
        (Some(FloatSlice::F32(t)), Some(FloatSlice::F32(p))) => Some(Rgb::F32(t, p)),
        (Some(FloatSlice::F64(t)), Some(FloatSlice::F64(p))) => Some(Rgb::F64(t, p)),
        (None, None) => None,
        _ => return Err(value_error("internal: the images differ in dtype")),
    };
    let out = py.allow_threads(|| -> PyResult<Vec<ImageOut>> {
        let truth = t.batch_labels(batch, pixels, truth_name)?;
        let pred = match p_ids {
            Some(p) => Some(p.batch_labels(batch, pixels, pred_name)?),
            None => None,
        };
        let slots = if pad_to_truth {
            let max = truth.iter().filter_map(|t| t.iter().max()).max();
            min_slots.max(max.map_or(1, |&m| m as usize + 1))
        } else {
            min_slots
        };
        Ok(truth
            .par_iter()
            .enumerate()
            .map(|(b, t)| {
                let (p, pred_slots) = match (&pred, p_masks) {
                    (Some(pred), _) => {
                        let p = &pred[b];
                        (
                            std::borrow::Cow::Borrowed(p),
                            p.iter().max().map_or(1, |&m| m as usize + 1),
                        )
                    }
                    (None, Some((m, k))) => {
                        let r = b * k * pixels..(b + 1) * k * pixels;
                        let labels = match m {
                            FloatSlice::F32(m) => argmax(&m[r], k, pixels, no_background),
                            FloatSlice::F64(m) => argmax(&m[r], k, pixels, no_background),
                        };
                        (
                            std::borrow::Cow::Owned(labels),
                            k + usize::from(no_background),
                        )
                    }
                    (None, None) => unreachable!("predictions are ids or masks"),
                };
                let mut s = score_image(t, &p, pred_slots.max(slots), None);
                let mut sq = None;
                if let Some(images) = images {
                    let r = 3 * b * pixels..3 * (b + 1) * pixels;
                    let k = s.true_sizes.len();
                    let (per_true, total) = match images {
                        Rgb::F32(tr, pr) => squared_error(t, &tr[r.clone()], &pr[r], k),
                        Rgb::F64(tr, pr) => squared_error(t, &tr[r.clone()], &pr[r], k),
                    };
                    s.values[Metric::Mse.index()] = total.is_finite().then_some(total);
                    sq = Some(per_true);
                }
                (s.values.to_vec(), s.iou_per_true, s.true_sizes, sq)
            })
            .collect())
    })?;
    Ok(out)
}

/// The true and predicted images of a batch, of one dtype.
#[derive(Clone, Copy)]
enum Rgb<'a> {
    F32(&'a [f32], &'a [f32]),
    F64(&'a [f64], &'a [f64]),
}

/// The names of every metric, in the order `score` returns them.
#[pyfunction]
fn metric_names() -> Vec<&'static str> {
    Metric::ALL.iter().map(|m| m.name()).collect()
}

/// The default metrics of a protocol.
#[pyfunction]
fn protocol_metrics(protocol: &str) -> PyResult<Vec<&'static str>> {
    let p = clevrtex_eval::Protocol::from_name(protocol).ok_or_else(|| {
        value_error(format!(
            "unknown protocol `{protocol}`; known: clevrtex, native, deepmind, ocl"
        ))
    })?;
    Ok(p.default_metrics().iter().map(|m| m.name()).collect())
}

/// The samples of a dataset in the published layout: `(variant, [(index, image, mask, meta)])`
/// for one split (`test`, `val`, `train`, `all`; test-only variants have `test` = all).
#[pyfunction]
#[pyo3(signature = (path, variant=None, split="test"))]
#[allow(clippy::type_complexity)]
fn discover(
    py: Python<'_>,
    path: &str,
    variant: Option<&str>,
    split: &str,
) -> PyResult<(String, Vec<(u64, String, String, String)>)> {
    let split = match split {
        "test" => Split::Test,
        "val" => Split::Val,
        "train" => Split::Train,
        "all" => Split::All,
        other => {
            return Err(value_error(format!(
                "unknown split `{other}`; known: test, val, train, all"
            )))
        }
    };
    py.allow_threads(|| {
        let (variant, mut samples) = discover_gt(Path::new(path), variant).map_err(eval_error)?;
        // As the public loader: a test-only variant is read whole, whatever the split.
        let split = if is_test_only(&variant) {
            Split::All
        } else {
            split
        };
        // Each sample's split is the one its metadata records (the one rule of every reader,
        // `clevrtex_dataset::dataset::splits`); an empty split is an error naming the sizes.
        if split.part().is_some() {
            clevrtex_eval::dataset::read_splits(Path::new(path), &variant, &mut samples)
                .map_err(eval_error)?;
        }
        let chosen = split.select(&samples, &variant).map_err(eval_error)?;
        if chosen.is_empty() {
            return Err(value_error(format!(
                "the `{}` split of `{path}` is empty: it has {} samples in all ({})\nhint: pick a split that has samples, or `split=\"all\"`",
                split.name(),
                samples.len(),
                clevrtex_eval::dataset::split_sizes(&samples)
            )));
        }
        let s = |p: &Path| p.display().to_string();
        let list = chosen
            .iter()
            .map(|x| (x.index, s(&x.image), s(&x.mask), s(&x.meta)))
            .collect();
        Ok((variant, list))
    })
}

/// Whether a variant's objects are plain-coloured, so that its metadata and results carry
/// their colour (the variant config's property, `Config::colour_breakdown`: `vbg`, `clevr`).
#[pyfunction]
fn colour_breakdown(variant: &str) -> bool {
    clevrtex_dataset::layout::variant_colour_breakdown(variant)
}

/// A variant with only a test split (its config says `"splits": "test_only"`, e.g. `outd`).
fn is_test_only(variant: &str) -> bool {
    clevrtex_dataset::layout::variant_splits(variant) == clevrtex_scene::config::Splits::TestOnly
}

/// The largest `resize` side (the largest image a dataset has).
const MAX_SIDE: usize = clevrtex_scene::scene_file::MAX_IMAGE_SIDE as usize;

/// Why a file of the dataset was not read, as the Python exception of its kind: `OSError` of
/// its errno (`FileNotFoundError`, `PermissionError`, ...) when it cannot be opened, else
/// `ValueError`; the message names the file.
fn read_error(path: &str, e: clevrtex_dataset::dataset::ReadError) -> PyErr {
    use clevrtex_dataset::dataset::ReadError;
    match e {
        // OSError(errno, message, filename) is the subclass of its errno.
        ReadError::Io(e) => PyOSError::new_err((
            e.raw_os_error().unwrap_or(0),
            format!("`{path}` cannot be read: {e}"),
            path.to_string(),
        )),
        other => value_error(format!(
            "`{path}` {}; not read",
            other.to_string().trim_end_matches("; skipped")
        )),
    }
}

/// The bytes of the dataset's file `p`, read by the dataset reader (`clevrtex_dataset::dataset`):
/// a regular file only (a FIFO never blocks), at most `cap` bytes, and, with `root` (the
/// dataset's canonical folder), not a link swapped in that leads out of the dataset.
fn read_checked(root: Option<&Path>, p: &str, cap: u64) -> PyResult<Vec<u8>> {
    use clevrtex_dataset::dataset::{classify, read_beneath, read_regular, Kind};
    if let Some(root) = root {
        if let Kind::Skipped(why) = classify(root, Path::new(p)) {
            if !why.starts_with("cannot be read") {
                return Err(value_error(format!(
                    "`{p}` {}",
                    why.replace("; skipped", "; not read")
                )));
            }
        }
    }
    match root {
        // Opened relative to the root's handle: a folder swapped for a link out of the dataset
        // since `discover` is not read through.
        Some(root) => read_beneath(root, Path::new(p), cap),
        None => read_regular(Path::new(p), cap),
    }
    .map_err(|e| read_error(p, e))
}

/// The dataset's folder, resolved (links inside it are followed, none out of it).
fn canonical_root(root: Option<&str>) -> PyResult<Option<std::path::PathBuf>> {
    root.map(|r| {
        Path::new(r)
            .canonicalize()
            .map_err(|e| PyOSError::new_err(format!("`{r}` cannot be read: {e}")))
    })
    .transpose()
}

/// A dataset's PNG, its header's size checked before it is decoded (a 1 MB mask can declare
/// 30000x30000: 4.5 GB decoded).
fn dataset_png(root: Option<&Path>, p: &str) -> PyResult<Vec<u8>> {
    let bytes = read_checked(root, p, clevrtex_dataset::dataset::MAX_FILE_BYTES)?;
    read::png_size_of_dataset_image(&bytes)
        .map_err(|r| value_error(format!("cannot decode `{p}`: {r}")))?;
    Ok(bytes)
}

/// The RGB image and the mask of a sample, cropped and resized: `(rgb, labels, h, w, W, H)`
/// (`W`, `H`: the files' own size).
type Pair = (Vec<u8>, Vec<u32>, usize, usize, usize, usize);

fn load_pair(
    root: Option<&Path>,
    image: &str,
    mask: &str,
    crop: bool,
    side: Option<usize>,
) -> PyResult<Pair> {
    let img = read::png_rgb(&dataset_png(root, image)?)
        .map_err(|r| value_error(format!("cannot decode `{image}`: {r}")))?;
    let mask_bytes = dataset_png(root, mask)?;
    if let Some(problem) =
        clevrtex_dataset::dataset::png_mode_problem(&mask_bytes, clevrtex_scene::Pass::Mask)
    {
        return Err(value_error(format!("`{mask}` {problem}")));
    }
    let msk = read::png_labels(&mask_bytes)
        .map_err(|r| value_error(format!("cannot decode `{mask}`: {r}")))?;
    let (w, h) = (img.width, img.height);
    if (msk.width, msk.height) != (w, h) {
        return Err(value_error(format!(
            "`{image}` is {w}x{h} but its mask is {}x{}",
            msk.width, msk.height
        )));
    }
    match (crop, side) {
        (false, None) => Ok((img.rgb, msk.labels, h, w, w, h)),
        (true, side) => {
            let side = side.unwrap_or_else(|| crop_box(w, h).2);
            let rgb = crop_resize_bilinear_rgb(&img.rgb, w, h, side);
            let labels = crop_resize_nearest(&msk.labels, w, h, side);
            match (rgb, labels) {
                (Some(r), Some(l)) => Ok((r, l, side, side, w, h)),
                _ => Err(value_error(format!("`{image}` is too small to crop"))),
            }
        }
        (false, Some(_)) => Err(value_error(
            "resizing without the crop is not supported: pass crop=True or resize=None",
        )),
    }
}

fn check_side(side: Option<usize>) -> PyResult<()> {
    if let Some(s) = side.filter(|&s| s == 0 || s > MAX_SIDE) {
        return Err(value_error(format!(
            "`resize` side {s} is outside 1..{MAX_SIDE} (the benchmark's is 128)"
        )));
    }
    Ok(())
}

/// Read one sample as the public `CLEVRTEX` loader does: `(rgb, labels, height, width)` with
/// `rgb` 8-bit interleaved and `labels` little-endian u32; with `crop`, the centre square of
/// side `int(0.8 min(W, H))`; resized to `side` (Pillow-exact bilinear for the image, nearest
/// for the mask), or kept at the crop's size when `side` is `None`. With `root` (the dataset's
/// folder), each file is checked again against it when read: a link swapped in after the
/// `Dataset` was made that leads out of the dataset is not followed (ValueError).
#[pyfunction]
#[pyo3(signature = (image, mask, crop=true, side=Some(128), root=None))]
fn load_sample<'py>(
    py: Python<'py>,
    image: &str,
    mask: &str,
    crop: bool,
    side: Option<usize>,
    root: Option<&str>,
) -> PyResult<(Bound<'py, PyBytes>, Bound<'py, PyBytes>, usize, usize)> {
    check_side(side)?;
    let (rgb, labels, h, w, _, _) = py.allow_threads(|| {
        let root = canonical_root(root)?;
        load_pair(root.as_deref(), image, mask, crop, side)
    })?;
    let lb: Vec<u8> = labels.iter().flat_map(|v| v.to_le_bytes()).collect();
    Ok((PyBytes::new(py, &rgb), PyBytes::new(py, &lb), h, w))
}

/// One optional pass of a sample decoded to its quantity, `(C, H, W)` float32 planar
/// (docs/python.md): `depth` metres (background `+inf`), `normal` the unit vector in world
/// space (background 0), `albedo` and `shadow` in 0..1. Depth, normal and shadow are data
/// (one point per pixel): cropped and resized nearest, like the mask; albedo is a colour:
/// bilinear, like the image. The PNG's layout must be the pass table's and its size the image's.
fn decode_pass(
    pass: Pass,
    p: &str,
    bytes: &[u8],
    (w, h): (usize, usize),
    crop: bool,
    side: Option<usize>,
) -> PyResult<(Vec<f32>, usize)> {
    use clevrtex_scene::passes::{PngKind, DEPTH_BACKGROUND, DEPTH_SCALE_M, NORMAL_BACKGROUND};
    let img =
        read::png_samples(bytes).map_err(|r| value_error(format!("cannot decode `{p}`: {r}")))?;
    let (channels, bits) = match pass.spec().png {
        PngKind::Gray8 => (1, 8),
        PngKind::Gray16 => (1, 16),
        PngKind::Rgb8 => (3, 8),
        PngKind::Rgb16 => (3, 16),
        PngKind::Palette8 => {
            return Err(value_error(format!(
                "internal: `{}` is not an optional pass",
                pass.name()
            )))
        }
    };
    if (img.channels, img.bits) != (channels, bits) {
        let kind = |c: usize, b: u8| format!("{b}-bit {}", if c == 1 { "grey" } else { "RGB" });
        return Err(value_error(format!(
            "`{p}` is a {} PNG, but the {} pass is {}",
            kind(img.channels, img.bits),
            pass.name(),
            kind(channels, bits)
        )));
    }
    if (img.width, img.height) != (w, h) {
        return Err(value_error(format!(
            "`{p}` is {}x{} but its image is {w}x{h}",
            img.width, img.height
        )));
    }
    let out_side = if crop {
        Some(side.unwrap_or_else(|| crop_box(w, h).2))
    } else {
        None
    };
    let n_out = out_side.map_or(w * h, |s| s * s);
    let small = || value_error(format!("`{p}` is too small to crop"));
    // Albedo: 8-bit RGB resized as the image is (Pillow's bilinear).
    if pass == Pass::Albedo {
        let rgb: Vec<u8> = img.samples.iter().map(|&v| v as u8).collect();
        let rgb = match out_side {
            Some(s) => crop_resize_bilinear_rgb(&rgb, w, h, s).ok_or_else(small)?,
            None => rgb,
        };
        let mut out = vec![0f32; 3 * n_out];
        for (i, px) in rgb.chunks_exact(3).enumerate() {
            for c in 0..3 {
                out[c * n_out + i] = f32::from(px[c]) / 255.0;
            }
        }
        return Ok((out, 3));
    }
    // The others: nearest, one channel plane at a time.
    let mut planes = Vec::with_capacity(channels);
    for c in 0..channels {
        let plane: Vec<u32> = img
            .samples
            .iter()
            .skip(c)
            .step_by(channels)
            .map(|&v| u32::from(v))
            .collect();
        planes.push(match out_side {
            Some(s) => crop_resize_nearest(&plane, w, h, s).ok_or_else(small)?,
            None => plane,
        });
    }
    let out = match pass {
        Pass::Depth => planes[0]
            .iter()
            .map(|&v| {
                if v == u32::from(DEPTH_BACKGROUND) {
                    f32::INFINITY
                } else {
                    (f64::from(v) * DEPTH_SCALE_M) as f32
                }
            })
            .collect(),
        Pass::Normal => {
            let mut out = vec![0f32; 3 * n_out];
            let bg = NORMAL_BACKGROUND.map(u32::from);
            for i in 0..n_out {
                let v = [planes[0][i], planes[1][i], planes[2][i]];
                if v != bg {
                    for c in 0..3 {
                        out[c * n_out + i] = (f64::from(v[c]) / 65535.0 * 2.0 - 1.0) as f32;
                    }
                }
            }
            out
        }
        _ => planes[0].iter().map(|&v| v as f32 / 255.0).collect(),
    };
    Ok((out, channels))
}

/// A decoded optional pass: its name, float32 bytes (native order) and channels.
type PassOut<'py> = (String, Bound<'py, PyBytes>, usize);

/// What [`load_item`] returns: `(rgb, labels, h, w, (W, H), passes)`, `(W, H)` the files' own
/// size.
type Item<'py> = (
    Bound<'py, PyBytes>,
    Bound<'py, PyBytes>,
    usize,
    usize,
    (usize, usize),
    Vec<PassOut<'py>>,
);

/// [`load_sample`] and the sample's optional passes `passes` (`(name, path)`: `depth`,
/// `normal`, `albedo`, `shadow`), each decoded by [`decode_pass`] to `(C, H, W)` float32 of
/// the image's output size: `(rgb, labels, h, w, (W, H), [(name, bytes, channels)])` (`W`, `H`:
/// the files' own size). Every file is
/// read by the dataset reader (checked against `root`, capped, never a FIFO); a missing file
/// is `FileNotFoundError` naming it.
#[pyfunction]
#[pyo3(signature = (image, mask, passes, crop=true, side=Some(128), root=None))]
fn load_item<'py>(
    py: Python<'py>,
    image: &str,
    mask: &str,
    passes: Vec<(String, String)>,
    crop: bool,
    side: Option<usize>,
    root: Option<&str>,
) -> PyResult<Item<'py>> {
    check_side(side)?;
    let mut wanted = Vec::with_capacity(passes.len());
    for (name, path) in &passes {
        match Pass::from_name(name) {
            Some(p @ (Pass::Depth | Pass::Normal | Pass::Albedo | Pass::Shadow)) => {
                wanted.push((p, path.as_str()))
            }
            _ => {
                return Err(value_error(format!(
                    "unknown pass `{name}`; known: depth, normal, albedo, shadow"
                )))
            }
        }
    }
    let (rgb, labels, h, w, size, decoded) = py.allow_threads(|| -> PyResult<_> {
        let root = canonical_root(root)?;
        let (rgb, labels, h, w, fw, fh) = load_pair(root.as_deref(), image, mask, crop, side)?;
        let mut decoded = Vec::with_capacity(wanted.len());
        for &(pass, p) in &wanted {
            let bytes = dataset_png(root.as_deref(), p)?;
            decoded.push((pass, decode_pass(pass, p, &bytes, (fw, fh), crop, side)?));
        }
        Ok((rgb, labels, h, w, (fw, fh), decoded))
    })?;
    let lb: Vec<u8> = labels.iter().flat_map(|v| v.to_le_bytes()).collect();
    let out = decoded
        .into_iter()
        .map(|(pass, (v, c))| {
            let bytes: Vec<u8> = v.iter().flat_map(|x| x.to_ne_bytes()).collect();
            (pass.name().to_string(), PyBytes::new(py, &bytes), c)
        })
        .collect();
    Ok((
        PyBytes::new(py, &rgb),
        PyBytes::new(py, &lb),
        h,
        w,
        size,
        out,
    ))
}

/// Every pass's file suffix after the stem (`<stem><suffix>.png`) and metadata key, from the
/// pass table: `{name: (suffix, metadata_key)}`.
#[pyfunction]
fn pass_files() -> Vec<(&'static str, &'static str, &'static str)> {
    Pass::ALL
        .iter()
        .map(|p| (p.name(), p.spec().file_suffix, p.metadata_key()))
        .collect()
}

/// The name tables of a built-in variant's config (`None` for another variant), for ids a
/// model can use: `(shapes, sizes as (name, scale), materials of objects and ground, colours)`,
/// in the config's order (materials sorted).
#[pyfunction]
#[allow(clippy::type_complexity)]
fn variant_names(
    variant: &str,
) -> Option<(Vec<String>, Vec<(String, f64)>, Vec<String>, Vec<String>)> {
    let c = clevrtex_scene::config::Config::builtin(variant).ok()?;
    let mut materials: Vec<String> = c.objects.materials.clone();
    materials.extend(c.background.materials.iter().cloned());
    materials.sort();
    materials.dedup();
    Some((
        c.objects.shapes.clone(),
        c.objects
            .sizes
            .iter()
            .map(|s| (s.name.clone(), s.scale))
            .collect(),
        materials,
        c.objects.colors.iter().map(|c| c.name.clone()).collect(),
    ))
}

/// The extension module.
/// A sample's metadata, read as every reader of a dataset reads it
/// (`clevrtex_dataset::dataset`): checked again when read, so that a link swapped in after
/// `discover` that leads out of the dataset `root` is not followed; a regular file opened
/// non-blocking, at most 64 MiB. `ValueError` naming the file when it is not read, `OSError`
/// (its subclass by errno: `FileNotFoundError`, `PermissionError`) when it cannot be opened.
#[pyfunction]
fn read_metadata<'py>(py: Python<'py>, path: &str, root: &str) -> PyResult<Bound<'py, PyBytes>> {
    use clevrtex_dataset::dataset::{classify, read_beneath, Kind, ReadError};
    let p = Path::new(path);
    let read = py.allow_threads(|| {
        let root = Path::new(root).canonicalize().map_err(ReadError::Io)?;
        if let Kind::Skipped(why) = classify(&root, p) {
            if !why.starts_with("cannot be read") {
                return Ok(Err(why.replace("; skipped", "; not read")));
            }
        }
        // Opened relative to the root's handle: a folder on the way swapped for a link out of
        // the dataset is not read through.
        match read_beneath(&root, p, clevrtex_eval::dataset::MAX_METADATA_BYTES) {
            Err(ReadError::LeadsOut) => Ok(Err(ReadError::LeadsOut.to_string())),
            r => r.map(Ok),
        }
    });
    match read {
        Ok(Ok(bytes)) => Ok(PyBytes::new(py, &bytes)),
        Ok(Err(why)) => Err(value_error(format!("`{path}` {why}"))),
        // OSError(errno, message, filename) is the subclass of its errno.
        Err(ReadError::Io(e)) => Err(PyOSError::new_err((
            e.raw_os_error().unwrap_or(0),
            format!("`{path}` cannot be read: {e}"),
            path.to_string(),
        ))),
        Err(ReadError::NotRegular) => Err(value_error(format!(
            "`{path}` is not a regular file (a FIFO, socket or device); not read"
        ))),
        Err(e @ ReadError::LeadsOut) => Err(value_error(format!("`{path}` {e}"))),
        Err(ReadError::TooLarge { len, cap }) => Err(value_error(format!(
            "`{path}` {}, over the {cap} bytes read of a sample's metadata; not read",
            len.map_or("grew".to_string(), |n| format!("is {n} bytes"))
        ))),
    }
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(score, m)?)?;
    m.add_function(wrap_pyfunction!(metric_names, m)?)?;
    m.add_function(wrap_pyfunction!(protocol_metrics, m)?)?;
    m.add_function(wrap_pyfunction!(discover, m)?)?;
    m.add_function(wrap_pyfunction!(colour_breakdown, m)?)?;
    m.add_function(wrap_pyfunction!(load_sample, m)?)?;
    m.add_function(wrap_pyfunction!(read_metadata, m)?)?;
    m.add_function(wrap_pyfunction!(load_item, m)?)?;
    m.add_function(wrap_pyfunction!(pass_files, m)?)?;
    m.add_function(wrap_pyfunction!(variant_names, m)?)?;
    Ok(())
}
