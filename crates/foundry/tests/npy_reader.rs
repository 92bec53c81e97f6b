//! The `.npy` reader on arbitrary bytes: mutated headers (shapes, dtypes, byte order,
//! Fortran order, lengths), truncations, insertions and random bytes of valid plain and
//! structured arrays. Every file either reads with exactly the bytes its header announces
//! or is refused with an error naming the file; never a panic or an allocation the file
//! cannot back.

use std::path::Path;

use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::{read_array, read_records, write_array, write_records};
use hytrace_foundry::records::{Instance, Prim};
use hytrace_testkit::{Random, SplitMix64};

/// Header text edits: each replaces a piece of a valid header by something a broken or
/// hostile writer could produce.
const HEADER_EDITS: &[(&str, &str)] = &[
    ("'<f4'", "'>f4'"),
    ("'<f4'", "'<f2'"),
    ("'<f4'", "'|O'"),
    ("'<f4'", "'<U8'"),
    ("'<f8'", "'<c16'"),
    ("'<u4'", "'<i8'"),
    ("False", "True"),
    ("False", "Flase"),
    ("(5, 8)", "(5, 8, 0)"),
    ("(5, 8)", "(18446744073709551615, 8)"),
    ("(5, 8)", "(4611686018427387904, 4)"),
    ("(5, 8)", "(-5, 8)"),
    ("(5, 8)", "(5.5, 8)"),
    ("(5, 8)", "()"),
    ("(5, 8)", "(6, 8)"),
    ("(5, 8)", "(4, 8)"),
    ("(3,)", "(3000000000000,)"),
    ("(3,)", "(2,)"),
    ("'descr'", "'desc'"),
    ("'shape'", "'shap'"),
    ("{", "["),
    ("}", ""),
    ("'", "\""),
];

/// Valid files to mutate: plain float32, float64 and uint32 arrays, and structured records.
fn seeds(dir: &Path) -> Vec<Vec<u8>> {
    let f32s: Vec<u8> = (0..40)
        .flat_map(|k| (k as f32 * 0.5).to_le_bytes())
        .collect();
    let f64s: Vec<u8> = (0..40)
        .flat_map(|k| (k as f64 - 3.0).to_le_bytes())
        .collect();
    let u32s: Vec<u8> = (0..12u32).flat_map(|k| k.to_le_bytes()).collect();
    let path = dir.join("seed.npy");
    let mut out = Vec::new();
    let mut keep = |write: &dyn Fn(&Path)| {
        write(&path);
        out.push(std::fs::read(&path).unwrap());
    };
    keep(&|p| write_array(p, Scalar::F32, &[5, 8], &f32s).unwrap());
    keep(&|p| write_array(p, Scalar::F64, &[5, 8], &f64s).unwrap());
    keep(&|p| write_array(p, Scalar::U32, &[3, 4], &u32s).unwrap());
    keep(&|p| write_records(p, &[<Instance as bytemuck::Zeroable>::zeroed(); 3]).unwrap());
    keep(&|p| write_records(p, &[<Prim as bytemuck::Zeroable>::zeroed(); 3]).unwrap());
    out
}

fn mutate(seed: &[u8], rng: &mut SplitMix64) -> Vec<u8> {
    let mut bytes = seed.to_vec();
    for _ in 0..1 + rng.below(3) {
        // Mostly the header (magic, version, length, dict), sometimes anywhere.
        let span = if rng.below(3) == 0 {
            bytes.len()
        } else {
            bytes.len().min(128)
        };
        let at = rng.below(span.max(1));
        match rng.below(6) {
            0 => bytes.truncate(at),
            1 => {
                if let Some(b) = bytes.get_mut(at) {
                    *b ^= 1 << rng.below(8);
                }
            }
            2 => {
                if let Some(b) = bytes.get_mut(at) {
                    *b = rng.next_u64() as u8;
                }
            }
            3 => {
                let n = rng.below(16);
                let junk: Vec<u8> = (0..n).map(|_| rng.next_u64() as u8).collect();
                bytes.splice(at..at, junk);
            }
            4 => {
                // The header length field (bytes 8..10 of version 1 files).
                if bytes.len() >= 10 {
                    let v = [0u16, 1, 0xffff, 0x7f, 0x81][rng.below(5)];
                    bytes[8..10].copy_from_slice(&v.to_le_bytes());
                }
            }
            _ => {
                let (from, to) = HEADER_EDITS[rng.below(HEADER_EDITS.len())];
                let head = bytes.len().min(128);
                if let Some(p) = find(&bytes[..head], from.as_bytes()) {
                    bytes.splice(p..p + from.len(), to.bytes());
                }
            }
        }
    }
    bytes
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

#[test]
fn mutated_npy_files_read_exactly_or_are_refused_with_the_file_named() {
    let dir = tempfile::tempdir().unwrap();
    let seeds = seeds(dir.path());
    let path = dir.path().join("fuzz.npy");
    let mut rng = SplitMix64(0x00c0_ffee);
    let (mut read, mut refused) = (0usize, 0usize);
    let cases = hytrace_testkit::fuzz_cases(5000);
    for case in 0..cases {
        let bytes = mutate(&seeds[rng.below(seeds.len())], &mut rng);
        std::fs::write(&path, &bytes).unwrap();
        let t0 = std::time::Instant::now();
        match read_array(&path) {
            Ok(a) => {
                // Exactly the announced bytes, and never more than the file holds.
                let n = a.shape.iter().product::<u64>() * a.scalar.size() as u64;
                assert_eq!(a.bytes.len() as u64, n, "case {case}: {:?}", a.shape);
                assert!(n <= bytes.len() as u64, "case {case}");
                read += 1;
            }
            Err(e) => {
                assert!(e.to_string().contains("fuzz.npy"), "case {case}: {e}");
                refused += 1;
            }
        }
        match read_records::<Instance>(&path) {
            Ok(r) => assert!(
                r.len() * size_of::<Instance>() <= bytes.len(),
                "case {case}"
            ),
            Err(e) => assert!(e.to_string().contains("fuzz.npy"), "case {case}: {e}"),
        }
        assert!(
            t0.elapsed().as_secs() < 5,
            "case {case} took {:?}",
            t0.elapsed()
        );
    }
    assert!(
        read > cases / 50 && refused > cases / 2,
        "{read} read, {refused} refused"
    );
}
