//! Fuzzing the readers and the metadata parser with proptest (no nightly toolchain needed):
//! valid seeds from `tests/data/eval/fuzz/` are mutated (byte flips, truncation, insertion;
//! PNG chunk CRCs are repaired so mutations reach the decoder) and every reader must return
//! `Ok` or `Err`, never panic. Failing inputs are saved by proptest in
//! `fuzz.proptest-regressions` beside this file and replayed on every run.

use std::path::PathBuf;

use clevrtex_eval::meta;
use clevrtex_eval::read::{self, NpyData};
use proptest::prelude::*;
use proptest::test_runner::FileFailurePersistence;

fn corpus() -> Vec<(String, Vec<u8>)> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/eval/fuzz");
    let mut out: Vec<(String, Vec<u8>)> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| {
            let p = e.unwrap().path();
            (
                p.file_name().unwrap().to_string_lossy().into_owned(),
                std::fs::read(&p).unwrap(),
            )
        })
        .collect();
    out.sort();
    assert!(out.len() >= 12, "fuzz corpus missing: {}", dir.display());
    out
}

fn seed(name: &str) -> Vec<u8> {
    corpus().into_iter().find(|(n, _)| n == name).unwrap().1
}

/// Recompute the CRC of every PNG chunk whose length still fits.
fn fix_png_crcs(b: &mut [u8]) {
    let mut pos = 8;
    while pos + 12 <= b.len() {
        let len = u32::from_be_bytes([b[pos], b[pos + 1], b[pos + 2], b[pos + 3]]) as usize;
        let end = match (pos + 8).checked_add(len) {
            Some(e) if e + 4 <= b.len() => e,
            _ => break,
        };
        let crc = crc32fast::hash(&b[pos + 4..end]);
        b[end..end + 4].copy_from_slice(&crc.to_be_bytes());
        pos = end + 4;
    }
}

fn run_all(bytes: &[u8]) {
    let _ = read::png_labels(bytes);
    let _ = read::png_rgb(bytes);
    let _ = read::png_samples(bytes);
    let _ = read::npy(bytes);
    let _ = read::npz(bytes, &["labels", "masks", "recon"], &|_| usize::MAX);
    let _ = read::npz_names(bytes);
    let _ = meta::parse(bytes);
}

#[derive(Debug, Clone)]
enum Edit {
    Set(usize, u8),
    Truncate(usize),
    Insert(usize, Vec<u8>),
    Dup(usize, usize),
}

fn edits() -> impl Strategy<Value = Vec<Edit>> {
    prop::collection::vec(
        prop_oneof![
            4 => (any::<usize>(), any::<u8>()).prop_map(|(p, v)| Edit::Set(p, v)),
            1 => any::<usize>().prop_map(Edit::Truncate),
            1 => (any::<usize>(), prop::collection::vec(any::<u8>(), 1..8)).prop_map(|(p, v)| Edit::Insert(p, v)),
            1 => (any::<usize>(), 1usize..64).prop_map(|(p, l)| Edit::Dup(p, l)),
        ],
        1..6,
    )
}

fn apply(mut b: Vec<u8>, edits: &[Edit]) -> Vec<u8> {
    for e in edits {
        if b.is_empty() {
            break;
        }
        let n = b.len();
        match e {
            Edit::Set(p, v) => b[p % n] = *v,
            Edit::Truncate(p) => b.truncate(p % n),
            Edit::Insert(p, v) => {
                let at = p % n;
                b.splice(at..at, v.iter().copied());
            }
            Edit::Dup(p, l) => {
                let at = p % n;
                let chunk: Vec<u8> = b[at..(at + l).min(n)].to_vec();
                b.splice(at..at, chunk);
            }
        }
    }
    b
}

proptest! {
    #![proptest_config(ProptestConfig {
        // `FUZZ_CASES=200000 cargo test --release -p clevrtex-eval --test fuzz` for a long run.
        cases: std::env::var("FUZZ_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(2000),
        failure_persistence: Some(Box::new(FileFailurePersistence::Direct("tests/fuzz.proptest-regressions"))),
        ..ProptestConfig::default()
    })]

    #[test]
    fn mutated_seeds_never_panic(which in any::<prop::sample::Index>(), e in edits()) {
        let seeds = corpus();
        let (name, bytes) = &seeds[which.index(seeds.len())];
        let mut b = apply(bytes.clone(), &e);
        if name.ends_with(".png") {
            fix_png_crcs(&mut b);
        }
        run_all(&b);
    }

    #[test]
    fn random_bytes_never_panic(prefix in 0usize..4, tail in prop::collection::vec(any::<u8>(), 0..256)) {
        let magic: &[u8] = [&b""[..], b"\x89PNG\r\n\x1a\n", b"\x93NUMPY\x01\x00", b"PK\x03\x04"][prefix];
        let mut b = magic.to_vec();
        b.extend(tail);
        run_all(&b);
    }

    #[test]
    fn npy_headers_never_panic(header in "\\{'descr': '[<>|=]?[biuf][0-9]{1,2}', 'fortran_order': (True|False), 'shape': \\(([0-9]{1,12}, ){0,4}\\), \\}", body in prop::collection::vec(any::<u8>(), 0..64)) {
        let mut b = b"\x93NUMPY\x01\x00".to_vec();
        b.extend((header.len() as u16).to_le_bytes());
        b.extend(header.as_bytes());
        b.extend(body);
        let _ = read::npy(&b);
    }
}

#[test]
fn seeds_decode_to_the_same_values() {
    let palette = read::png_labels(&seed("palette.png")).unwrap();
    let npy = read::npy(&seed("labels_i4.npy")).unwrap();
    assert_eq!(npy.shape, vec![6, 5]);
    let NpyData::Int(ids) = &npy.data else {
        panic!("int expected")
    };
    assert_eq!((palette.width, palette.height), (5, 6));
    assert_eq!(
        palette.labels,
        ids.iter().map(|&v| v as u32).collect::<Vec<_>>()
    );
    let g16 = read::png_labels(&seed("grey16.png")).unwrap();
    assert_eq!(
        g16.labels,
        palette.labels.iter().map(|&v| v * 300).collect::<Vec<_>>()
    );
    // The optional passes' reader: 16-bit grey as it is, palette and 1-bit refused.
    let s16 = read::png_samples(&seed("grey16.png")).unwrap();
    assert_eq!((s16.channels, s16.bits), (1, 16));
    assert_eq!(
        s16.samples
            .iter()
            .map(|&v| u32::from(v))
            .collect::<Vec<_>>(),
        g16.labels
    );
    assert!(read::png_samples(&seed("palette.png")).is_err());
    assert!(read::png_samples(&seed("bit1.png")).is_err());
    let bit = read::png_labels(&seed("bit1.png")).unwrap();
    assert_eq!(
        bit.labels,
        palette
            .labels
            .iter()
            .map(|&v| (v > 1) as u32)
            .collect::<Vec<_>>()
    );
    let f = read::npy(&seed("masks_f8_fortran.npy")).unwrap();
    let c = read::npy(&seed("masks_f8_big_endian.npy")).unwrap();
    assert_eq!(f.shape, vec![2, 3, 4]);
    assert_eq!(f.data, c.data);
    let z = read::npz(&seed("stored.npz"), &["labels"], &|_| usize::MAX).unwrap();
    assert_eq!(z["labels"].shape, vec![6, 5]);
    let z = read::npz(
        &seed("deflated.npz"),
        &["masks", "recon", "labels"],
        &|_| usize::MAX,
    )
    .unwrap();
    assert_eq!(z["recon"].shape, vec![3, 6, 5]);
    assert!(!z.contains_key("labels"));
    assert_eq!(
        read::png_rgb(&seed("rgba.png")).unwrap().rgb.len(),
        4 * 3 * 3
    );
    assert!(matches!(
        read::npy(&seed("half.npy")).unwrap().data,
        NpyData::F32(_)
    ));
}
