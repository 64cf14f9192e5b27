//! Shared helpers of the integration tests.

use std::path::{Path, PathBuf};

use rendiff::{Overrides, Prepared};

/// The crate root.
pub fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// A bundled scene's path.
pub fn scene_path(name: &str) -> PathBuf {
    root().join("scenes").join(format!("{name}.toml"))
}

/// Every bundled scene's name, sorted.
pub fn bundled_scenes() -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(root().join("scenes"))
        .expect("scenes/ exists")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// Loads a bundled scene with overrides.
pub fn load(name: &str, ov: &Overrides) -> Prepared {
    Prepared::load(&scene_path(name), ov).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// Runs `f` on a pool of exactly `n` threads.
pub fn with_threads<T: Send>(n: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .build()
        .expect("thread pool")
        .install(f)
}

/// A small deterministic generator (SplitMix64): tests print the seed they
/// were given, so a failure is reproducible.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.f64()
    }

    /// Uniform in [lo, hi) as f32.
    pub fn rangef(&mut self, lo: f32, hi: f32) -> f32 {
        self.range(f64::from(lo), f64::from(hi)) as f32
    }

    /// Uniform integer in 0..n.
    pub fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n
    }
}
