//! Property tests against brute-force references written independently here, invariances,
//! and the spec's stiff cases.

use clevrtex_eval::predict::argmax_masks;
use clevrtex_eval::{score_image, Metric};
use proptest::prelude::*;

/// ARI by enumerating unordered pixel pairs (scikit-learn's definition).
fn brute_ari(t: &[u32], p: &[u32]) -> f64 {
    let (mut a, mut b, mut c, mut d) = (0f64, 0f64, 0f64, 0f64);
    for i in 0..t.len() {
        for j in i + 1..t.len() {
            match (t[i] == t[j], p[i] == p[j]) {
                (true, true) => a += 1.0,
                (true, false) => b += 1.0,
                (false, true) => c += 1.0,
                (false, false) => d += 1.0,
            }
        }
    }
    if b == 0.0 && c == 0.0 {
        return 1.0;
    }
    2.0 * (a * d - b * c) / ((a + b) * (b + d) + (a + c) * (c + d))
}

/// Best total IoU over every permutation (K <= 7), IoU computed independently.
fn brute_best_iou_sum(t: &[u32], p: &[u32], k: usize) -> f64 {
    let mut iou = vec![vec![0f64; k]; k]; // [t][p]
    for (tt, row) in iou.iter_mut().enumerate() {
        for (pp, v) in row.iter_mut().enumerate() {
            let inter = t
                .iter()
                .zip(p)
                .filter(|(&a, &b)| a as usize == tt && b as usize == pp)
                .count();
            let union = t
                .iter()
                .zip(p)
                .filter(|(&a, &b)| a as usize == tt || b as usize == pp)
                .count();
            let ts = t.iter().filter(|&&a| a as usize == tt).count();
            let ps = p.iter().filter(|&&b| b as usize == pp).count();
            if ts > 0 && ps > 0 {
                *v = (inter as f32 / union as f32) as f64;
            }
        }
    }
    fn rec(iou: &[Vec<f64>], row: usize, used: &mut Vec<bool>) -> f64 {
        if row == iou.len() {
            return 0.0;
        }
        let mut best = f64::NEG_INFINITY;
        for c in 0..iou.len() {
            if !used[c] {
                used[c] = true;
                best = best.max(iou[row][c] + rec(iou, row + 1, used));
                used[c] = false;
            }
        }
        best
    }
    rec(&iou, 0, &mut vec![false; k])
}

fn labels(max_len: usize, k: u32) -> impl Strategy<Value = (Vec<u32>, Vec<u32>)> {
    (1..max_len).prop_flat_map(move |n| {
        (
            prop::collection::vec(0..k, n),
            prop::collection::vec(0..k, n),
        )
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn ari_matches_pair_counting((t, p) in labels(40, 6)) {
        let s = score_image(&t, &p, 1, None);
        let want = brute_ari(&t, &p);
        prop_assert!((s.get(Metric::Ari).unwrap() - want).abs() < 1e-12);
        let fg: Vec<usize> = (0..t.len()).filter(|&i| t[i] > 0).collect();
        let tf: Vec<u32> = fg.iter().map(|&i| t[i]).collect();
        let pf: Vec<u32> = fg.iter().map(|&i| p[i]).collect();
        prop_assert!((s.get(Metric::AriFg).unwrap() - brute_ari(&tf, &pf)).abs() < 1e-12);
    }

    #[test]
    fn matching_is_optimal((t, p) in labels(30, 7), extra in 0usize..3) {
        let k = (*t.iter().chain(&p).max().unwrap() as usize + 1 + extra).min(7);
        let s = score_image(&t, &p, k, None);
        let ours: f64 = s.iou_per_true.iter().sum();
        let best = brute_best_iou_sum(&t, &p, s.iou_per_true.len());
        prop_assert!((ours - best).abs() < 1e-9, "ours {ours} best {best}");
    }

    #[test]
    fn relabelling_predictions_keeps_ari_and_miou_gt((t, p) in labels(40, 6), perm in Just((0u32..6).collect::<Vec<_>>()).prop_shuffle()) {
        let q: Vec<u32> = p.iter().map(|&x| perm[x as usize]).collect();
        let a = score_image(&t, &p, 6, None);
        let b = score_image(&t, &q, 6, None);
        prop_assert_eq!(a.get(Metric::Ari), b.get(Metric::Ari));
        prop_assert_eq!(a.get(Metric::AriFg), b.get(Metric::AriFg));
        prop_assert!((a.get(Metric::MIoUGt).unwrap() - b.get(Metric::MIoUGt).unwrap()).abs() < 1e-9);
        prop_assert_eq!(a.get(Metric::MSc), b.get(Metric::MSc));
    }

    #[test]
    fn perfect_prediction_scores_one((mut t, _) in labels(50, 8), perm in Just((0u32..8).collect::<Vec<_>>()).prop_shuffle()) {
        // Real masks have background; without any, `mIoU_fg` follows the reference's
        // `num_pairs - 1` denominator (see docs/eval.md) and is not a mean.
        t[0] = 0;
        let q: Vec<u32> = t.iter().map(|&x| perm[x as usize]).collect();
        let s = score_image(&t, &q, 8, None);
        for m in [Metric::MIoUGt, Metric::Ari, Metric::AriFg, Metric::Acc, Metric::MSc] {
            prop_assert_eq!(s.get(m), Some(1.0), "{}", m.name());
        }
        for m in [Metric::MIoU, Metric::MIoUFg, Metric::Dice, Metric::DiceFg] {
            if let Some(v) = s.get(m) {
                prop_assert!((v - 1.0).abs() < 1e-12, "{} = {v}", m.name());
            }
        }
    }

    #[test]
    fn never_nan((t, p) in labels(30, 5), k in 0usize..9) {
        let s = score_image(&t, &p, k, None);
        for v in s.values.iter().flatten() {
            prop_assert!(v.is_finite());
        }
    }
}

#[test]
fn stiff_all_singletons() {
    let t: Vec<u32> = (0..16).collect();
    let s = score_image(&t, &t, 16, None);
    assert_eq!(s.get(Metric::Ari), Some(1.0));
    let zeros = vec![0u32; 16];
    let s = score_image(&t, &zeros, 1, None);
    assert_eq!(s.get(Metric::Ari), Some(0.0));
    for v in s.values.iter().flatten() {
        assert!(v.is_finite());
    }
}

#[test]
fn stiff_one_cluster_both_sides() {
    let z = vec![0u32; 9];
    let s = score_image(&z, &z, 1, None);
    assert_eq!(s.get(Metric::Ari), Some(1.0));
    assert_eq!(s.get(Metric::MIoU), Some(1.0));
    // One pair only: the foreground means are undefined, not NaN.
    assert_eq!(s.get(Metric::MIoUFg), None);
    assert_eq!(s.get(Metric::DiceFg), None);
}

#[test]
fn stiff_empty_image() {
    let s = score_image(&[], &[], 3, None);
    assert!(s.values.iter().all(|v| v.is_none()));
}

#[test]
fn stiff_300_segments() {
    let t: Vec<u32> = (0..30 * 30).map(|i| (i / 3) as u32).collect();
    let p: Vec<u32> = t.iter().map(|&x| 299 - x).collect();
    let s = score_image(&t, &p, 300, None);
    assert_eq!(s.true_segments, 300);
    assert_eq!(s.get(Metric::Ari), Some(1.0));
    assert!((s.get(Metric::MIoU).unwrap() - 1.0).abs() < 1e-12);
}

#[test]
fn stiff_4096_squared_pair_counts_overflow_i64_products() {
    // Left half 1 / right half 2, prediction shifted by a quarter: n = 2^24 pixels, so
    // tp * tn is ~2^94 and needs i128.
    let side = 4096usize;
    let t: Vec<u32> = (0..side * side)
        .map(|i| if i % side < side / 2 { 1 } else { 2 })
        .collect();
    let p: Vec<u32> = (0..side * side)
        .map(|i| {
            if i % side < side / 4 {
                0
            } else {
                1 + (i % side >= side / 2) as u32
            }
        })
        .collect();
    let s = score_image(&t, &p, 3, None);
    // Closed form with exact rationals: rows a = (n/2, n/2), cols b = (n/4, n/4, n/2),
    // n_ij = n/4, n/4, n/2.
    let n = (side * side) as i128;
    let sq = |x: i128| x * x;
    let ss = sq(n / 4) * 2 + sq(n / 2);
    let a = sq(n / 2) * 2;
    let b = sq(n / 4) * 2 + sq(n / 2);
    let want = clevrtex_eval::metrics::ari_from_sums(n, ss, a, b);
    assert_eq!(s.get(Metric::Ari), Some(want));
    assert!(want > 0.0 && want < 1.0, "{want}");
    assert_eq!(s.get(Metric::AriFg), Some(want_fg(n)));
}

fn want_fg(n: i128) -> f64 {
    // Foreground is all pixels here (true labels 1 and 2 only).
    let sq = |x: i128| x * x;
    clevrtex_eval::metrics::ari_from_sums(
        n,
        sq(n / 4) * 2 + sq(n / 2),
        sq(n / 2) * 2,
        sq(n / 4) * 2 + sq(n / 2),
    )
}

#[test]
fn soft_masks_nan_and_ties() {
    // Two pixels, three masks. Pixel 0: tie between masks 1 and 2 -> 1. Pixel 1: NaN in mask 1
    // wins over a larger mask 2 (numpy/torch treat NaN as the maximum).
    let data = [0.1f32, 0.2, 0.5, f32::NAN, 0.5, 0.9];
    assert_eq!(argmax_masks(&data, 3, 2, false), vec![1, 1]);
    // No background: bg = 1 - sum; pixel 0 bg = 1 - 1.1 < 0 -> mask 2 (label 2) ties mask 3;
    // pixel 1 bg is NaN -> background.
    assert_eq!(argmax_masks(&data, 3, 2, true), vec![2, 0]);
    let data = [0.1f32, 0.0, 0.2, 0.0];
    assert_eq!(argmax_masks(&data, 2, 2, true), vec![0, 0]);
}
