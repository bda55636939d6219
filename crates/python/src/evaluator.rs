//! The scoring behind `Evaluator` and `evaluate`: numpy arrays read in place (segment ids of
//! any integer dtype, float32/float64 soft masks and images) and scored with eval's kernels,
//! the GIL released, in parallel over images.

use clevrtex_eval::error::MAX_SLOTS;
use clevrtex_eval::metrics::squared_errors;
use clevrtex_eval::predict::argmax_by;
use clevrtex_eval::{score_image, Metric};
use numpy::{PyReadonlyArray, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::prelude::*;
use rayon::prelude::*;

use crate::errors::value_error;

/// Soft masks or images: `(batch, channels, pixels)` float32 or float64, C-contiguous.
#[derive(FromPyObject)]
pub(crate) enum Floats<'py> {
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
pub(crate) enum Pred<'py> {
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
        pub(crate) enum Ids<'py> {
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
pub(crate) type ImageOut = (Vec<Option<f64>>, Vec<f64>, Vec<u64>, Option<Vec<f64>>);

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
pub(crate) fn score(
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
pub(crate) fn metric_names() -> Vec<&'static str> {
    Metric::ALL.iter().map(|m| m.name()).collect()
}

/// The default metrics of a protocol.
#[pyfunction]
pub(crate) fn protocol_metrics(protocol: &str) -> PyResult<Vec<&'static str>> {
    let p = clevrtex_eval::Protocol::from_name(protocol).ok_or_else(|| {
        value_error(format!(
            "unknown protocol `{protocol}`; known: clevrtex, native, deepmind, ocl"
        ))
    })?;
    Ok(p.default_metrics().iter().map(|m| m.name()).collect())
}
