//! The report's tests: chi-square (goodness of fit and two-sample homogeneity) for categorical
//! statistics, two-sample Kolmogorov-Smirnov for continuous ones.
//!
//! The chi-square survival function is statrs' (`ChiSquared::sf`, the regularised upper
//! incomplete gamma with its own accuracy tests); the Kolmogorov distribution is the standard
//! asymptotic series with Stephens' small-sample correction (Numerical Recipes' `kstwo`), which
//! statrs does not have.

use statrs::distribution::{ChiSquared, ContinuousCDF};

/// A test's result.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Test {
    /// The statistic (chi-square, or the KS distance D).
    pub statistic: f64,
    /// Degrees of freedom (chi-square only).
    pub df: Option<f64>,
    /// The p-value.
    pub p: f64,
}

/// Upper tail of the chi-square distribution with `df` degrees of freedom.
pub fn chi2_sf(x: f64, df: f64) -> f64 {
    match ChiSquared::new(df) {
        Ok(d) => d.sf(x),
        Err(_) => f64::NAN,
    }
}

/// Pearson's goodness of fit of `observed` counts to `expected` counts (same total).
pub fn chi2_fit(observed: &[f64], expected: &[f64]) -> Option<Test> {
    if observed.len() < 2 || expected.iter().any(|&e| e <= 0.0) {
        return None;
    }
    let stat: f64 = observed
        .iter()
        .zip(expected)
        .map(|(o, e)| (o - e) * (o - e) / e)
        .sum();
    let df = (observed.len() - 1) as f64;
    Some(Test {
        statistic: stat,
        df: Some(df),
        p: chi2_sf(stat, df),
    })
}

/// Chi-square test that two samples of category counts come from one distribution
/// (a 2 x K contingency table; categories empty in both are left out).
pub fn chi2_two_sample(a: &[f64], b: &[f64]) -> Option<Test> {
    let (na, nb): (f64, f64) = (a.iter().sum(), b.iter().sum());
    if na <= 0.0 || nb <= 0.0 {
        return None;
    }
    let n = na + nb;
    let mut stat = 0.0;
    let mut k = 0usize;
    for (x, y) in a.iter().zip(b) {
        let col = x + y;
        if col <= 0.0 {
            continue;
        }
        k += 1;
        let (ea, eb) = (na * col / n, nb * col / n);
        stat += (x - ea) * (x - ea) / ea + (y - eb) * (y - eb) / eb;
    }
    if k < 2 {
        return None;
    }
    let df = (k - 1) as f64;
    Some(Test {
        statistic: stat,
        df: Some(df),
        p: chi2_sf(stat, df),
    })
}

/// The Kolmogorov distribution's upper tail `Q(lambda) = 2 sum (-1)^(j-1) exp(-2 j^2 lambda^2)`.
fn kolmogorov_q(lambda: f64) -> f64 {
    if lambda < 0.2 {
        return 1.0;
    }
    let mut sum = 0.0;
    let mut sign = 1.0;
    for j in 1..=100 {
        let term = sign * 2.0 * (-2.0 * (j * j) as f64 * lambda * lambda).exp();
        sum += term;
        if term.abs() < 1e-12 {
            break;
        }
        sign = -sign;
    }
    sum.clamp(0.0, 1.0)
}

/// Two-sample Kolmogorov-Smirnov test (NaNs left out); `None` when a sample is empty.
pub fn ks_two_sample(a: &[f64], b: &[f64]) -> Option<Test> {
    let sorted = |v: &[f64]| {
        let mut s: Vec<f64> = v.iter().copied().filter(|x| !x.is_nan()).collect();
        s.sort_by(f64::total_cmp);
        s
    };
    let (a, b) = (sorted(a), sorted(b));
    if a.is_empty() || b.is_empty() {
        return None;
    }
    let (na, nb) = (a.len() as f64, b.len() as f64);
    let (mut i, mut j, mut d) = (0usize, 0usize, 0.0f64);
    while i < a.len() && j < b.len() {
        let x = a[i].min(b[j]);
        while i < a.len() && a[i] <= x {
            i += 1;
        }
        while j < b.len() && b[j] <= x {
            j += 1;
        }
        d = d.max((i as f64 / na - j as f64 / nb).abs());
    }
    let en = (na * nb / (na + nb)).sqrt();
    Some(Test {
        statistic: d,
        df: None,
        p: kolmogorov_q((en + 0.12 + 0.11 / en) * d),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chi2_sf_matches_tables() {
        // Table values: P(X > 14.067) = 0.05 at 7 df; P(X > 3.841) = 0.05 at 1 df.
        assert!((chi2_sf(14.067, 7.0) - 0.05).abs() < 1e-4);
        assert!((chi2_sf(3.841, 1.0) - 0.05).abs() < 1e-4);
    }

    #[test]
    fn fit_of_exact_counts_has_p_one_and_a_skewed_one_a_tiny_p() {
        let t = chi2_fit(&[10.0; 8], &[10.0; 8]).unwrap();
        assert_eq!(t.statistic, 0.0);
        assert!((t.p - 1.0).abs() < 1e-12);
        let t = chi2_fit(&[80.0, 0.0, 0.0, 0.0], &[20.0; 4]).unwrap();
        assert!(t.p < 1e-20, "{t:?}");
    }

    #[test]
    fn two_sample_chi2_and_ks() {
        let t = chi2_two_sample(&[30.0, 30.0, 0.0], &[15.0, 15.0, 0.0]).unwrap();
        assert!(t.statistic.abs() < 1e-12 && t.df == Some(1.0));
        let t = chi2_two_sample(&[50.0, 0.0], &[0.0, 50.0]).unwrap();
        assert!(t.p < 1e-10);
        let a: Vec<f64> = (0..200).map(|i| i as f64).collect();
        let b: Vec<f64> = (0..200).map(|i| i as f64 + 0.5).collect();
        assert!(ks_two_sample(&a, &b).unwrap().p > 0.9);
        let c: Vec<f64> = (0..200).map(|i| i as f64 + 100.0).collect();
        let t = ks_two_sample(&a, &c).unwrap();
        assert!((t.statistic - 0.5).abs() < 1e-12);
        // lambda = (10 + 0.12 + 0.011) * 0.5, Q = 2 exp(-2 lambda^2) ~ 5e-23.
        assert!(t.p < 1e-20, "{t:?}");
    }
}
