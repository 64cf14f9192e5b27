//! The fuzz corpora replayed: every input the fuzzers kept
//! (`fuzz/corpus/TARGET/`) and every crash they ever found
//! (`fuzz/artifacts/TARGET/`, each fixed and kept as a regression case)
//! goes through the same entry point as under `cargo fuzz`
//! (`rendiff::fuzz`), which panics on any failure of its properties.

use std::path::Path;

use crate::util::root;

/// Replays every kept input and past crash of one target through `run`.
/// The inputs are spread over the machine's threads (the scene corpus is
/// the suite's longest test); every failing file is named.
fn replay(name: &str, run: impl Fn(&[u8]) + Sync) {
    use rayon::prelude::*;
    let corpus = files(&root().join("fuzz/corpus").join(name));
    let crashes = files(&root().join("fuzz/artifacts").join(name));
    assert!(!corpus.is_empty(), "{name}: no corpus");
    let all: Vec<&std::path::PathBuf> = corpus.iter().chain(&crashes).collect();
    let failed: Vec<String> = all
        .par_iter()
        .filter_map(|f| {
            let data = match std::fs::read(f) {
                Ok(d) => d,
                // A running fuzzer replaces corpus files as it reduces them.
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => return None,
                Err(e) => return Some(format!("{}: {e}", f.display())),
            };
            let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| run(&data)));
            outcome.is_err().then(|| format!("{} fails", f.display()))
        })
        .collect();
    assert!(failed.is_empty(), "{name}: {}", failed.join("; "));
    eprintln!(
        "{name}: {} corpus inputs, {} past crashes replayed",
        corpus.len(),
        crashes.len()
    );
}

fn files(dir: &Path) -> Vec<std::path::PathBuf> {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut v: Vec<_> = rd
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.is_file())
        .collect();
    v.sort();
    v
}

#[test]
fn scene_text_corpus_replays_cleanly() {
    let scenes = root().join("scenes");
    replay("scene_text", |d| rendiff::fuzz::scene_text(&scenes, d));
}

#[test]
fn scene_files_corpus_replays_cleanly() {
    replay("scene_files", rendiff::fuzz::scene_files);
}

#[test]
fn obj_bytes_corpus_replays_cleanly() {
    replay("obj_bytes", rendiff::fuzz::obj_bytes);
}

#[test]
fn png_bytes_corpus_replays_cleanly() {
    replay("png_bytes", rendiff::fuzz::png_bytes);
}

#[test]
fn polygon_corpus_replays_cleanly() {
    replay("polygon", rendiff::fuzz::polygon);
}

#[test]
fn triangles_corpus_replays_cleanly() {
    replay("triangles", rendiff::fuzz::triangles);
}
