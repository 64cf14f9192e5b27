//! The architecture of ARCHITECTURE.md, checked where Cargo cannot hold
//! it. Cargo holds the crates: each may use only the crates its manifest
//! names, so [`crates_depend_only_downward`] pins those manifests (the
//! backends never depend on each other; the facade has no CLI crates).
//! Inside a crate, and across the floors that share one, Cargo sees no
//! direction: [`modules_depend_only_downward`] reads every source file and
//! fails on a reference to a module outside the table below (`compare`
//! renders nothing, `plan` never reads the scene model, …).

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use crate::util::root;

/// Crate → the workspace crates its `[dependencies]` may name.
const CRATES: &[(&str, &[&str])] = &[
    ("rendiff-core", &[]),
    ("rendiff-scene", &["rendiff-core"]),
    ("rendiff-accel", &["rendiff-core"]),
    ("rendiff-raster", &["rendiff-accel", "rendiff-core"]),
    ("rendiff-ray", &["rendiff-accel", "rendiff-core"]),
    ("rendiff-lines", &["rendiff-accel", "rendiff-core"]),
    (
        "rendiff",
        &[
            "rendiff-accel",
            "rendiff-core",
            "rendiff-lines",
            "rendiff-raster",
            "rendiff-ray",
            "rendiff-scene",
        ],
    ),
    ("rendiff-cli", &["rendiff"]),
];

/// What no crate below the command line may depend on.
const CLI_ONLY: &[&str] = &[
    "anyhow",
    "clap",
    "clap_complete",
    "clap_mangen",
    "indicatif",
    "plotters",
    "signal-hook",
];

/// The `[dependencies]` names of a manifest.
fn dependencies(manifest: &Path) -> BTreeSet<String> {
    let text = std::fs::read_to_string(manifest).unwrap();
    let doc: toml::Table = text.parse().unwrap();
    doc.get("dependencies")
        .and_then(toml::Value::as_table)
        .map(|t| t.keys().cloned().collect())
        .unwrap_or_default()
}

#[test]
fn crates_depend_only_downward() {
    let mut found = BTreeSet::new();
    for (name, allowed) in CRATES {
        let manifest = if *name == "rendiff-cli" {
            root().join("Cargo.toml")
        } else {
            root().join("crates").join(name).join("Cargo.toml")
        };
        found.insert(*name);
        let deps = dependencies(&manifest);
        let ours: BTreeSet<&str> = deps
            .iter()
            .map(String::as_str)
            .filter(|d| d.starts_with("rendiff"))
            .collect();
        assert_eq!(
            ours,
            allowed.iter().copied().collect::<BTreeSet<_>>(),
            "{name}: its workspace dependencies"
        );
        if *name != "rendiff-cli" {
            for d in CLI_ONLY {
                assert!(!deps.contains(*d), "{name} depends on {d}");
            }
        }
    }
    let dirs: BTreeSet<String> = std::fs::read_dir(root().join("crates"))
        .unwrap()
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    for d in &dirs {
        assert!(found.contains(d.as_str()), "crates/{d} is not in the table");
    }
}

/// Module → the modules it may use (`facade` = items of lib.rs itself).
const ALLOWED: &[(&str, &[&str])] = &[
    ("math", &[]),
    ("color", &[]),
    ("options", &[]),
    ("coverage", &[]),
    ("analytic", &[]),
    ("input", &[]),
    ("budget", &[]),
    ("cleanup", &[]),
    ("escape", &[]),
    ("huge", &[]),
    (
        "texture",
        &["budget", "color", "image_io", "input", "math", "options"],
    ),
    ("image_io", &["budget", "cleanup", "color", "input"]),
    ("output", &["cleanup", "image_io"]),
    ("camera", &["coverage", "math"]),
    ("polygon", &["math"]),
    ("shade", &["color", "math", "texture"]),
    ("frame", &["color", "huge", "image_io"]),
    (
        "scene",
        &[
            "budget", "camera", "color", "coverage", "escape", "input", "math", "options",
            "polygon", "shade", "texture",
        ],
    ),
    (
        "tri_scene",
        &["analytic", "camera", "color", "math", "shade"],
    ),
    (
        "tessellate",
        &[
            "analytic",
            "budget",
            "camera",
            "math",
            "scene",
            "shade",
            "tri_scene",
        ],
    ),
    (
        "accel",
        &[
            "analytic",
            "color",
            "huge",
            "math",
            "options",
            "shade",
            "tri_scene",
        ],
    ),
    ("plan", &["camera", "math", "options", "tri_scene"]),
    ("lines", &["accel", "camera", "math", "tri_scene"]),
    (
        "raster",
        &[
            "accel",
            "budget",
            "camera",
            "color",
            "coverage",
            "frame",
            "huge",
            "math",
            "options",
            "shade",
            "tri_scene",
        ],
    ),
    (
        "ray",
        &[
            "accel",
            "camera",
            "color",
            "frame",
            "math",
            "shade",
            "tri_scene",
        ],
    ),
    (
        "compare",
        &[
            "accel",
            "camera",
            "color",
            "coverage",
            "escape",
            "frame",
            "math",
            "options",
            "shade",
            "tri_scene",
        ],
    ),
    (
        "pov",
        &[
            "budget",
            "camera",
            "cleanup",
            "color",
            "escape",
            "image_io",
            "input",
            "math",
            "options",
            "scene",
            "shade",
            "texture",
            "tri_scene",
        ],
    ),
    (
        "bench",
        &[
            "facade", "accel", "color", "image_io", "options", "pov", "ray", "scene",
        ],
    ),
    (
        "diff",
        &[
            "facade", "accel", "budget", "color", "compare", "frame", "image_io", "options", "pov",
            "scene",
        ],
    ),
    (
        "snapshot",
        &["facade", "budget", "color", "compare", "diff", "image_io"],
    ),
    (
        "fuzz",
        &[
            "facade",
            "accel",
            "budget",
            "camera",
            "frame",
            "image_io",
            "math",
            "options",
            "polygon",
            "pov",
            "raster",
            "ray",
            "scene",
            "texture",
            "tri_scene",
        ],
    ),
];

/// The modules a source text refers to: the first segment after
/// `crate::` or `rendiff::` (with `{a, b}` groups expanded), after
/// `rendiff_core::` or `rendiff_scene::`, and the single-module crates
/// `rendiff_accel`, `rendiff_raster`, `rendiff_ray` and `rendiff_lines`
/// as `accel`, `raster`, `ray` and `lines`; capitalised names are items of
/// the facade's lib.rs.
fn references(text: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for prefix in ["crate::", "rendiff::", "rendiff_core::", "rendiff_scene::"] {
        let mut rest = text;
        while let Some(i) = rest.find(prefix) {
            let before = rest[..i].chars().next_back();
            rest = &rest[i + prefix.len()..];
            if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
                continue;
            }
            if let Some(group) = rest.strip_prefix('{') {
                let end = group.find('}').unwrap_or(group.len());
                for item in group[..end].split(',') {
                    let first = item.trim().split("::").next().unwrap_or("").to_string();
                    if !first.is_empty() {
                        out.insert(first);
                    }
                }
            } else {
                let first: String = rest
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                out.insert(first);
            }
        }
    }
    for m in ["accel", "raster", "ray", "lines"] {
        if text.contains(&format!("rendiff_{m}")) {
            out.insert(m.to_string());
        }
    }
    out.into_iter()
        .map(|m| {
            if m.chars().next().is_some_and(char::is_uppercase) {
                "facade".to_string()
            } else {
                m
            }
        })
        .collect()
}

/// Every library source file with the module it belongs to.
fn sources() -> Vec<(String, std::path::PathBuf)> {
    let mut out = Vec::new();
    let mut roots = vec![("".to_string(), root().join("src"))];
    for e in std::fs::read_dir(root().join("crates")).unwrap() {
        let e = e.unwrap();
        let name = e.file_name().to_string_lossy().into_owned();
        let single = name
            .strip_prefix("rendiff-")
            .filter(|m| ["accel", "raster", "ray", "lines"].contains(m))
            .map(str::to_string);
        roots.push((single.unwrap_or_default(), e.path().join("src")));
    }
    for (single, src) in roots {
        let mut stack = vec![src.clone()];
        while let Some(dir) = stack.pop() {
            for entry in std::fs::read_dir(&dir).unwrap() {
                let path = entry.unwrap().path();
                if path.is_dir() {
                    if path.file_name().is_some_and(|n| n != "bin") {
                        stack.push(path);
                    }
                    continue;
                }
                if path.extension().is_none_or(|e| e != "rs") {
                    continue;
                }
                let rel = path.strip_prefix(&src).unwrap();
                let module = if single.is_empty() {
                    rel.components()
                        .next()
                        .unwrap()
                        .as_os_str()
                        .to_string_lossy()
                        .trim_end_matches(".rs")
                        .to_string()
                } else {
                    single.clone()
                };
                if module != "lib" {
                    out.push((module, path));
                }
            }
        }
    }
    out
}

#[test]
fn modules_depend_only_downward() {
    let allowed: BTreeMap<&str, BTreeSet<&str>> = ALLOWED
        .iter()
        .map(|(m, deps)| (*m, deps.iter().copied().collect()))
        .collect();
    let mut seen = BTreeSet::new();
    let mut violations = Vec::new();
    for (module, path) in sources() {
        let rel = path.strip_prefix(root()).unwrap();
        let Some(ok) = allowed.get(module.as_str()) else {
            violations.push(format!(
                "{}: module `{module}` is missing from the table",
                rel.display()
            ));
            continue;
        };
        seen.insert(module.clone());
        let text = std::fs::read_to_string(&path).unwrap();
        for r in references(&text) {
            if r != module && !ok.contains(r.as_str()) {
                violations.push(format!("{}: `{module}` uses `{r}`", rel.display()));
            }
        }
    }
    assert!(
        violations.is_empty(),
        "dependency rule broken:\n{}",
        violations.join("\n")
    );
    assert_eq!(
        seen.len(),
        ALLOWED.len(),
        "modules in the table but not in the sources: {:?}",
        allowed
            .keys()
            .filter(|k| !seen.contains(**k))
            .collect::<Vec<_>>()
    );
}
