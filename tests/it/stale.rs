//! A stored POV-Ray reference of another version of the scene is named
//! stale before any count, in words that fit any repository.

use std::process::Command;

use crate::util::root;

#[test]
fn diff_against_a_stale_reference_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir_all(d.join("g")).unwrap();
    std::fs::create_dir_all(d.join("textures")).unwrap();
    for f in std::fs::read_dir(root().join("scenes/textures")).unwrap() {
        let f = f.unwrap().path();
        std::fs::copy(&f, d.join("textures").join(f.file_name().unwrap())).unwrap();
    }
    for f in ["spheres.png", "spheres.analytic.png", "spheres.toml"] {
        std::fs::copy(root().join("golden/pov").join(f), d.join("g").join(f)).unwrap();
    }
    let scene = std::fs::read_to_string(root().join("scenes/spheres.toml")).unwrap();
    let run = |text: &str| {
        std::fs::write(d.join("spheres.toml"), text).unwrap();
        let o = Command::new(env!("CARGO_BIN_EXE_rendiff"))
            .args([
                "diff",
                "spheres.toml",
                "--b",
                "pov",
                "--golden",
                "g",
                "--json",
            ])
            .current_dir(d)
            .output()
            .unwrap();
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        v["notes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|n| n.as_str().unwrap().to_string())
            .collect::<Vec<_>>()
    };
    // The scene as stored: no note.
    assert!(!run(&scene).iter().any(|n| n.contains("stale")));
    // A changed pigment: the reference is stale, and the note says how to
    // re-render it without naming a Makefile.
    let edited = scene.replacen("[0.85, 0.15, 0.1]", "[0.1, 0.15, 0.85]", 1);
    assert_ne!(edited, scene);
    let notes = run(&edited);
    let note = notes
        .iter()
        .find(|n| n.contains("stale"))
        .expect("a stale note");
    assert!(
        note.contains("rendiff golden --update spheres.toml"),
        "{note}"
    );
    assert!(!note.contains("make "), "{note}");
}

#[test]
fn two_scenes_of_one_name_cannot_share_a_golden_folder() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = "[image]\nwidth = 8\nheight = 6\n[camera]\neye = [0.0, 0.0, 5.0]\nlook_at = [0.0, 0.0, 0.0]\nup = [0.0, 1.0, 0.0]\nfov_y = 40.0\n[[lights]]\nkind = \"point\"\nposition = [2.0, 2.0, 5.0]\ncolor = [1.0, 1.0, 1.0]\n[materials.m]\npigment = [0.5, 0.5, 0.5]\n[[objects]]\nkind = \"sphere\"\nmaterial = \"m\"\ncenter = [0.0, 0.0, 0.0]\nradius = 1.0\n";
    for sub in ["a", "b"] {
        std::fs::create_dir_all(d.join(sub)).unwrap();
        std::fs::write(d.join(sub).join("x.toml"), scene).unwrap();
    }
    for args in [
        &["golden", "a/x.toml", "b/x.toml", "--golden", "g"][..],
        &[
            "golden", "a/x.toml", "b/x.toml", "--golden", "g", "--update",
        ],
        &[
            "diff", "a/x.toml", "b/x.toml", "--b", "pov", "--golden", "g",
        ],
    ] {
        let o = Command::new(env!("CARGO_BIN_EXE_rendiff"))
            .args(args)
            .current_dir(d)
            .output()
            .unwrap();
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert!(
            e.contains("a/x.toml") && e.contains("b/x.toml"),
            "{args:?}: {e}"
        );
        assert!(!d.join("g").exists(), "{args:?} wrote the golden folder");
    }
}
