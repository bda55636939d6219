//! The table of `clevrtex materials cost`: each material's render time relative to `plain`,
//! the median, and the materials over three times the median.

/// The relative costs of a batch.
#[derive(Debug, Clone, PartialEq)]
pub struct Cost {
    /// Each material's time over `plain`'s, in the batch's order (NaN where it has no time).
    pub relative: Vec<f64>,
    /// The median of `relative`.
    pub median: f64,
    /// The largest of `relative` (NaN sorts last).
    pub max: f64,
    /// `name (x.xx plain)` of each material over three times the median.
    pub outliers: Vec<String>,
}

/// The costs of `names` rendered in `times` seconds (NaN for a material that failed); `plain`
/// must be one of them (else every cost is NaN). Needs at least one material.
pub fn relative(names: &[&str], times: &[f64]) -> Cost {
    let plain = names
        .iter()
        .zip(times)
        .find(|(n, _)| **n == "plain")
        .map_or(f64::NAN, |(_, t)| *t);
    let shown: Vec<f64> = times.iter().map(|t| t / plain).collect();
    let mut rel = shown.clone();
    rel.sort_by(f64::total_cmp);
    let median = rel[rel.len() / 2];
    let outliers: Vec<String> = names
        .iter()
        .zip(&shown)
        .filter(|(_, x)| **x > 3.0 * median)
        .map(|(name, x)| format!("{name} ({x:.2}x plain)"))
        .collect();
    Cost {
        relative: shown,
        median,
        max: rel[rel.len() - 1],
        outliers,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn costs_are_relative_to_plain_and_outliers_are_over_three_medians() {
        let c = relative(&["a", "plain", "b", "c"], &[2.0, 1.0, 1.5, 10.0]);
        assert_eq!(c.relative, vec![2.0, 1.0, 1.5, 10.0]);
        assert_eq!(c.median, 2.0);
        assert_eq!(c.max, 10.0);
        assert_eq!(c.outliers, vec!["c (10.00x plain)".to_string()]);
        // Without `plain` nothing can be compared.
        assert!(relative(&["a"], &[2.0]).median.is_nan());
    }
}
