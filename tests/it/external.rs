//! Another renderer's G-buffer (colour, triangle ids, depth) compared with
//! rendiff's backends: its disagreements are classified like a backend's,
//! so a renderer that loses surfaces is caught, sample by sample.

use std::path::Path;
use std::process::Command;

use rendiff::image_io;

use crate::util::scene_path;

fn rendiff(args: &[&str], dir: &Path) -> (i32, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap();
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stdout).into_owned() + &String::from_utf8_lossy(&o.stderr),
    )
}

const SIZE: &str = "96x72";

/// The ray tracer's G-buffer written as another renderer would hand it
/// over: `color.png`, `id.png`, `depth.pfm` (what `render --gbuffer`
/// writes).
fn export(scene: &str, dir: &Path) {
    let s = scene_path(scene);
    let (code, text) = rendiff(
        &[
            "render",
            s.to_str().unwrap(),
            "--backend",
            "ray",
            "--max-depth",
            "1",
            "--samples",
            "1",
            "--size",
            SIZE,
            "-o",
            "picture.png",
            "--gbuffer",
            "g",
        ],
        dir,
    );
    assert_eq!(code, 0, "{text}");
}

fn diff(scene: &str, dir: &Path, b: &str) -> (i32, serde_json::Value, String) {
    let s = scene_path(scene);
    let (code, text) = rendiff(
        &[
            "diff",
            s.to_str().unwrap(),
            "--a",
            "raster",
            "--b",
            b,
            "--samples",
            "1",
            "--size",
            SIZE,
            "--json",
        ],
        dir,
    );
    let v = serde_json::from_str(&text).unwrap_or(serde_json::Value::Null);
    (code, v, text)
}

#[test]
fn an_external_gbuffer_is_classified_like_a_backend() {
    for scene in ["menagerie", "polygons", "spheres"] {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        export(scene, dir);
        let (code_ext, ext, text) = diff(scene, dir, "g");
        let (_, own, _) = diff(scene, dir, "ray");
        assert_eq!(ext["visibility"], own["visibility"], "{scene}: {text}");
        // Its colours came through a 16-bit PNG: no difference beyond that.
        assert_eq!(ext["shading"]["over_threshold"], 0, "{scene}: {text}");
        assert_eq!(code_ext, 0, "{scene}: {text}");
    }
}

#[test]
fn a_renderer_that_loses_a_region_of_floor_fails_with_real_samples() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    export("spheres", dir);
    let g = dir.join("g");
    let (w, h) = (96u32, 72u32);
    let budget = rendiff::budget::Budget::default();
    let mut ids = image_io::read_png_u32_within(&g.join("id.png"), (w, h), &budget).unwrap();
    let mut depth = image_io::read_pfm_within(&g.join("depth.pfm"), (w, h), &budget).unwrap();
    // The bottom ten rows (floor) seen as background, as a ray tracer
    // whose rays leak through the floor would report them.
    let mut lost = 0;
    for y in h - 10..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            if ids[i] != 0 {
                lost += 1;
            }
            ids[i] = 0;
            depth[i] = f32::INFINITY;
        }
    }
    assert!(lost > 500);
    image_io::write_png_u32(&g.join("id.png"), w, h, &ids).unwrap();
    image_io::write_pfm(&g.join("depth.pfm"), w, h, &depth).unwrap();
    let (code, v, text) = diff("spheres", dir, "g");
    assert_eq!(code, 1, "{text}");
    assert_eq!(
        v["visibility"]["real"], lost,
        "every lost sample is real: {text}"
    );
}

#[test]
fn a_broken_gbuffer_is_refused_naming_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    export("spheres", dir);
    let g = dir.join("g");
    let budget = rendiff::budget::Budget::default();
    let mut ids = image_io::read_png_u32_within(&g.join("id.png"), (96, 72), &budget).unwrap();
    ids[5] = 1_000_000;
    image_io::write_png_u32(&g.join("id.png"), 96, 72, &ids).unwrap();
    let (code, _, text) = diff("spheres", dir, "g");
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("id.png") && text.contains("(5, 0)"), "{text}");
    // Another size than the sample grid.
    image_io::write_pfm(&g.join("depth.pfm"), 4, 4, &[1.0; 16]).unwrap();
    ids[5] = 1;
    image_io::write_png_u32(&g.join("id.png"), 96, 72, &ids).unwrap();
    let (code, _, text) = diff("spheres", dir, "g");
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("depth.pfm") && text.contains("4x4"), "{text}");
    // A missing file.
    std::fs::remove_file(g.join("color.png")).unwrap();
    let (code, _, text) = diff("spheres", dir, "g");
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("color.png"), "{text}");
}

#[test]
fn a_supersampled_gbuffer_is_read_at_its_sample_grid() {
    // What `render --gbuffer` writes at 2×2 samples is what `diff --b`
    // reads: colour, ids and depth at the 192×144 sample grid.
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let s = scene_path("spheres");
    let s = s.to_str().unwrap();
    let (code, text) = rendiff(
        &[
            "render",
            s,
            "--backend",
            "ray",
            "--max-depth",
            "1",
            "--samples",
            "2",
            "--size",
            SIZE,
            "-o",
            "p.png",
            "--gbuffer",
            "g",
        ],
        dir,
    );
    assert_eq!(code, 0, "{text}");
    let (code, text) = rendiff(
        &[
            "diff",
            s,
            "--a",
            "raster",
            "--b",
            "g",
            "--samples",
            "2",
            "--size",
            SIZE,
            "--json",
        ],
        dir,
    );
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["visibility"]["real"], 0, "{text}");
    assert_eq!(v["shading"]["over_threshold"], 0, "{text}");
    assert_eq!(code, 0, "{text}");
}
