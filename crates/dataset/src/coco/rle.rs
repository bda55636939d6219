//! A mask's objects as COCO run-length encodings ([`object_runs`]): column-major runs, starting
//! with a run of zeros, compressed into COCO's string form ([`compress`], pycocotools'
//! `rleToString`), with each object's area and box.

/// One object of a mask: its runs (column-major, zeros first), pixel count and inclusive
/// extent.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectRle {
    /// Alternating runs of 0 and 1, column-major, the first a (possibly empty) run of 0s.
    pub counts: Vec<u32>,
    /// Pixels of the object.
    pub area: u64,
    /// `[x_min, y_min, x_max, y_max]`, inclusive pixel indices.
    pub extent: [u32; 4],
}

/// The runs of each id `1..=n` in the `width` x `height` row-major `ids` (an id over `n` is
/// the caller's to refuse first): `result[id - 1]`, `None` for an id with no pixel.
pub fn object_runs(ids: &[u16], width: usize, height: usize, n: usize) -> Vec<Option<ObjectRle>> {
    debug_assert_eq!(ids.len(), width * height);
    let mut out: Vec<Option<ObjectRle>> = vec![None; n];
    // The end (exclusive, column-major position) of each object's last run of 1s.
    let mut end = vec![0usize; n];
    for x in 0..width {
        for y in 0..height {
            let id = usize::from(ids[y * width + x]);
            if id == 0 || id > n {
                continue;
            }
            let p = x * height + y;
            let (x32, y32) = (x as u32, y as u32);
            let o = out[id - 1].get_or_insert_with(|| ObjectRle {
                counts: Vec::new(),
                area: 0,
                extent: [x32, y32, x32, y32],
            });
            if !o.counts.is_empty() && end[id - 1] == p {
                *o.counts.last_mut().expect("not empty") += 1;
            } else {
                o.counts.push((p - end[id - 1]) as u32);
                o.counts.push(1);
            }
            end[id - 1] = p + 1;
            o.area += 1;
            let e = &mut o.extent;
            e[0] = e[0].min(x32);
            e[1] = e[1].min(y32);
            e[2] = e[2].max(x32);
            e[3] = e[3].max(y32);
        }
    }
    let total = width * height;
    for (o, end) in out.iter_mut().zip(end) {
        if let Some(o) = o {
            if end < total {
                o.counts.push((total - end) as u32);
            }
        }
    }
    out
}

/// COCO's compressed string of `counts` (pycocotools `maskApi.c` `rleToString`): each count
/// (from the third on, less the count two before) in 5-bit groups, lowest first, with a
/// continuation bit, plus 48.
pub fn compress(counts: &[u32]) -> String {
    let mut s = String::with_capacity(counts.len() * 2);
    for (i, &c) in counts.iter().enumerate() {
        let mut x = i64::from(c);
        if i > 2 {
            x -= i64::from(counts[i - 2]);
        }
        loop {
            let mut c = x & 0x1f;
            x >>= 5;
            let more = if c & 0x10 != 0 { x != -1 } else { x != 0 };
            if more {
                c |= 0x20;
            }
            s.push(char::from((c + 48) as u8));
            if !more {
                break;
            }
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// pycocotools' `rleFrString`, to read back what [`compress`] wrote.
    fn decompress(s: &str) -> Vec<u32> {
        let b = s.as_bytes();
        let (mut out, mut p) = (Vec::<i64>::new(), 0);
        while p < b.len() {
            let (mut x, mut k, mut more) = (0i64, 0, true);
            while more {
                let c = i64::from(b[p]) - 48;
                x |= (c & 0x1f) << (5 * k);
                more = c & 0x20 != 0;
                p += 1;
                k += 1;
                if !more && c & 0x10 != 0 {
                    x |= -1 << (5 * k);
                }
            }
            if out.len() > 2 {
                x += out[out.len() - 2];
            }
            out.push(x);
        }
        out.into_iter().map(|x| x as u32).collect()
    }

    #[test]
    fn runs_are_column_major_and_compress_round_trips() {
        // 3 wide, 2 high: id 1 at (0,0), (1,0), (1,1); id 2 at (2,1); id 3 absent.
        let ids = [1, 1, 0, 0, 1, 2];
        let r = object_runs(&ids, 3, 2, 3);
        let one = r[0].as_ref().unwrap();
        // Column-major: (0,0)=1 (0,1)=0 (1,0)=1 (1,1)=1 (2,0)=0 (2,1)=0.
        assert_eq!(one.counts, [0, 1, 1, 2, 2]);
        assert_eq!((one.area, one.extent), (3, [0, 0, 1, 1]));
        let two = r[1].as_ref().unwrap();
        assert_eq!(two.counts, [5, 1]);
        assert_eq!((two.area, two.extent), (1, [2, 1, 2, 1]));
        assert!(r[2].is_none());
        for counts in [
            vec![0, 1, 1, 2, 2],
            vec![5, 1],
            vec![100_000, 3, 7, 40_000, 1, 2, 99_999],
        ] {
            assert_eq!(decompress(&compress(&counts)), counts);
        }
        // pycocotools: `encode(np.asfortranarray([[1, 1, 0], [0, 1, 0]], np.uint8))`.
        assert_eq!(compress(&one.counts), "01111");
    }
}
