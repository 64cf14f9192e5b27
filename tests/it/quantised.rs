//! Comparing with an 8-bit or 16-bit PNG, the way people test their own
//! renderer: the PNG's rounding is not a difference, one code of change is.

use std::path::Path;
use std::process::Command;

use rendiff::color::Rgb;
use rendiff::image_io::{self, PngEncoding};

use crate::util::scene_path;

fn rendiff(args: &[&str], dir: &Path) -> (i32, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap();
    let text =
        String::from_utf8_lossy(&o.stdout).into_owned() + &String::from_utf8_lossy(&o.stderr);
    (o.status.code().unwrap_or(-1), text)
}

fn over(json: &str) -> u64 {
    let v: serde_json::Value = serde_json::from_str(json).unwrap();
    v["shading"]["over_threshold"].as_u64().unwrap()
}

/// Renders `scene` with the ray tracer into `png` (8-bit or 16-bit).
fn render(scene: &str, png: &Path, linear16: bool, dir: &Path) {
    let s = scene_path(scene);
    let mut args = vec![
        "render",
        s.to_str().unwrap(),
        "--backend",
        "ray",
        "--size",
        "96x72",
    ];
    args.extend(["-o", png.to_str().unwrap()]);
    if linear16 {
        args.push("--linear16");
    }
    let (code, text) = rendiff(&args, dir);
    assert_eq!(code, 0, "{text}");
}

fn diff_json(scene: &str, png: &Path, dir: &Path) -> (i32, String) {
    let s = scene_path(scene);
    rendiff(
        &[
            "diff",
            s.to_str().unwrap(),
            "--a",
            "ray",
            "--b",
            png.to_str().unwrap(),
            "--size",
            "96x72",
            "--json",
        ],
        dir,
    )
}

#[test]
fn an_image_is_never_over_against_its_own_rounding() {
    // rendiff's own render stored as 8-bit sRGB and as 16-bit linear: the
    // same frame, rounded once. Every scene, every pixel within its code.
    let dir = tempfile::tempdir().unwrap();
    for scene in ["menagerie", "textured", "glass", "bumps", "inside"] {
        for linear16 in [false, true] {
            let png = dir.path().join(format!("{scene}-{linear16}.png"));
            render(scene, &png, linear16, dir.path());
            let (code, json) = diff_json(scene, &png, dir.path());
            assert_eq!(over(&json), 0, "{scene} linear16={linear16}: {json}");
            assert!(code == 0 || code == 1, "{json}");
        }
    }
}

#[test]
fn one_code_of_change_is_over_even_where_the_image_is_dark() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("ref.png");
    render("menagerie", &png, false, dir.path());
    let img = image_io::read_png_linear(&png).unwrap();
    // The darkest and the brightest pixel: one code there is 1.5e-4 and
    // 4.4e-3 in linear, the range a single global bound cannot span.
    let lum = |c: &Rgb| c.r + c.g + c.b;
    let idx = |best: fn(f32, f32) -> bool| {
        (0..img.pixels.len())
            .reduce(|i, j| {
                if best(lum(&img.pixels[j]), lum(&img.pixels[i])) {
                    j
                } else {
                    i
                }
            })
            .unwrap()
    };
    for k in [idx(|a, b| a < b), idx(|a, b| a > b)] {
        let mut px = img.pixels.clone();
        let code = rendiff::color::to_srgb8(px[k].g);
        let moved = if code == 255 { code - 1 } else { code + 1 };
        px[k].g = rendiff::color::srgb_decode(f32::from(moved) / 255.0);
        let changed = dir.path().join(format!("changed-{k}.png"));
        image_io::write_png(&changed, img.width, img.height, &px, PngEncoding::Srgb8).unwrap();
        let (code, json) = diff_json("menagerie", &changed, dir.path());
        assert_eq!(over(&json), 1, "pixel {k}: {json}");
        assert_eq!(code, 1, "a changed pixel fails the verdict");
    }
}

#[test]
fn two_images_compare_without_a_scene_and_a_fuzzy_rule_is_the_users() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("ref.png");
    render("spheres", &png, false, dir.path());
    let img = image_io::read_png_linear(&png).unwrap();
    let mut px = img.pixels.clone();
    // Three pixels changed by 3 codes each.
    for k in [10usize, 500, 3000] {
        let c = rendiff::color::to_srgb8(px[k].r);
        let moved = if c >= 3 { c - 3 } else { c + 3 };
        px[k].r = rendiff::color::srgb_decode(f32::from(moved) / 255.0);
    }
    let changed = dir.path().join("changed.png");
    image_io::write_png(&changed, img.width, img.height, &px, PngEncoding::Srgb8).unwrap();
    let (p, c) = (png.to_str().unwrap(), changed.to_str().unwrap());
    let (code, json) = rendiff(&["diff", p, p, "--json"], dir.path());
    assert_eq!((code, over(&json)), (0, 0), "{json}");
    let (code, json) = rendiff(&["diff", p, c, "--json"], dir.path());
    assert_eq!((code, over(&json)), (1, 3), "{json}");
    // The user's rule decides, and says so; it may be looser than the
    // derived one, and it still fails when exceeded.
    for (rule, want) in [("3,3", 0), ("2,3", 1), ("3,2", 1)] {
        let (code, json) = rendiff(&["diff", p, c, "--json", "--fuzzy", rule], dir.path());
        assert_eq!(code, want, "--fuzzy {rule}: {json}");
        let v: serde_json::Value = serde_json::from_str(&json).unwrap();
        assert!(v["tolerance"]["fuzzy"].is_object(), "{json}");
    }
    let (_, text) = rendiff(&["diff", p, c, "--fuzzy", "3,3"], dir.path());
    assert!(text.contains("the user's fuzzy rule"), "{text}");
    // A size mismatch names the file; a mix of image and scene is refused.
    let small = dir.path().join("small.png");
    image_io::write_png(&small, 2, 2, &[Rgb::BLACK; 4], PngEncoding::Srgb8).unwrap();
    let (code, text) = rendiff(&["diff", p, small.to_str().unwrap()], dir.path());
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("small.png"), "{text}");
    let s = scene_path("spheres");
    let (code, text) = rendiff(&["diff", s.to_str().unwrap(), p], dir.path());
    assert_eq!(code, 2, "{text}");
}

#[test]
fn the_scenes_fuzzy_table_is_read_and_checked() {
    let dir = tempfile::tempdir().unwrap();
    let base = std::fs::read_to_string(scene_path("spheres")).unwrap();
    // The scene's textures, beside the copy.
    let textures = scene_path("spheres").parent().unwrap().join("textures");
    std::fs::create_dir(dir.path().join("textures")).unwrap();
    for f in std::fs::read_dir(textures).unwrap() {
        let f = f.unwrap().path();
        std::fs::copy(&f, dir.path().join("textures").join(f.file_name().unwrap())).unwrap();
    }
    let scene = dir.path().join("s.toml");
    let png = dir.path().join("ref.png");
    let write = |extra: &str| {
        std::fs::write(&scene, format!("{base}\n[tolerance]\n{extra}\n")).unwrap();
    };
    write("fuzzy = { max_diff = 3, pixels = 1 }");
    let args = |out: &Path| {
        vec![
            "render".to_string(),
            scene.to_str().unwrap().to_string(),
            "--backend".into(),
            "ray".into(),
            "-o".into(),
            out.to_str().unwrap().to_string(),
        ]
    };
    let a: Vec<String> = args(&png);
    let (code, text) = rendiff(
        &a.iter().map(String::as_str).collect::<Vec<_>>(),
        dir.path(),
    );
    assert_eq!(code, 0, "{text}");
    let img = image_io::read_png_linear(&png).unwrap();
    let mut px = img.pixels.clone();
    px[7].b = if px[7].b > 0.5 { 0.0 } else { 1.0 };
    let changed = dir.path().join("changed.png");
    image_io::write_png(&changed, img.width, img.height, &px, PngEncoding::Srgb8).unwrap();
    let diff = |png: &Path| {
        rendiff(
            &[
                "diff",
                scene.to_str().unwrap(),
                "--a",
                "ray",
                "--b",
                png.to_str().unwrap(),
                "--json",
            ],
            dir.path(),
        )
    };
    // One pixel over, but by far more than 3 codes: the rule fails it.
    let (code, json) = diff(&changed);
    assert_eq!((code, over(&json)), (1, 1), "{json}");
    write("fuzzy = { max_diff = 255, pixels = 1 }");
    let (code, json) = diff(&changed);
    assert_eq!(code, 0, "{json}");
    for (bad, key) in [
        ("fuzzy = { max_diff = 256, pixels = 1 }", "max_diff"),
        ("fuzzy = { max_diff = 2 }", "pixels"),
        ("fuzzy = { max_diff = 2, pixels = -1 }", "pixels"),
        ("fuzzy = { max_diff = 2, pixels = 1, pixel = 3 }", "pixel"),
    ] {
        write(bad);
        let (code, text) = diff(&changed);
        assert_eq!(code, 2, "{bad}: {text}");
        assert!(
            text.contains(key) && text.contains("s.toml"),
            "{bad}: {text}"
        );
    }
}

#[test]
fn float_images_compare_exactly() {
    // A colour PFM (PF, little-endian, rows bottom to top) and a grey one.
    let dir = tempfile::tempdir().unwrap();
    let write_pf = |name: &str, values: &[f32]| {
        let mut bytes = b"PF\n4 3\n-1.0\n".to_vec();
        for v in values {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        std::fs::write(dir.path().join(name), bytes).unwrap();
    };
    let base: Vec<f32> = (0..36u8).map(|k| f32::from(k) / 40.0).collect();
    write_pf("a.pfm", &base);
    write_pf("same.pfm", &base);
    let mut moved = base.clone();
    moved[7] += 1e-6;
    write_pf("moved.pfm", &moved);
    let run = |b: &str, extra: &[&str]| {
        let mut args = vec!["diff", "a.pfm", b, "--json"];
        args.extend(extra);
        let (code, json) = rendiff(&args, dir.path());
        (code, over(&json))
    };
    assert_eq!(run("same.pfm", &[]), (0, 0));
    // A float stores its value: a change of 1e-6 is a difference.
    assert_eq!(run("moved.pfm", &[]), (1, 1));
    assert_eq!(run("moved.pfm", &["--fuzzy", "0,1"]), (0, 1));
    // Not a PFM: exit 2 naming the file.
    std::fs::write(dir.path().join("bad.pfm"), b"P6\n1 1\n255\n...").unwrap();
    let (code, text) = rendiff(&["diff", "a.pfm", "bad.pfm"], dir.path());
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("bad.pfm"), "{text}");
    // A scale of zero, NaN or infinity gives no byte order: refused, naming
    // the file and the scale (it was read as big-endian).
    for scale in ["0.0", "-0", "nan", "inf", "-inf"] {
        let mut bytes = format!("PF\n4 3\n{scale}\n").into_bytes();
        for v in &base {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        std::fs::write(dir.path().join("scale.pfm"), bytes).unwrap();
        let (code, text) = rendiff(&["diff", "a.pfm", "scale.pfm"], dir.path());
        assert_eq!(code, 2, "{scale}: {text}");
        assert!(
            text.contains("scale.pfm") && text.contains("byte order"),
            "{scale}: {text}"
        );
    }
}

#[test]
fn openexr_images_compare_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, bump: f32| {
        exr::prelude::write_rgb_file(dir.path().join(name), 6, 4, |x, y| {
            #[expect(clippy::cast_precision_loss, reason = "a 6x4 image")]
            let v = (x + 6 * y) as f32 / 24.0;
            let extra = if (x, y) == (2, 3) { bump } else { 0.0 };
            (v, v * 0.5 + extra, 1.0 - v)
        })
        .unwrap();
    };
    write("a.exr", 0.0);
    write("same.exr", 0.0);
    write("moved.exr", 1e-3);
    let (code, json) = rendiff(&["diff", "a.exr", "same.exr", "--json"], dir.path());
    assert_eq!((code, over(&json)), (0, 0), "{json}");
    let (code, json) = rendiff(&["diff", "a.exr", "moved.exr", "--json"], dir.path());
    assert_eq!((code, over(&json)), (1, 1), "{json}");
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    let c = &v["clusters"]["list"][0]["box"];
    assert_eq!(
        (c["x0"].as_u64(), c["y0"].as_u64()),
        (Some(2), Some(3)),
        "{json}"
    );
    // An EXR against a PNG of another size: exit 2 naming the file.
    image_io::write_png(
        &dir.path().join("small.png"),
        2,
        2,
        &[Rgb::BLACK; 4],
        PngEncoding::Srgb8,
    )
    .unwrap();
    let (code, text) = rendiff(&["diff", "a.exr", "small.png"], dir.path());
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("small.png"), "{text}");
    std::fs::write(dir.path().join("bad.exr"), b"not an exr").unwrap();
    let (code, text) = rendiff(&["diff", "bad.exr", "a.exr"], dir.path());
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("bad.exr"), "{text}");
}

#[test]
fn red_team_findings_stay_fixed() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Two 8-bit images one code apart differ (their intervals only touch).
    let a: Vec<Rgb> = (0..12u8)
        .map(|k| Rgb::splat(rendiff::color::srgb_decode(f32::from(100 + k) / 255.0)))
        .collect();
    let mut b = a.clone();
    b[5] = Rgb::splat(rendiff::color::srgb_decode(106.0 / 255.0));
    image_io::write_png(&d.join("a.png"), 4, 3, &a, PngEncoding::Srgb8).unwrap();
    image_io::write_png(&d.join("b.png"), 4, 3, &b, PngEncoding::Srgb8).unwrap();
    let (code, json) = rendiff(&["diff", "a.png", "b.png", "--json"], d);
    assert_eq!((code, over(&json)), (1, 1), "{json}");
    // A float image with NaN is refused naming the pixel; HDR values are
    // compared unclamped.
    let write_pf = |name: &str, values: &[f32]| {
        let mut bytes = b"PF\n2 1\n-1.0\n".to_vec();
        for v in values {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        std::fs::write(d.join(name), bytes).unwrap();
    };
    write_pf("nan.pfm", &[0.5, f32::NAN, 0.5, 0.5, 0.5, 0.5]);
    write_pf("two.pfm", &[2.0; 6]);
    write_pf("five.pfm", &[5.0; 6]);
    let (code, text) = rendiff(&["diff", "two.pfm", "nan.pfm"], d);
    assert_eq!(code, 2, "{text}");
    assert!(
        text.contains("nan.pfm") && text.contains("(0, 0)"),
        "{text}"
    );
    let (code, json) = rendiff(&["diff", "two.pfm", "five.pfm", "--json"], d);
    assert_eq!((code, over(&json)), (1, 2), "{json}");
    // Flags that need a scene are refused with two images; --fuzzy with two
    // backends too.
    let (code, text) = rendiff(&["diff", "a.png", "b.png", "--size", "4x3"], d);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("--size"), "{text}");
    let s = scene_path("spheres");
    let (code, text) = rendiff(&["diff", s.to_str().unwrap(), "--fuzzy", "2,2"], d);
    assert_eq!(code, 2, "{text}");
    // report: a folder with no report fails the merge; verdicts are pass or fail.
    std::fs::create_dir(d.join("empty")).unwrap();
    let (code, text) = rendiff(&["report", "empty"], d);
    assert_eq!(code, 2, "{text}");
    std::fs::write(
        d.join("weird.json"),
        r#"{"scene": "x", "verdict": "weird"}"#,
    )
    .unwrap();
    let (code, text) = rendiff(&["report", "weird.json"], d);
    assert_eq!(code, 2, "{text}");
    // review: a size-changed snapshot is a verdict that can be accepted, a
    // pending file that is not a PNG can be rejected but not accepted, and
    // --out makes the nested folders.
    let g = d.join("golden/scenes");
    std::fs::create_dir_all(&g).unwrap();
    image_io::write_png(&g.join("x.ray.png"), 4, 3, &a, PngEncoding::Srgb8).unwrap();
    image_io::write_png(&g.join("x.ray.new.png"), 2, 2, &a[..4], PngEncoding::Srgb8).unwrap();
    image_io::write_png(&g.join("y.ray.png"), 4, 3, &a, PngEncoding::Srgb8).unwrap();
    image_io::write_png(&g.join("y.ray.new.png"), 4, 3, &b, PngEncoding::Srgb8).unwrap();
    std::fs::write(g.join("z.ray.new.png"), "junk").unwrap();
    let (code, text) = rendiff(&["review", "golden", "--accept-all", "--out", "rev"], d);
    assert_eq!(code, 1, "the junk file stays pending: {text}");
    assert!(
        text.contains("differs") && text.contains("not accepted"),
        "{text}"
    );
    assert!(d.join("rev/scenes/y.ray/index.html").exists(), "{text}");
    assert!(!g.join("x.ray.new.png").exists() && !g.join("y.ray.new.png").exists());
    assert!(
        !g.join("z.ray.png").exists(),
        "junk was never made a golden"
    );
    let (code, text) = rendiff(&["review", "golden", "--reject-all"], d);
    assert_eq!(code, 0, "{text}");
    assert!(!g.join("z.ray.new.png").exists());
}

#[test]
fn out_makes_the_folders_of_the_path_it_is_given() {
    // The README's first command writes `--out out/spheres` on a fresh
    // checkout, where `out/` does not exist yet.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let s = scene_path("spheres");
    let (code, text) = rendiff(
        &[
            "diff",
            s.to_str().unwrap(),
            "--size",
            "32x24",
            "--out",
            "out/a/spheres",
        ],
        d,
    );
    assert_eq!(code, 0, "{text}");
    assert!(d.join("out/a/spheres/index.html").is_file(), "{text}");
    // A file in the way is refused by name, and nothing is made.
    std::fs::write(d.join("blocker"), "x").unwrap();
    let (code, text) = rendiff(
        &[
            "diff",
            s.to_str().unwrap(),
            "--size",
            "32x24",
            "--out",
            "blocker/x/y",
        ],
        d,
    );
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("blocker is a file"), "{text}");
}
