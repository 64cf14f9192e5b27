//! OBJ faces as exporters write them: a keyhole face (a ring around a hole,
//! joined by a bridge edge walked once each way) loads as the ring.

use std::process::Command;

use rendiff::Overrides;

use crate::util::root;

/// A scene showing one OBJ file face-on (the x = −1.146 plane of
/// assimp's `concave_polygon.obj`).
fn scene(dir: &std::path::Path, obj: &std::path::Path) -> std::path::PathBuf {
    let text = format!(
        "[image]\nwidth = 64\nheight = 64\n[camera]\neye = [5.0, 2.4, 2.35]\nlook_at = [-1.146, 2.4, 2.35]\nup = [0.0, 1.0, 0.0]\nfov_y = 20.0\n\
         [[lights]]\nkind = \"point\"\nposition = [5.0, 4.0, 4.0]\ncolor = [1.0, 1.0, 1.0]\n\
         [materials.m]\npigment = [0.8, 0.6, 0.2]\n\
         [[objects]]\nkind = \"mesh\"\nfile = {:?}\nmaterial = \"m\"\n",
        obj.display().to_string()
    );
    let p = dir.join("s.toml");
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn a_keyhole_face_loads_as_a_ring() {
    let dir = tempfile::tempdir().unwrap();
    let obj = root().join("tests/data/obj/concave_polygon.obj");
    let path = scene(dir.path(), &obj);
    let job = rendiff::Prepared::load(&path, &Overrides::default()).unwrap();
    let t = &job.tri;
    // 64 distinct corners in two rings: V + 2H − 2 = 64 triangles.
    assert_eq!(t.len(), 64);
    // The triangles cover the ring: the outer ring's area less the hole's
    // (both from the file's own corner order), to rounding.
    let text = std::fs::read_to_string(&obj).unwrap();
    let v: Vec<[f64; 3]> = text
        .lines()
        .filter_map(|l| l.strip_prefix("v "))
        .map(|l| {
            let p: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            [p[0], p[1], p[2]]
        })
        .collect();
    let face: Vec<usize> = text
        .lines()
        .find_map(|l| l.strip_prefix("f "))
        .unwrap()
        .split_whitespace()
        .map(|c| c.split('/').next().unwrap().parse::<usize>().unwrap() - 1)
        .collect();
    // Shoelace in the (y, z) plane of the face.
    let area = |ring: &[usize]| {
        let n = ring.len();
        (0..n)
            .map(|k| {
                let (a, b) = (v[ring[k]], v[ring[(k + 1) % n]]);
                a[1] * b[2] - b[1] * a[2]
            })
            .sum::<f64>()
            .abs()
            / 2.0
    };
    // The bridge: corners 31 and 32 (0-based 30, 31).
    let i = face.iter().position(|&c| c == 30).unwrap();
    let j = face.iter().rposition(|&c| c == 31).unwrap();
    let inner = &face[i + 1..j];
    let outer: Vec<usize> = face[j + 1..].iter().chain(&face[..i]).copied().collect();
    let want = area(&outer) - area(inner);
    let got: f64 = (0..u32::try_from(t.len()).unwrap())
        .map(|k| {
            let [a, b, c] = t.triangle_f64(k);
            (b - a).cross(c - a).length() / 2.0
        })
        .sum();
    assert!(
        (got - want).abs() < 1e-5 * want,
        "area {got}, the ring's {want}"
    );
    // The hole is a real part of the face: without it the area would be
    // the outer ring's.
    assert!(area(inner) > 0.1 * area(&outer), "{want}");
    // Both backends see the same ring: the verdict passes with no real sample.
    let o = Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .args(["diff", path.to_str().unwrap(), "--json"])
        .output()
        .unwrap();
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(r["visibility"]["real"], 0, "{r}");
    assert_eq!(o.status.code(), Some(0), "{r}");
    // And the hole is empty: the centre of the view sees the background.
    let frame = job.render(rendiff::Backend::Ray).unwrap().frame;
    let centre = (32 * 64 + 32) as usize;
    assert_eq!(frame.id[centre], rendiff::frame::BACKGROUND);
}

#[test]
fn a_true_spike_is_still_refused_naming_its_corners() {
    let dir = tempfile::tempdir().unwrap();
    // A square with a spike out to a fifth corner and back: no ring closes
    // behind it, so it stays an error.
    let obj = dir.path().join("spike.obj");
    std::fs::write(
        &obj,
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 2 0\nf 1 2 3 5 3 4\n",
    )
    .unwrap();
    let path = scene(dir.path(), &obj);
    let e = rendiff::Prepared::load(&path, &Overrides::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("spike") && e.contains("`3`") && e.contains("`5`"),
        "{e}"
    );
}
