//! Regression images per backend: every bundled scene against
//! `golden/raster/NAME.png` and `golden/ray/NAME.png` (16-bit linear).
//!
//! A golden passes when the render, quantised to the golden's 16-bit
//! linear codes, differs from it by at most 2 codes (2/65535) on at most
//! 0.1 % of the pixels (the reftest pair, in the golden's own units): the
//! renders are deterministic, so on the machine that blessed them the
//! difference is 0; the slack is for libm differences between platforms
//! (a few ulps of f32 shading, far below one 16-bit code on most pixels).
//!
//! A missing golden fails the test and is written beside the others as
//! `NAME.new.png` for review. `UPDATE_GOLDEN=1` (or `make bless`)
//! rewrites the goldens that fail, and only those. On failure the render,
//! the golden and a difference image are left under
//! `target/tmp/image-diffs/golden/`.

use std::path::{Path, PathBuf};

use rendiff::color::{Rgb, to_linear16};
use rendiff::image_io::{PngEncoding, read_png_linear, write_png};
use rendiff::{Backend, Overrides};

use crate::util::{bundled_scenes, load, root};

/// Largest 16-bit code difference and fraction of pixels that may differ.
const MAX_CODES: u16 = 2;
const MAX_FRACTION: f64 = 0.001;

/// The reftest pair in 16-bit linear codes: (largest difference, pixels differing).
fn fuzzy_pair(a: &[Rgb], b: &[Rgb]) -> (u16, usize) {
    let mut max = 0u16;
    let mut count = 0usize;
    for (p, q) in a.iter().zip(b) {
        let d = [(p.r, q.r), (p.g, q.g), (p.b, q.b)]
            .iter()
            .map(|(x, y)| to_linear16(*x).abs_diff(to_linear16(*y)))
            .max()
            .unwrap_or(0);
        max = max.max(d);
        count += usize::from(d > 0);
    }
    (max, count)
}

fn artifact_dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("image-diffs/golden")
        .join(name);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn renders_match_their_goldens() {
    let update = std::env::var("UPDATE_GOLDEN").is_ok_and(|v| v == "1");
    let mut failures = Vec::new();
    let mut checked = 0;
    for name in bundled_scenes() {
        let job = load(&name, &Overrides::default());
        for backend in [Backend::Raster, Backend::Ray] {
            let frame = job.render(backend).unwrap().frame;
            let (w, h) = (frame.width, frame.height);
            let dir = root().join("golden").join(backend.to_string());
            let path = dir.join(format!("{name}.png"));
            let label = format!("{backend}/{name}");
            if !path.exists() {
                if update {
                    write_png(&path, w, h, &frame.color, PngEncoding::Linear16).unwrap();
                } else {
                    let new = dir.join(format!("{name}.new.png"));
                    write_png(&new, w, h, &frame.color, PngEncoding::Linear16).unwrap();
                    failures.push(format!(
                        "{label}: no golden; wrote {} for review (accept with make bless)",
                        new.display()
                    ));
                }
                continue;
            }
            let golden = read_png_linear(&path).unwrap();
            assert!(
                golden.linear16,
                "{}: goldens are 16-bit linear",
                path.display()
            );
            let same_size = (golden.width, golden.height) == (w, h);
            let stats = same_size.then(|| fuzzy_pair(&golden.pixels, &frame.color));
            let ok = stats.is_some_and(|(max, count)| {
                max <= MAX_CODES && (count as f64) <= MAX_FRACTION * f64::from(w * h)
            });
            checked += 1;
            if ok {
                continue;
            }
            if update {
                write_png(&path, w, h, &frame.color, PngEncoding::Linear16).unwrap();
                continue;
            }
            let art = artifact_dir(&format!("{backend}-{name}"));
            write_png(
                &art.join("actual.png"),
                w,
                h,
                &frame.color,
                PngEncoding::Srgb8,
            )
            .unwrap();
            write_png(
                &art.join("expected.png"),
                golden.width,
                golden.height,
                &golden.pixels,
                PngEncoding::Srgb8,
            )
            .unwrap();
            if same_size {
                let diff: Vec<Rgb> = golden
                    .pixels
                    .iter()
                    .zip(&frame.color)
                    .map(|(a, b)| {
                        let d = a.max_abs_diff(*b) * 16.0;
                        Rgb::splat(d)
                    })
                    .collect();
                write_png(&art.join("diff.png"), w, h, &diff, PngEncoding::Srgb8).unwrap();
            }
            failures.push(format!(
                "{label}: (largest 16-bit difference, pixels differing) = {stats:?} (artifacts in {})",
                art.display()
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "goldens differ:\n{}",
        failures.join("\n")
    );
    assert!(checked >= 24 || update, "only {checked} goldens checked");
}
