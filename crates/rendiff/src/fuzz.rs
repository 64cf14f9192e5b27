//! Entry points of the fuzz targets (`fuzz/`), shared with the test that
//! replays their committed corpora (`tests/it/fuzz_corpus.rs`). Each takes
//! arbitrary bytes and must neither panic nor produce a non-finite pixel:
//! every input ends in a picture or an error value.

use std::path::Path;

use crate::accel::{Accel, AccelOptions};
use crate::budget::Budget;
use crate::camera::{Camera, Projection};
use crate::frame::Frame;
use crate::math::{DVec3, Vec3};
use crate::options::{DepthFormat, ShadowMode};
use crate::polygon::{PolygonOptions, triangulate};
use crate::raster::{self, RasterOptions};
use crate::scene::Scene;
use crate::tri_scene::TriScene;
use crate::{Backend, GATE_EPS, Overrides, Prepared};

/// Panics if a frame holds a non-finite colour: the one property every
/// render must keep (DESIGN.md §5: never a NaN pixel).
fn assert_finite(frame: &Frame, what: &str) {
    assert!(
        frame.color.iter().all(|c| c.is_finite()),
        "{what}: a non-finite pixel"
    );
}

/// A scene file: parsed as UTF-8 TOML with `dir/fuzz.toml` as its path
/// (so relative mesh and image paths resolve in `dir`); if it loads, it is
/// prepared at 16×12 with a 64 MiB memory budget and rendered by all four
/// backends.
pub fn scene_text(dir: &Path, data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(scene) = Scene::from_str(&dir.join("fuzz.toml"), text) else {
        return;
    };
    let Ok(job) = Prepared::from_scene(scene, &small()) else {
        return;
    };
    render_and_export(
        &job,
        &[
            Backend::Raster,
            Backend::Ray,
            Backend::Painter,
            Backend::Bsp,
        ],
        crate::options::Geometry::Analytic,
        "scene",
    );
}

/// What the scene entry points render with: 16×12, one sample per pixel,
/// a 64 MiB memory budget.
fn small() -> Overrides {
    Overrides {
        size: Some((16, 12)),
        samples: Some(1),
        memory_budget: Some(64 << 20),
        ..Overrides::default()
    }
}

/// Renders `job` with each of `backends` (within the fuzz budget a render
/// may be refused; never a panic or a non-finite pixel) and exports it to
/// SDL, which must pass [`check_sdl`]; returns the ray tracer's frame when
/// it rendered.
fn render_and_export(
    job: &Prepared,
    backends: &[Backend],
    geometry: crate::options::Geometry,
    what: &str,
) -> Option<Frame> {
    let mut ray = None;
    for &backend in backends {
        if let Ok(r) = job.render(backend) {
            assert_finite(&r.frame, what);
            if backend == Backend::Ray {
                ray = Some(r.frame);
            }
        }
    }
    let opts = crate::pov::ExportOptions {
        geometry,
        max_depth: 5,
        abridged: false,
    };
    if let Ok(export) = crate::pov::export(&job.scene, &job.tri, &opts) {
        check_sdl(&export.text);
    }
    ray
}

/// A scene with the files it refers to, across the file system: `data`
/// is split at its first two `0xFF` bytes into scene text, the bytes of
/// `m.obj` and the bytes of `t.png`, written into a fresh folder (with a
/// link `l.png` to `t.png`, so one texture can be named two ways). The
/// scene is loaded from disk through the same readers as the command line
/// and, if it loads, rendered at 16×12 by both backends within a 64 MiB
/// budget, exported to POV-Ray SDL (checked by [`check_sdl`]) and written
/// as a PNG; afterwards the folder holds exactly what was put there and
/// the one output.
///
/// # Panics
///
/// On a non-finite pixel, SDL that could run anything but the export's own
/// code, or a file left behind.
pub fn scene_files(data: &[u8]) {
    let mut parts = data.splitn(3, |&b| b == 0xFF);
    let text = parts.next().unwrap_or_default();
    let obj = parts.next().unwrap_or_default();
    let png = parts.next().unwrap_or_default();
    let Ok(dir) = tempfile::tempdir() else {
        return;
    };
    let d = dir.path();
    let inputs = [("s.toml", text), ("m.obj", obj), ("t.png", png)];
    for (name, bytes) in inputs {
        let written =
            crate::image_io::write_atomic(&d.join(name), |f| std::io::Write::write_all(f, bytes));
        if written.is_err() {
            return;
        }
    }
    if std::os::unix::fs::symlink(d.join("t.png"), d.join("l.png")).is_err() {
        return;
    }
    let mut expected = vec!["l.png", "m.obj", "s.toml", "t.png"];
    if let Ok(job) = Prepared::load(&d.join("s.toml"), &small()) {
        let ray = render_and_export(
            &job,
            &[Backend::Raster, Backend::Ray],
            crate::options::Geometry::Mesh,
            "scene files",
        );
        // The output's own name, and no other.
        if ray.is_some_and(|f| {
            f.write_png(&d.join("o.png"), crate::image_io::PngEncoding::Srgb8)
                .is_ok()
        }) {
            expected.push("o.png");
        }
    }
    let mut found: Vec<String> = std::fs::read_dir(d)
        .map(|r| {
            r.filter_map(Result::ok)
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    found.sort();
    expected.sort_unstable();
    assert_eq!(found, expected, "the folder changed beyond the one output");
}

/// Checks exported SDL the way POV-Ray's tokenizer would see it: the only
/// directive is the first line's `#version 3.7;`; every string closes on
/// its own line and holds no unescaped quote; comments are `//` to the end
/// of a line; braces, brackets and parentheses balance and never close
/// more than was opened. A scene string that escaped its literal or its
/// comment (a file name with a quote, a name with a newline) breaks one of
/// these.
///
/// # Panics
///
/// On the first rule broken, with the line.
pub(crate) fn check_sdl(text: &str) {
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("#version 3.7;"),
        "SDL must start with #version"
    );
    let mut depth = [0usize; 3];
    for (k, line) in lines.enumerate() {
        let n = k + 2;
        let mut chars = line.chars().peekable();
        while let Some(c) = chars.next() {
            match c {
                '/' if chars.peek() == Some(&'/') => break,
                '"' => loop {
                    match chars.next() {
                        None => panic!("line {n}: a string runs past the end of its line"),
                        Some('\\') => {
                            assert!(
                                matches!(chars.next(), Some('"' | '\\')),
                                "line {n}: an escape other than \\\" or \\\\"
                            );
                        }
                        Some('"') => break,
                        Some(c) => {
                            assert!((' '..='~').contains(&c), "line {n}: a string holds {c:?}")
                        }
                    }
                },
                '#' => panic!("line {n}: a directive outside a string or comment: {line}"),
                '{' | '[' | '(' => depth["{[(".find(c).unwrap_or(0)] += 1,
                '}' | ']' | ')' => {
                    let d = &mut depth["}])".find(c).unwrap_or(0)];
                    *d = d
                        .checked_sub(1)
                        .unwrap_or_else(|| panic!("line {n}: `{c}` closes nothing"));
                }
                c => assert!(
                    c == '\t' || (' '..='~').contains(&c),
                    "line {n}: {c:?} outside a string or comment"
                ),
            }
        }
    }
    assert_eq!(
        depth,
        [0, 0, 0],
        "unbalanced braces, brackets or parentheses"
    );
}

/// An OBJ file's bytes.
pub fn obj_bytes(data: &[u8]) {
    let _ = crate::scene::obj::load_obj_bytes(Path::new("fuzz.obj"), data);
}

/// A PNG file's bytes (as a texture or a bump map); a decoded texture is
/// sampled at a few points, which must be finite.
pub fn png_bytes(data: &[u8]) {
    if let Ok(t) = crate::texture::Texture::from_png_bytes(Path::new("fuzz.png"), data) {
        for (x, y) in [(0.0, 0.0), (0.5, 0.5), (-3.7, 12.2), (1e6, -1e6)] {
            let s = t.bilinear(x, y);
            assert!(s.iter().all(|v| v.is_finite()), "a non-finite texel");
        }
    }
}

/// Reads `n` little-endian f32 from the front of `data` (zero past its end).
fn floats(data: &[u8], n: usize) -> Vec<f32> {
    (0..n)
        .map(|i| {
            let mut b = [0u8; 4];
            for (k, byte) in b.iter_mut().enumerate() {
                *byte = data.get(4 * i + k).copied().unwrap_or(0);
            }
            f32::from_le_bytes(b)
        })
        .collect()
}

/// A polygon: the first byte gives the outline's corner count (3 … 34,
/// its low five bits) and the hole count (0 … 3, its top two bits; each
/// hole has 4 corners), the rest the
/// coordinates as f32 (any value: NaN, infinite, repeated, crossing).
pub fn polygon(data: &[u8]) {
    let Some((&head, rest)) = data.split_first() else {
        return;
    };
    let n = 3 + usize::from(head & 31);
    let holes = usize::from(head >> 6);
    let total = n + holes * 4;
    let f = floats(rest, 3 * total);
    let p = |k: usize| {
        DVec3::new(
            f64::from(f[3 * k]),
            f64::from(f[3 * k + 1]),
            f64::from(f[3 * k + 2]),
        )
    };
    let outline: Vec<DVec3> = (0..n).map(p).collect();
    let hole_rings: Vec<Vec<DVec3>> = (0..holes)
        .map(|h| (0..4).map(|k| p(n + 4 * h + k)).collect())
        .collect();
    // Both as a scene polygon (planarity checked) and as an OBJ face
    // (projected onto its Newell plane).
    for check_planarity in [true, false] {
        if let Ok(t) = triangulate(&outline, &hole_rings, PolygonOptions { check_planarity }) {
            assert!(!t.triangles.is_empty(), "a valid polygon with no triangles");
        }
    }
}

/// Triangles and a camera from raw bytes — any f32, finite or not — rendered
/// by the rasterizer and the ray tracer at 12×9.
pub fn triangles(data: &[u8]) {
    let Some((&head, rest)) = data.split_first() else {
        return;
    };
    let count = usize::from(head % 24) + 1;
    let f = floats(rest, 12 + 9 * count);
    let tris: Vec<[Vec3; 3]> = (0..count)
        .map(|t| {
            let b = 12 + 9 * t;
            [0, 3, 6].map(|o| Vec3::new(f[b + o], f[b + o + 1], f[b + o + 2]))
        })
        .collect();
    // Non-finite coordinates never reach a renderer: written as an OBJ
    // file, the loader must refuse them at the first such vertex's line.
    // Finite ones of any size (beyond the loader's ±1e12 too) must render
    // without a panic or a non-finite pixel.
    if let Some(first) = tris.iter().flatten().position(|p| !p.is_finite()) {
        let mut obj = String::new();
        for p in tris.iter().flatten() {
            obj.push_str(&format!("v {} {} {}\n", p.x, p.y, p.z));
        }
        for t in 0..tris.len() {
            obj.push_str(&format!("f {} {} {}\n", 3 * t + 1, 3 * t + 2, 3 * t + 3));
        }
        match crate::scene::obj::load_obj_bytes(Path::new("fuzz.obj"), obj.as_bytes()) {
            Ok(_) => panic!("an OBJ file with a non-finite vertex was accepted"),
            Err(e) => {
                let e = e.to_string();
                assert!(
                    e.starts_with(&format!("fuzz.obj:{}:", first + 1))
                        && e.contains("not a finite number"),
                    "not refused at line {}: {e}",
                    first + 1
                );
            }
        }
        return;
    }
    let v = |k: usize| DVec3::new(f64::from(f[k]), f64::from(f[k + 1]), f64::from(f[k + 2]));
    let projection = if head & 0x80 == 0 {
        Projection::Perspective {
            tan_half_fov: f64::from(f[9]).abs(),
        }
    } else {
        Projection::Orthographic {
            view_height: f64::from(f[9]).abs(),
        }
    };
    let near = f64::from(f[10]).abs();
    let far = f64::from(f[11]).abs();
    let Ok(camera) = Camera::new(
        v(0),
        v(3),
        v(6),
        projection,
        12,
        9,
        1 + u32::from(head & 0x40 != 0),
        near,
        far,
    ) else {
        return;
    };
    let scene = TriScene::from_triangles(camera, &tris);
    let opts = RasterOptions {
        depth: DepthFormat::F32,
        shadows: ShadowMode::Rays,
        shadows_needed: false,
        gate_eps: GATE_EPS,
        frustum_cull: vec![false; scene.objects.len()],
        backface_cull: vec![false; scene.objects.len()],
        perturb: raster::Perturb::default(),
    };
    assert_finite(&raster::render(&scene, &opts).0, "raster");
    // The BSP tree of the same triangles (within the fuzz budget).
    if let Ok((frame, _, _)) = raster::bsp::render(&scene, &opts, &Budget::new(64 << 20)) {
        assert_finite(&frame, "bsp");
    }
    let accel = Accel::new(&scene, AccelOptions::default());
    let frame = crate::ray::render(
        &accel,
        &crate::ray::RayOptions {
            max_depth: 1,
            shadows: false,
            gate_eps: GATE_EPS,
        },
    );
    assert_finite(&frame, "ray");
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bytes of [`triangles`]: a header byte, then the floats.
    fn encode(head: u8, floats: &[f32]) -> Vec<u8> {
        let mut d = vec![head];
        for f in floats {
            d.extend_from_slice(&f.to_le_bytes());
        }
        d
    }

    const CAMERA: [f32; 12] = [0.0, 0.0, 5.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.5, 0.1, 100.0];

    #[test]
    fn triangles_checks_the_loader_refuses_non_finite_vertices() {
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let mut f = CAMERA.to_vec();
            f.extend_from_slice(&[bad, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
            triangles(&encode(0, &f));
        }
        let obj = "v 0 0 0\nv NaN 0 0\nv 0 1 0\nf 1 2 3\n";
        let e = crate::scene::obj::load_obj_bytes(Path::new("fuzz.obj"), obj.as_bytes())
            .expect_err("a NaN vertex is refused");
        assert!(e.to_string().contains("fuzz.obj:2"), "{e}");
    }

    #[test]
    fn triangles_renders_a_finite_triangle() {
        let mut f = CAMERA.to_vec();
        f.extend_from_slice(&[-1.0, -1.0, 0.0, 1.0, -1.0, 0.0, 0.0, 1.0, 0.0]);
        triangles(&encode(0, &f));
        triangles(&encode(0x80 | 0x40, &f));
    }

    #[test]
    fn escaped_sdl_passes() {
        check_sdl(
            "#version 3.7;\n// a \"comment #x\n  pigment { image_map { png \"a\\\" #b.png\" } }\n",
        );
    }

    #[test]
    #[should_panic(expected = "a directive outside a string or comment")]
    fn a_name_that_left_its_literal_is_found() {
        check_sdl(
            "#version 3.7;\npigment { image_map { png \"t.png\" } } #fopen F \"x\" write \"\" }\n",
        );
    }

    #[test]
    #[should_panic(expected = "runs past the end of its line")]
    fn a_string_split_by_a_newline_is_found() {
        check_sdl("#version 3.7;\npng \"a\n#b\"\n");
    }

    #[test]
    #[should_panic(expected = "closes nothing")]
    fn an_extra_brace_is_found() {
        check_sdl("#version 3.7;\nsphere { 0, 1 } }\n");
    }
}
