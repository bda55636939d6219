use crate::dataset;

use super::*;

#[test]
fn shard_names_are_recognised_and_nothing_else() {
    assert!(is_shard_name(&shard_name("full", "train", 3)));
    assert_eq!(shard_name("camo", "val", 12), "camo-val-000012.tar");
    for name in [
        "full-train-00003.tar",
        "full-nope-000003.tar",
        "-train-000003.tar",
        "full-train-000003.tar.clevrtex-tmp",
        "index.json",
    ] {
        assert!(!is_shard_name(name), "{name}");
    }
}

#[test]
fn an_unfinished_shard_leaves_nothing_and_a_finished_one_is_reproducible() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    std::fs::create_dir(&data).unwrap();
    std::fs::write(data.join("a.png"), b"not really a png").unwrap();
    let root = dataset::root(&data).unwrap();
    let files = vec![SampleFile {
        key: "png".to_string(),
        path: data.join("a.png"),
        pass: None,
        npy: false,
    }];
    let entries = sample_entries(&root, &files, &PassCheck::default()).unwrap();
    let out = dir.path().join("full-train-000000.tar");
    {
        let mut w = ShardWriter::create(out.clone()).unwrap();
        w.add(7, "CLEVRTEX_full_000007", &entries).unwrap();
        assert_eq!((w.samples(), w.bytes()), (1, 1024));
    }
    assert!(
        std::fs::read_dir(dir.path()).unwrap().count() == 1,
        "a temporary shard is left"
    );
    let mut bytes = Vec::new();
    for _ in 0..2 {
        let mut w = ShardWriter::create(out.clone()).unwrap();
        w.add(7, "CLEVRTEX_full_000007", &entries).unwrap();
        let entry = w.finish().unwrap();
        assert_eq!(entry["first_index"], 7);
        assert_eq!(entry["samples"], 1);
        bytes.push(std::fs::read(&out).unwrap());
    }
    assert_eq!(bytes[0], bytes[1]);
    let missing = SampleFile {
        key: "png".into(),
        path: data.join("missing.png"),
        pass: None,
        npy: false,
    };
    let err = sample_entries(&root, &[missing], &PassCheck::default()).unwrap_err();
    assert!(err.to_string().contains("missing.png"), "{err}");
    assert!(err.to_string().contains("hint:"), "{err}");
}

#[test]
fn npy_headers_are_numpy_s_and_pad_to_64_bytes() {
    for shape in [&[240usize, 320][..], &[2, 3, 3], &[5]] {
        let h = npy_header("<f4", shape);
        assert_eq!(h.len() % 64, 0);
        assert_eq!(&h[..8], b"\x93NUMPY\x01\x00");
        assert_eq!(usize::from(u16::from_le_bytes([h[8], h[9]])), h.len() - 10);
        assert_eq!(*h.last().unwrap(), b'\n');
    }
    let h = String::from_utf8(npy_header("|u1", &[240, 320])[10..].to_vec()).unwrap();
    assert!(h.starts_with("{'descr': '|u1', 'fortran_order': False, 'shape': (240, 320), }"));
    let h = String::from_utf8(npy_header("<f4", &[5])[10..].to_vec()).unwrap();
    assert!(h.contains("'shape': (5,)"), "{h}");
}
