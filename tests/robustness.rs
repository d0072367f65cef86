//! Malformed input never panics the library: a fuzz harness mutates real files (the committed
//! OpenFace file, every spec of `experiments/`) thousands of times with our seeded streams and
//! feeds each mutant to the reader; an error is fine, a panic is a bug. The mutants are the
//! same every run (seeded), so a failure names a reproducible case.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

use facelab::rng::{stream, Stream};

/// Tokens that break CSV and TOML files in the ways real files break.
const TOKENS: [&str; 24] = [
    "", "nan", "NaN", "inf", "-inf", "-1", "1e999", "abc", ",", ", ", "\"", "=", "[", "]", "{",
    "}", "\n", "\r\n", "AU12_r", " success", "0x1F", "true", "[[", "\u{feff}",
];

fn pick(rng: &mut Stream, n: usize) -> usize {
    ((rng.uniform() * n as f64) as usize).min(n.saturating_sub(1))
}

/// One random edit of `bytes`: cut a range, duplicate or drop a line, swap two lines, put a
/// token or raw bytes (invalid UTF-8 included) somewhere, or truncate.
fn mutate(bytes: &[u8], rng: &mut Stream) -> Vec<u8> {
    let mut b = bytes.to_vec();
    let edits = 1 + pick(rng, 4);
    for _ in 0..edits {
        let n = b.len().max(1);
        match pick(rng, 7) {
            0 => {
                let at = pick(rng, n);
                let len = pick(rng, 40).min(b.len().saturating_sub(at));
                b.drain(at..at + len);
            }
            1 | 2 => {
                let text = String::from_utf8_lossy(&b).into_owned();
                let mut lines: Vec<&str> = text.lines().collect();
                if lines.is_empty() {
                    continue;
                }
                let i = pick(rng, lines.len());
                let j = pick(rng, lines.len());
                match pick(rng, 3) {
                    0 => lines.insert(j, lines[i]),
                    1 => {
                        lines.remove(i);
                    }
                    _ => lines.swap(i, j),
                }
                b = lines.join("\n").into_bytes();
            }
            3 | 4 => {
                let at = pick(rng, n + 1).min(b.len());
                let token = TOKENS[pick(rng, TOKENS.len())].as_bytes();
                b.splice(at..at, token.iter().copied());
            }
            5 => {
                let at = pick(rng, n + 1).min(b.len());
                let raw: Vec<u8> = (0..1 + pick(rng, 4))
                    .map(|_| pick(rng, 256) as u8)
                    .collect();
                b.splice(at..at, raw);
            }
            _ => b.truncate(pick(rng, n + 1)),
        }
    }
    b
}

/// Runs `f` on `count` mutants of `seed_bytes`; returns the first mutant that panicked.
fn fuzz(
    label: &str,
    seed_bytes: &[u8],
    count: usize,
    f: impl Fn(&[u8]),
) -> Option<(usize, Vec<u8>)> {
    let mut rng = stream(7, &format!("test/robustness/{label}"));
    let mut found = None;
    for i in 0..count {
        let m = mutate(seed_bytes, &mut rng);
        if catch_unwind(AssertUnwindSafe(|| f(&m))).is_err() {
            found = Some((i, m));
            break;
        }
    }
    found
}

#[test]
fn malformed_openface_files_are_errors_not_panics() {
    let path = crate::root().join("assets/openface/py-feat/OpenFace_Test.csv");
    let real = std::fs::read(&path).unwrap();
    // A short file (header and a few rows) makes each mutant hit the header as often as rows.
    let short: Vec<u8> = String::from_utf8_lossy(&real)
        .lines()
        .take(4)
        .collect::<Vec<_>>()
        .join("\n")
        .into_bytes();
    for (label, bytes, count) in [
        ("openface/short", &short, 3000),
        ("openface/full", &real, 300),
    ] {
        let found = fuzz(label, bytes, count, |m| {
            let _ = facelab::io::openface::parse_openface(m.to_vec(), Path::new("fuzz.csv"));
        });
        if let Some((i, m)) = found {
            panic!(
                "{label}: mutant {i} panicked the OpenFace reader:\n{}",
                String::from_utf8_lossy(&m)
            );
        }
    }
}

#[test]
fn malformed_specs_and_overrides_are_errors_not_panics() {
    let dir = crate::root().join("experiments");
    let mut specs: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .chain(std::fs::read_dir(dir.join("ablations")).unwrap())
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    specs.sort();
    // The paper spec fully resolved (every key written out), as a run records it.
    let resolved = facelab::spec::load(&facelab::io::Layout::here(), &dir.join("paper.toml"), &[])
        .unwrap()[0]
        .spec
        .to_toml();
    let mut inputs: Vec<(String, Vec<u8>)> = specs
        .iter()
        .map(|p| (p.display().to_string(), std::fs::read(p).unwrap()))
        .collect();
    inputs.push(("resolved paper".into(), resolved.into_bytes()));
    let per_input = 4000 / inputs.len();
    let layout = facelab::io::Layout::here();
    for (label, bytes) in &inputs {
        let found = fuzz(label, bytes, per_input, |m| {
            let text = String::from_utf8_lossy(m);
            let file = Path::new("fuzz.toml");
            if let Ok(tree) = facelab::spec::raw::parse_text(&text, file) {
                let _ = facelab::spec::resolve::cells(tree, file, &layout);
            }
        });
        if let Some((i, m)) = found {
            panic!(
                "{label}: mutant {i} panicked the spec parser:\n{}",
                String::from_utf8_lossy(&m)
            );
        }
    }
    let overrides = b"train.learning_rate=0.001";
    let found = fuzz("overrides", overrides, 3000, |m| {
        let _ = facelab::spec::raw::parse_override(&String::from_utf8_lossy(m));
    });
    assert!(found.is_none(), "an override panicked: {found:?}");
}
