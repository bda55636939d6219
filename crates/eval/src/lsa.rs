//! Linear sum assignment that returns the same optimum as scipy's `linear_sum_assignment`.
//!
//! The benchmark's mIoU depends on *which* optimal assignment is returned when several tie
//! (renaming a prediction's slots can move mIoU from 0.333 to 0.444), so an arbitrary
//! Hungarian solver is not enough. This is a shortest-augmenting-path solver (Crouse 2016) that
//! makes the same choices as scipy's: rows are processed in order, the columns still to scan
//! are kept in a vector filled in reverse order, a column of equal reduced cost replaces the
//! current best only if it is unassigned, and a scanned column is removed by swapping it with
//! the last one. All arithmetic is `f64`, in the same order as scipy's, so the same ties arise.

/// Minimum-cost assignment of the rows of a square `n x n` cost matrix (row-major) to
/// distinct columns. Returns `col_for_row`.
///
/// Entries must be finite; a non-finite entry is treated as `+inf`-free input by the callers
/// (IoU values are always finite), and the function never panics: if no finite augmenting
/// path exists the remaining rows get the remaining columns in order.
pub fn min_cost_assignment(n: usize, cost: &[f64]) -> Vec<usize> {
    debug_assert_eq!(cost.len(), n * n);
    let mut u = vec![0.0f64; n];
    let mut v = vec![0.0f64; n];
    let mut shortest = vec![f64::INFINITY; n];
    let mut path = vec![usize::MAX; n];
    let mut col4row = vec![usize::MAX; n];
    let mut row4col = vec![usize::MAX; n];
    let mut sr = vec![false; n];
    let mut sc = vec![false; n];
    let mut remaining = vec![0usize; n];

    for cur_row in 0..n {
        // Shortest augmenting path from `cur_row`.
        let mut min_val = 0.0f64;
        let mut num_remaining = n;
        for (it, slot) in remaining.iter_mut().enumerate() {
            // Reverse order: a constant matrix yields the identity, as in scipy.
            *slot = n - it - 1;
        }
        sr.iter_mut().for_each(|x| *x = false);
        sc.iter_mut().for_each(|x| *x = false);
        shortest.iter_mut().for_each(|x| *x = f64::INFINITY);

        let mut i = cur_row;
        let mut sink = usize::MAX;
        while sink == usize::MAX {
            let mut index = usize::MAX;
            let mut lowest = f64::INFINITY;
            sr[i] = true;
            for (it, &j) in remaining[..num_remaining].iter().enumerate() {
                let r = min_val + cost[i * n + j] - u[i] - v[j];
                if r < shortest[j] {
                    path[j] = i;
                    shortest[j] = r;
                }
                if shortest[j] < lowest || (shortest[j] == lowest && row4col[j] == usize::MAX) {
                    lowest = shortest[j];
                    index = it;
                }
            }
            if index == usize::MAX || !lowest.is_finite() {
                // Infeasible (only possible with non-finite costs): finish greedily.
                return finish_greedy(n, col4row);
            }
            min_val = lowest;
            let j = remaining[index];
            if row4col[j] == usize::MAX {
                sink = j;
            } else {
                i = row4col[j];
            }
            sc[j] = true;
            num_remaining -= 1;
            remaining[index] = remaining[num_remaining];
        }

        // Update the dual variables.
        u[cur_row] += min_val;
        for r in 0..n {
            if sr[r] && r != cur_row {
                u[r] += min_val - shortest[col4row[r]];
            }
        }
        for c in 0..n {
            if sc[c] {
                v[c] -= min_val - shortest[c];
            }
        }

        // Augment the previous solution along the path.
        let mut j = sink;
        loop {
            let r = path[j];
            row4col[j] = r;
            std::mem::swap(&mut col4row[r], &mut j);
            if r == cur_row {
                break;
            }
        }
    }
    col4row
}

fn finish_greedy(n: usize, mut col4row: Vec<usize>) -> Vec<usize> {
    let mut used = vec![false; n];
    for &c in col4row.iter().filter(|&&c| c != usize::MAX) {
        used[c] = true;
    }
    let mut free = (0..n).filter(|&c| !used[c]);
    for c in col4row.iter_mut().filter(|c| **c == usize::MAX) {
        *c = free.next().unwrap_or(0);
    }
    col4row
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_matrix_gives_identity() {
        let n = 4;
        let cost = vec![0.0; n * n];
        assert_eq!(min_cost_assignment(n, &cost), vec![0, 1, 2, 3]);
    }

    #[test]
    fn simple_optimum() {
        // Rows 0,1,2; best is 0->1, 1->0, 2->2 with cost 1+2+2 = 5.
        let cost = [4.0, 1.0, 3.0, 2.0, 0.0, 5.0, 3.0, 2.0, 2.0];
        assert_eq!(min_cost_assignment(3, &cost), vec![1, 0, 2]);
    }

    #[test]
    fn empty() {
        assert!(min_cost_assignment(0, &[]).is_empty());
    }
}
