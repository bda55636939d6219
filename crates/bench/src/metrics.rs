//! Error of one render against its reference: pure functions on pixel buffers.

/// How a render differs from its reference.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Errors {
    /// Root-mean-square difference of the linear (scene-referred) Combined RGB, over every
    /// pixel and channel.
    pub rmse_linear: f64,
    /// `rmse_linear` divided by the reference's mean linear value: the "relative RMSE" of
    /// this project's render measurements (docs/performance.md).
    pub rel_error: f64,
    /// Mean of the render minus mean of the reference, over the reference's mean: the
    /// systematic part of the error (reduced bounces or clamping darken; noise alone gives
    /// ~0).
    pub bias: f64,
    /// PSNR of the 8-bit sRGB PNG against the reference's, dB; infinite when identical.
    pub psnr_srgb: f64,
    /// The mask (object index) equals that of a 1-sample render at the same Cycles seed
    /// exactly (both come from each pixel's first sample).
    pub mask_equal: bool,
    /// The depth equals that of the same 1-sample render exactly.
    pub depth_equal: bool,
}

/// Sum of squared differences of two equally long buffers, in f64.
fn sum_sq_diff<T: Copy + Into<f64>>(a: &[T], b: &[T]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(&x, &y)| {
            let d = x.into() - y.into();
            d * d
        })
        .sum()
}

/// RMSE of `a` against `b` (same length, at least one value).
pub fn rmse(a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len(), "buffers of different sizes");
    (sum_sq_diff(a, b) / a.len().max(1) as f64).sqrt()
}

/// Mean of `a` (0 for an empty slice).
pub fn mean(a: &[f32]) -> f64 {
    a.iter().map(|&x| f64::from(x)).sum::<f64>() / a.len().max(1) as f64
}

/// `x / d`, or 0 when `d` is 0 (a black reference: no relative error is defined, and 0 keeps
/// tables and plots finite).
pub fn ratio(x: f64, d: f64) -> f64 {
    if d > 0.0 {
        x / d
    } else {
        0.0
    }
}

/// PSNR in dB of 8-bit images `a` against `b`: `10 log10(255^2 / MSE)`; `f64::INFINITY`
/// when they are identical.
pub fn psnr_u8(a: &[u8], b: &[u8]) -> f64 {
    assert_eq!(a.len(), b.len(), "images of different sizes");
    let sum = sum_sq_diff(a, b);
    if sum == 0.0 {
        return f64::INFINITY;
    }
    let mse = sum / a.len() as f64;
    10.0 * (255.0 * 255.0 / mse).log10()
}

/// Bitwise equality of two float buffers (so `NaN`s compare equal and `-0 != 0`): "exactly
/// the same pass".
pub fn bits_equal(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rmse_of_a_constant_offset_is_the_offset() {
        let a = [1.0f32, 2.0, 3.0, 4.0];
        let b = [1.5f32, 2.5, 3.5, 4.5];
        assert!((rmse(&a, &b) - 0.5).abs() < 1e-12);
        assert_eq!(rmse(&a, &a), 0.0);
        assert!((mean(&b) - 3.0).abs() < 1e-12);
        assert!((ratio(rmse(&a, &b), mean(&b)) - 0.5 / 3.0).abs() < 1e-12);
        assert_eq!(ratio(1.0, 0.0), 0.0);
    }

    #[test]
    fn psnr_matches_the_formula_and_is_infinite_for_equal_images() {
        let a = [0u8, 10, 20, 30];
        assert_eq!(psnr_u8(&a, &a), f64::INFINITY);
        // One value off by 10: MSE = 100 / 4 = 25.
        let b = [0u8, 10, 20, 40];
        let want = 10.0 * (255.0f64 * 255.0 / 25.0).log10();
        assert!((psnr_u8(&a, &b) - want).abs() < 1e-9);
    }

    #[test]
    fn bits_equal_is_exact() {
        assert!(bits_equal(&[1.0, f32::NAN], &[1.0, f32::NAN]));
        assert!(!bits_equal(&[0.0], &[-0.0]));
        assert!(!bits_equal(&[1.0], &[1.0, 2.0]));
        assert!(!bits_equal(&[1.0], &[1.0 + f32::EPSILON]));
    }
}
