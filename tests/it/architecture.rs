//! The module map of ARCHITECTURE.md, enforced: each module of the
//! library may use only the modules listed for it (one-way dependencies,
//! backends never import each other, `compare` renders nothing).

use std::collections::{BTreeMap, BTreeSet};

use crate::util::root;

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
    ("texture", &["budget", "color", "image_io", "input", "math"]),
    ("image_io", &["budget", "cleanup", "color", "input"]),
    ("output", &["cleanup", "image_io"]),
    ("camera", &["math"]),
    ("polygon", &["math"]),
    ("shade", &["color", "math", "texture"]),
    ("frame", &["color", "image_io"]),
    (
        "scene",
        &[
            "budget", "camera", "color", "input", "math", "options", "polygon", "shade", "texture",
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
        &["analytic", "color", "math", "options", "shade", "tri_scene"],
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
            "math",
            "options",
            "shade",
            "tri_scene",
        ],
    ),
    (
        "ray",
        &["accel", "color", "frame", "math", "shade", "tri_scene"],
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
            "facade", "accel", "color", "compare", "frame", "image_io", "options", "pov", "scene",
        ],
    ),
    (
        "fuzz",
        &[
            "facade",
            "accel",
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

/// `crate::x` references of a source text (first path segment), with
/// `crate::{a, b}` groups expanded; capitalised names are lib.rs items.
fn references(text: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut rest = text;
    while let Some(i) = rest.find("crate::") {
        rest = &rest[i + 7..];
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

#[test]
fn modules_depend_only_downward() {
    let allowed: BTreeMap<&str, BTreeSet<&str>> = ALLOWED
        .iter()
        .map(|(m, deps)| (*m, deps.iter().copied().collect()))
        .collect();
    let src = root().join("src");
    let mut seen = BTreeSet::new();
    let mut violations = Vec::new();
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
            let module = rel
                .components()
                .next()
                .unwrap()
                .as_os_str()
                .to_string_lossy()
                .trim_end_matches(".rs")
                .to_string();
            if module == "lib" {
                continue;
            }
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
    }
    assert!(
        violations.is_empty(),
        "dependency rule broken:\n{}",
        violations.join("\n")
    );
    assert_eq!(
        seen.len(),
        ALLOWED.len(),
        "modules in the table but not in src/: {:?}",
        allowed
            .keys()
            .filter(|k| !seen.contains(**k))
            .collect::<Vec<_>>()
    );
}
