//! OBJ materials (`material = "obj"`): a mesh's own `.mtl` per `usemtl`
//! group, mapped onto the shared finish; JPEG textures; the POV-Ray export
//! of per-face materials. The hostile inputs (a missing or malformed
//! library, undefined names, bad textures) are in `hostile.rs`.

#![allow(
    clippy::cast_possible_truncation,
    clippy::cast_precision_loss,
    clippy::cast_sign_loss,
    reason = "test fixtures: small counts and codes, where a wrong cast fails the test"
)]

use rendiff::diff::{self, Side};
use rendiff::pov::{ExportOptions, export};
use rendiff::scene::Scene;
use rendiff::shade::Pigment;
use rendiff::texture::{ImageFormat, Texture};
use rendiff::{Backend, Overrides, Prepared};

use crate::util::{load, root};

/// A scene of `tests/data/obj/mtl/multi.obj`: a floor with a tinted JPEG
/// (`tiled`), a wall with a bump map (`bumpy`), a half-dissolved veil
/// (`veil`, illum 4: it reflects Ks and transmits 1 − d), and a face
/// before any `usemtl`.
fn multi_scene() -> Scene {
    let text = r#"
[image]
width = 160
height = 120
[camera]
eye = [0.5, 1.6, 3.2]
look_at = [0.0, 0.5, 0.0]
up = [0.0, 1.0, 0.0]
fov_y = 45.0
[[lights]]
kind = "point"
position = [2.0, 4.0, 3.0]
color = [1.0, 1.0, 1.0]
[[objects]]
kind = "mesh"
file = "multi.obj"
material = "obj"
smooth = true
"#;
    let path = root().join("tests/data/obj/mtl/multi.toml");
    Scene::from_str(&path, text).unwrap()
}

fn material_names(s: &Scene, tri: &rendiff::tri_scene::TriScene) -> Vec<String> {
    tri.tri_material
        .iter()
        .map(|&m| s.materials[usize::from(m)].name.clone())
        .collect()
}

#[test]
fn each_face_gets_its_groups_material() {
    let s = multi_scene();
    let job = Prepared::from_scene(s.clone(), &Overrides::default()).unwrap();
    // Face 1 (before any usemtl): the default; the floor and wall quads
    // two triangles each; the veil two.
    assert_eq!(
        material_names(&s, &job.tri),
        [
            "obj: no usemtl",
            "multi.mtl:tiled",
            "multi.mtl:tiled",
            "multi.mtl:bumpy",
            "multi.mtl:bumpy",
            "multi.mtl:veil",
            "multi.mtl:veil",
        ]
    );
    let m = |name: &str| s.materials.iter().find(|m| m.name == name).unwrap();
    // Kd 0.9 0.7 0.5 on a JPEG: diffuse 0.9, the texels tinted by Kd/0.9,
    // so diffuse × texel = Kd × the file's texel.
    let tiled = m("multi.mtl:tiled");
    assert_eq!(tiled.diffuse, 0.9);
    let Pigment::Image(tex) = &tiled.pigment else {
        panic!("tiled has no image")
    };
    assert_eq!(tex.format(), ImageFormat::Jpeg);
    let file = Texture::load(&root().join("tests/data/obj/mtl/tiles.jpg")).unwrap();
    for (t, f) in tex.texels().iter().zip(file.texels()) {
        for (c, kd) in [0.9f32, 0.7, 0.5].iter().enumerate() {
            assert!((t[c] * 0.9 - f[c] * kd).abs() < 1e-6, "{t:?} {f:?}");
        }
    }
    // The bump: Blinn's method, size -bm.
    let b = m("multi.mtl:bumpy").bump.as_ref().unwrap();
    assert_eq!(
        (b.size, b.method),
        (0.05, rendiff::shade::BumpMethod::Blinn)
    );
    // The veil: 1 − d transmitted, Ks reflected (illum 4), no refraction.
    let v = m("multi.mtl:veil");
    assert!((v.transmit - 0.4).abs() < 1e-6 && v.ior == 1.0 && v.reflection == 0.3);
}

#[test]
fn both_backends_agree_on_a_multi_material_obj() {
    let s = multi_scene();
    let job = Prepared::from_scene(s, &Overrides::default()).unwrap();
    let r = diff::diff(
        &job,
        "multi",
        &Side::Backend(Backend::Raster),
        &Side::Backend(Backend::Ray),
    )
    .unwrap();
    let v = r.report.visibility.expect("two frames");
    assert_eq!(v.real, 0, "{}", r.report.summary());
    assert_eq!(r.report.shading.over_threshold, 0, "{}", r.report.summary());
    assert!(r.report.passed(), "{}", r.report.summary());
    // Every material is on screen: the frame's triangles cover all four.
    let frame = job.render(Backend::Ray).unwrap().frame;
    let mut seen: Vec<u16> = frame
        .id
        .iter()
        .filter(|&&id| id != rendiff::frame::BACKGROUND)
        .map(|&id| job.tri.tri_material[id as usize])
        .collect();
    seen.sort_unstable();
    seen.dedup();
    assert_eq!(seen.len(), 4, "materials seen: {seen:?}");
}

#[test]
fn the_export_writes_a_texture_per_material_and_jpeg_texels_as_png() {
    let s = multi_scene();
    let job = Prepared::from_scene(s.clone(), &Overrides::default()).unwrap();
    let e = export(
        &s,
        &job.tri,
        &ExportOptions {
            geometry: rendiff::options::Geometry::Mesh,
            max_depth: 5,
            abridged: false,
        },
    )
    .unwrap();
    assert!(e.text.contains("texture_list { 4"), "{}", e.text);
    // Each face names its texture: the list is in material-index order
    // (tiled, bumpy, veil, then the default made last).
    assert!(e.text.contains("<0,1,2>, 3,"), "{}", e.text);
    let jpeg = e
        .images
        .iter()
        .find(|i| i.source.ends_with("tiles.jpg"))
        .expect("the JPEG is an image of the export");
    assert!(jpeg.rgb_copy && jpeg.texels.is_some());
    assert_eq!(jpeg.name, "rendiff_tex_tiles.png");
    // Its copy holds the tinted texels to a 16-bit code.
    let dir = tempfile::tempdir().unwrap();
    jpeg.materialise(dir.path()).unwrap();
    let copy = Texture::load(&dir.path().join(&jpeg.name)).unwrap();
    let want = jpeg.texels.as_ref().unwrap();
    for (a, b) in copy.texels().iter().zip(want.texels()) {
        for c in 0..3 {
            assert!((a[c] - b[c]).abs() <= 0.5 / 65535.0 + 1e-7, "{a:?} {b:?}");
        }
    }
}

#[test]
fn the_spider_loads_its_five_jpegs_and_every_face_has_its_material() {
    let job = load("spider", &Overrides::default());
    let mesh = job.tri.objects.len() - 1;
    let used = job.tri.object_materials(mesh);
    let names: Vec<&str> = used
        .iter()
        .map(|&m| job.scene.materials[usize::from(m)].name.as_str())
        .collect();
    // Brusttex is defined and never used; no face lacks a usemtl.
    assert_eq!(
        names,
        [
            "spider.mtl:HLeibTex",
            "spider.mtl:Skin",
            "spider.mtl:BeinTex",
            "spider.mtl:Augentex"
        ]
    );
    for &m in &used {
        let Pigment::Image(t) = &job.scene.materials[usize::from(m)].pigment else {
            panic!("{m}: no image")
        };
        assert_eq!(t.format(), ImageFormat::Jpeg);
    }
    // The progressive JPEG (engineflare1.jpg, 128x128) decodes too.
    let eye = &job.scene.materials[usize::from(used[3])];
    let Pigment::Image(t) = &eye.pigment else {
        panic!()
    };
    assert_eq!((t.width(), t.height()), (128, 128));
}

#[test]
fn a_real_file_with_an_undefined_usemtl_names_its_line() {
    // assimp's cube_usemtl.obj selects `mtl3`, which its .mtl does not
    // define (assimp falls back to a default material; rendiff says so).
    let dir = root().join("tests/data/bad/assets");
    let text = "[image]\nwidth = 8\nheight = 8\n[camera]\neye = [3.0, 3.0, 3.0]\nlook_at = [0.5, 0.5, 0.5]\nup = [0.0, 1.0, 0.0]\nfov_y = 40.0\n[[objects]]\nkind = \"mesh\"\nfile = \"cube_usemtl.obj\"\nmaterial = \"obj\"\n";
    let e = Scene::from_str(&dir.join("s.toml"), text)
        .unwrap_err()
        .to_string();
    assert!(
        e.ends_with("cube_usemtl.obj:21: usemtl `mtl3`: no material of that name in cube_usemtl.mtl (defined: `mtl`, `mtl2`)"),
        "{e}"
    );
}
