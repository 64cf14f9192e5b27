//! The interactive HTML report driven in headless Chromium: the page's
//! `#selftest` script clicks the A/B toggle, presses its key, hovers a
//! pixel, clicks the first cluster and switches views through real DOM
//! events, and writes what the page then showed into `<pre id="selftest">`;
//! these tests compare that with the frames and clusters the library
//! computed for the same diff. (Skipped, with a message, only where
//! Chromium is missing; CI sets RENDIFF_REQUIRE_CHROMIUM=1.)

use std::path::{Path, PathBuf};
use std::process::Command;

use rendiff::diff::{self, Side};
use rendiff::options::DepthFormat;
use rendiff::{Backend, Overrides};
use serde_json::Value;

use crate::util::{load, root};

fn chromium() -> Option<PathBuf> {
    let found = ["chromium", "chromium-browser", "google-chrome"]
        .iter()
        .find_map(|name| {
            let o = Command::new("which").arg(name).output().ok()?;
            o.status
                .success()
                .then(|| PathBuf::from(String::from_utf8_lossy(&o.stdout).trim()))
        });
    if found.is_none() {
        assert!(
            std::env::var("RENDIFF_REQUIRE_CHROMIUM").is_err(),
            "chromium is required but not installed"
        );
        eprintln!("skipped: chromium is not installed (install it to run the browser tests)");
    }
    found
}

fn temp(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("report_browser")
        .join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn rendiff(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .args(args)
        .current_dir(root())
        .output()
        .expect("could not run rendiff")
}

/// Opens `page#fragment` headless and returns the self-test's JSON.
fn selftest(browser: &Path, page: &Path, fragment: &str, profile: &Path) -> Value {
    let o = Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            "--window-size=1280,900",
            &format!("--user-data-dir={}", profile.display()),
            "--virtual-time-budget=2000",
            "--dump-dom",
            &format!("file://{}#{fragment}", page.display()),
        ])
        .output()
        .expect("chromium runs");
    let dom = String::from_utf8_lossy(&o.stdout);
    let text = dom
        .split("<pre id=\"selftest\">")
        .nth(1)
        .and_then(|r| r.split("</pre>").next())
        .unwrap_or_else(|| {
            panic!(
                "{}: no self-test output\n{}",
                page.display(),
                String::from_utf8_lossy(&o.stderr)
            )
        });
    let json = text
        .replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&amp;", "&");
    let v: Value = serde_json::from_str(&json).unwrap_or_else(|e| panic!("{e}: {json}"));
    assert!(v.get("error").is_none(), "the self-test threw: {v}");
    v
}

fn cell(v: &Value, key: &str) -> Vec<String> {
    v["hover"]["cells"][key]
        .as_array()
        .unwrap_or_else(|| panic!("no hover cell {key}: {v}"))
        .iter()
        .map(|s| s.as_str().unwrap_or("").to_string())
        .collect()
}

/// Raster (16-bit depth) against ray: depth ties the clusters list; the
/// toggle shows b, a hovered pixel shows both sides' ids, objects,
/// materials and class as the frames hold them, and a click on the first
/// cluster zooms the view onto its box.
#[test]
fn the_report_page_toggles_hovers_and_zooms_to_clusters() {
    let Some(browser) = chromium() else { return };
    let (scene, size) = ("scenes/spheres.toml", (64u32, 48u32));
    let dir = temp("frames");
    let o = rendiff(&[
        "diff",
        scene,
        "--size",
        "64x48",
        "--samples",
        "1",
        "--depth",
        "u16",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(
        matches!(o.status.code(), Some(0 | 1)),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // The same diff in process: the frames and clusters the page shows.
    let job = load(
        "spheres",
        &Overrides {
            size: Some(size),
            samples: Some(1),
            depth: Some(DepthFormat::U16),
            ..Overrides::default()
        },
    );
    let r = diff::diff(
        &job,
        scene,
        &Side::Backend(Backend::Raster),
        &Side::Backend(Backend::Ray),
    )
    .unwrap();
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap();
    assert_eq!(json["schema_version"], 2);
    assert_eq!(
        json["clusters"]["total"].as_u64(),
        Some(r.report.clusters.total as u64)
    );
    let first = r.report.clusters.list.first().expect("a cluster");
    // A pixel of a mismatch (one sample per pixel: the sample itself).
    let k = r
        .comparison
        .classes
        .iter()
        .position(|c| *c != rendiff::compare::Class::Agree)
        .expect("a mismatching sample");
    let (x, y) = (k % size.0 as usize, k / size.0 as usize);
    let (diff::Output::Frame(fa, _), diff::Output::Frame(fb, _)) = (&r.a, &r.b) else {
        panic!("two frames expected")
    };
    let v = selftest(
        &browser,
        &dir.join("index.html"),
        &format!("selftest={x},{y}"),
        &temp("profile-frames"),
    );
    // The toggle.
    assert_eq!(v["shown_before"], "a", "{v}");
    assert_eq!(v["shown_after_click"], "b", "{v}");
    assert_eq!(v["src_after_click"], "./b.png", "{v}");
    assert_eq!(v["caption_after_click"], "B: ray", "{v}");
    assert_eq!(v["shown_after_key"], "a", "{v}");
    // Hover: the G-buffer's values at (x, y).
    let name = |id: u32| {
        if id == rendiff::frame::BACKGROUND {
            ("background".to_string(), "background".to_string())
        } else {
            let o = job.tri.object_of(id).unwrap() as usize;
            (id.to_string(), job.tri.objects[o].label.clone())
        }
    };
    let (ida, oa) = name(fa.id[k]);
    let (idb, ob) = name(fb.id[k]);
    assert_eq!(cell(&v, "id"), [ida, idb], "{v}");
    assert_eq!(cell(&v, "object"), [oa, ob], "{v}");
    assert_eq!(cell(&v, "class"), [r.comparison.classes[k].name()], "{v}");
    assert_eq!(cell(&v, "pixel"), [format!("{x}, {y}")], "{v}");
    let rgb8 = |c: rendiff::color::Rgb| {
        use rendiff::color::to_srgb8;
        format!("{}, {}, {}", to_srgb8(c.r), to_srgb8(c.g), to_srgb8(c.b))
    };
    assert_eq!(
        cell(&v, "rgb8"),
        [rgb8(fa.color[k]), rgb8(fb.color[k])],
        "{v}"
    );
    // The first cluster: zoomed so its box is in view and highlighted.
    let b = &first.bbox;
    assert_eq!(
        v["cluster"]["box"],
        serde_json::json!([b.x0, b.y0, b.x1, b.y1]),
        "{v}"
    );
    let vis: Vec<f64> = v["cluster"]["visible"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert!(
        vis[0] <= f64::from(b.x0)
            && vis[1] <= f64::from(b.y0)
            && vis[2] >= f64::from(b.x1 + 1)
            && vis[3] >= f64::from(b.y1 + 1),
        "the box is not in view: {v}"
    );
    // The largest zoom level up to 64x at which the box and a pixel
    // around it fit the viewport, from 1x before the click.
    assert_eq!(v["zoom_before_cluster"], 1, "{v}");
    let zoom = v["cluster"]["zoom"].as_u64().unwrap();
    let avail: Vec<u64> = v["cluster"]["avail"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_u64().unwrap())
        .collect();
    let expected = [1u64, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64]
        .into_iter()
        .filter(|&l| {
            (u64::from(b.width()) + 2) * l <= avail[0]
                && (u64::from(b.height()) + 2) * l <= avail[1]
        })
        .max()
        .unwrap_or(1);
    assert_eq!(zoom, expected, "{v}");
    assert!(
        zoom > 1,
        "a {}x{} cluster is zoomed in: {v}",
        b.width(),
        b.height()
    );
    assert_eq!(v["cluster"]["highlight"], "block", "{v}");
    let z = zoom as f64;
    let hl: Vec<f64> = v["cluster"]["hl"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert_eq!(
        hl,
        [
            f64::from(b.x0) * z - 2.0,
            f64::from(b.y0) * z - 2.0,
            f64::from(b.width()) * z + 4.0,
            f64::from(b.height()) * z + 4.0
        ],
        "the highlight frames the box: {v}"
    );
    assert!(v["zoom_after_in"].as_u64().unwrap() > zoom, "{v}");
    // Views and their legends: both maps exist here.
    assert_eq!(v["side_panels"], serde_json::json!(["p-a", "p-b"]), "{v}");
    assert_eq!(
        v["diff_panels"],
        serde_json::json!(["p-heat", "p-vis"]),
        "{v}"
    );
    assert_eq!(v["legends"], 2, "{v}");
}

/// A frame against an image with one changed pixel: that pixel is the
/// only cluster, the page has no visibility map (and no legend for one),
/// and hovering it shows the frame's triangle on side a only.
#[test]
fn the_report_page_of_a_frame_against_an_image_lists_the_changed_pixel() {
    let Some(browser) = chromium() else { return };
    let dir = temp("image");
    let png = dir.join("ray.png");
    let o = rendiff(&[
        "render",
        "scenes/spheres.toml",
        "--backend",
        "ray",
        "--size",
        "48x36",
        "-o",
        png.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut img = rendiff::image_io::read_png_linear(&png).unwrap();
    let (x, y) = (20usize, 9usize);
    let i = y * 48 + x;
    let p = img.pixels[i];
    img.pixels[i] = rendiff::color::Rgb::new(1.0 - p.r, 1.0 - p.g, 1.0 - p.b.min(0.5));
    let changed = dir.join("changed.png");
    rendiff::image_io::write_png(
        &changed,
        48,
        36,
        &img.pixels,
        rendiff::image_io::PngEncoding::Srgb8,
    )
    .unwrap();
    let out = dir.join("out");
    let o = rendiff(&[
        "diff",
        "scenes/spheres.toml",
        "--size",
        "48x36",
        "--a",
        "ray",
        "--b",
        changed.to_str().unwrap(),
        "--json",
        "--out",
        out.to_str().unwrap(),
    ]);
    let json: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(json["schema_version"], 2);
    let list = json["clusters"]["list"].as_array().unwrap();
    assert_eq!(list.len(), 1, "{json}");
    assert_eq!(list[0]["kind"], "beyond_8bit");
    assert_eq!(
        list[0]["box"],
        serde_json::json!({"x0": x, "y0": y, "x1": x, "y1": y})
    );
    assert!(list[0]["b"].as_array().unwrap().is_empty());
    // The summary keeps its lines (and wraps them: CSS).
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(
        !html.contains("&#xfffd;"),
        "a control character was escaped"
    );
    // (A changed pixel against an image of the same frame fails.)
    assert!(
        html.contains("\n  verdict: fail"),
        "the summary's lines are kept"
    );
    let v = selftest(
        &browser,
        &out.join("index.html"),
        "selftest",
        &temp("profile-image"),
    );
    assert_eq!(
        v["caption_after_click"],
        format!("B: {}", changed.display()),
        "{v}"
    );
    assert_eq!(cell(&v, "pixel"), [format!("{x}, {y}")], "{v}");
    assert_eq!(cell(&v, "class"), ["n/a (image)"], "{v}");
    let ids = cell(&v, "id");
    assert_ne!(ids[0], "–", "{v}");
    assert_eq!(ids[1], "–", "{v}");
    assert_eq!(v["diff_panels"], serde_json::json!(["p-heat"]), "{v}");
    assert_eq!(v["legends"], 1, "{v}");
}
