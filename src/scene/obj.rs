//! OBJ meshes: a strict line-by-line check that names the line of every
//! problem, then tobj for the data, then the constrained Delaunay
//! triangulation of faces with more than three corners.
//!
//! tobj reports errors without line numbers and fills a missing `vt`/`vn`
//! of a corner with the previous one; the check pass records which faces
//! really have uvs and normals so neither surprise reaches a render.

use std::io::BufReader;
use std::path::{Path, PathBuf};

use super::error::LoadError;
use crate::math::{DVec3, Vec2, Vec3};
use crate::polygon::{self, PolygonError, PolygonOptions};

/// One triangle of a mesh: indices into the mesh's positions, normals and uvs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MeshTri {
    /// Position indices.
    pub v: [u32; 3],
    /// Normal indices, when the face has `vn` on every corner.
    pub n: Option<[u32; 3]>,
    /// uv indices, when the face has `vt` on every corner.
    pub t: Option<[u32; 3]>,
}

/// A loaded, triangulated mesh in object space.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshData {
    /// The OBJ file.
    pub path: PathBuf,
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Normals (as written; normalised where used).
    pub normals: Vec<Vec3>,
    /// Texture coordinates.
    pub uvs: Vec<Vec2>,
    /// Triangles.
    pub triangles: Vec<MeshTri>,
    /// The OBJ line of each triangle's face.
    pub lines: Vec<u32>,
    /// Number of faces in the file.
    pub faces: usize,
}

impl MeshData {
    /// `true` when every triangle has uvs.
    #[must_use]
    pub fn has_uv(&self) -> bool {
        !self.triangles.is_empty() && self.triangles.iter().all(|t| t.t.is_some())
    }

    /// The first line whose face has no uv.
    #[must_use]
    pub fn first_face_without_uv(&self) -> Option<u32> {
        self.triangles
            .iter()
            .zip(&self.lines)
            .find(|(t, _)| t.t.is_none())
            .map(|(_, l)| *l)
    }
}

struct FaceInfo {
    line: usize,
    corners: usize,
    has_vt: bool,
    has_vn: bool,
}

fn mesh_err(path: &Path, line: usize, message: impl Into<String>) -> LoadError {
    LoadError::Mesh {
        path: path.to_path_buf(),
        line: Some(line),
        message: message.into(),
    }
}

/// A number of the file, or what is wrong with it.
fn parse_f32(tok: &str) -> Result<f32, String> {
    match (tok.parse::<f32>(), tok.parse::<f64>()) {
        (Ok(v), _) if v.is_finite() => Ok(v),
        (_, Ok(v)) if v.is_finite() => Err(format!(
            "`{tok}` is outside the f32 range (a magnitude above {:e})",
            f32::MAX
        )),
        (Ok(_), _) | (_, Ok(_)) => Err(format!("`{tok}` is not a finite number")),
        _ => Err(format!("`{}` is not a number", shown(tok))),
    }
}

/// A token as shown in a message: control characters escaped.
fn shown(tok: &str) -> String {
    tok.chars()
        .map(|c| {
            if c.is_control() {
                c.escape_debug().to_string()
            } else {
                c.to_string()
            }
        })
        .collect()
}

/// The check pass: every line well formed, every number finite in `f32`,
/// every index in range.
fn check(path: &Path, text: &str) -> Result<Vec<FaceInfo>, LoadError> {
    let (mut nv, mut nvt, mut nvn) = (0i64, 0i64, 0i64);
    let mut faces = Vec::new();
    for (k, raw) in text.lines().enumerate() {
        let line = k + 1;
        let content = raw.split('#').next().unwrap_or("");
        let mut toks = content.split_whitespace();
        let Some(kw) = toks.next() else { continue };
        let args: Vec<&str> = toks.collect();
        let numbers = |min: usize, max: usize, what: &str| -> Result<(), LoadError> {
            if args.len() < min || args.len() > max {
                return Err(mesh_err(
                    path,
                    line,
                    format!(
                        "`{kw}` needs {} numbers ({what}), found {}",
                        if min == max {
                            min.to_string()
                        } else {
                            format!("{min} to {max}")
                        },
                        args.len()
                    ),
                ));
            }
            for a in &args {
                parse_f32(a).map_err(|m| mesh_err(path, line, m))?;
            }
            Ok(())
        };
        match kw {
            "v" => {
                numbers(3, 7, "x y z [w] or x y z r g b")?;
                nv += 1;
            }
            "vt" => {
                numbers(2, 3, "u v [w]")?;
                if let Some(a) = args
                    .iter()
                    .take(2)
                    .find(|a| parse_f32(a).is_ok_and(|v| f64::from(v.abs()) > super::MAX_UV))
                {
                    return Err(mesh_err(
                        path,
                        line,
                        format!(
                            "texture coordinate `{}` is beyond ±{:e} (f32 resolves it to a sixteenth of a repeat or worse)",
                            shown(a),
                            super::MAX_UV
                        ),
                    ));
                }
                nvt += 1;
            }
            "vn" => {
                numbers(3, 3, "x y z")?;
                nvn += 1;
            }
            "f" => {
                if args.len() < 3 {
                    return Err(mesh_err(
                        path,
                        line,
                        format!("a face needs at least 3 corners, found {}", args.len()),
                    ));
                }
                let mut has_vt = true;
                let mut has_vn = true;
                for corner in &args {
                    let parts: Vec<&str> = corner.split('/').collect();
                    if parts.len() > 3 || parts[0].is_empty() {
                        return Err(mesh_err(
                            path,
                            line,
                            format!(
                                "malformed face corner `{corner}`; expected v, v/vt, v//vn or v/vt/vn"
                            ),
                        ));
                    }
                    let idx = |s: &str, count: i64, what: &str| -> Result<(), LoadError> {
                        let i: i64 = s.parse().map_err(|_| {
                            mesh_err(
                                path,
                                line,
                                format!("`{s}` in corner `{corner}` is not an integer index"),
                            )
                        })?;
                        let ok = (i > 0 && i <= count) || (i < 0 && -i <= count);
                        if !ok {
                            return Err(mesh_err(
                                path,
                                line,
                                format!(
                                    "{what} index {i} in corner `{corner}` is out of range (1 … {count}, or -1 … -{count}, defined so far)"
                                ),
                            ));
                        }
                        Ok(())
                    };
                    idx(parts[0], nv, "vertex")?;
                    match parts.get(1) {
                        Some(s) if !s.is_empty() => idx(s, nvt, "texture")?,
                        _ => has_vt = false,
                    }
                    match parts.get(2) {
                        Some(s) if !s.is_empty() => idx(s, nvn, "normal")?,
                        _ => has_vn = false,
                    }
                }
                faces.push(FaceInfo {
                    line,
                    corners: args.len(),
                    has_vt,
                    has_vn,
                });
            }
            "o" | "g" | "s" | "usemtl" | "mtllib" | "l" | "p" => {}
            other => {
                let hint = if other.contains('\u{FFFD}') || other.chars().any(char::is_control) {
                    " (the line is not text: is this an OBJ file?)"
                } else {
                    ""
                };
                return Err(mesh_err(
                    path,
                    line,
                    format!(
                        "unsupported OBJ statement `{}`; expected v, vt, vn, f, o, g, s, usemtl, mtllib, l or p{hint}",
                        shown(other)
                    ),
                ));
            }
        }
    }
    if faces.is_empty() {
        return Err(LoadError::Mesh {
            path: path.to_path_buf(),
            line: None,
            message: "the mesh has no faces".into(),
        });
    }
    Ok(faces)
}

/// A polygon error of a face with more than three corners, in the face's
/// own terms: its corners as written on the line.
fn face_error(e: &PolygonError, corners: &[&str]) -> String {
    let c = |i: usize| {
        corners
            .get(i)
            .map_or_else(|| format!("#{i}"), |s| format!("`{}`", shown(s)))
    };
    let n = corners.len();
    match e {
        PolygonError::SelfIntersecting { a, b } => format!(
            "the face's edges {}–{} and {}–{} cross, touch or overlap; a face must be a simple polygon",
            c(a.from),
            c(a.to),
            c(b.from),
            c(b.to)
        ),
        PolygonError::Spike { from, to, .. } => format!(
            "the face runs from corner {} to corner {} and straight back (a spike with no area)",
            c(*from),
            c(*to)
        ),
        PolygonError::TooFewPoints { distinct, .. } => format!(
            "the face's {n} corners have only {distinct} distinct positions; a face needs at least 3"
        ),
        PolygonError::Collinear => {
            format!("the face's {n} corners all lie on one line; a face needs an area")
        }
        other => format!("face with {n} corners: {other}"),
    }
}

/// Loads an OBJ file from its bytes (decoded lossily if not UTF-8).
///
/// # Errors
///
/// [`LoadError::Mesh`] naming the file and line of the first problem.
pub fn load_obj_bytes(path: &Path, bytes: &[u8]) -> Result<MeshData, LoadError> {
    let text = String::from_utf8_lossy(bytes);
    let infos = check(path, &text)?;
    let opts = tobj::LoadOptions {
        single_index: false,
        triangulate: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let mut reader = BufReader::new(text.as_bytes());
    let (models, _materials) =
        tobj::load_obj_buf(&mut reader, &opts, |_| Err(tobj::LoadError::OpenFileFailed)).map_err(
            |e| LoadError::Mesh {
                path: path.to_path_buf(),
                line: None,
                message: format!("tobj could not load the mesh: {e}"),
            },
        )?;

    let mut data = MeshData {
        path: path.to_path_buf(),
        positions: Vec::new(),
        normals: Vec::new(),
        uvs: Vec::new(),
        triangles: Vec::new(),
        lines: Vec::new(),
        faces: infos.len(),
    };
    let mut face_no = 0usize;
    for model in &models {
        let m = &model.mesh;
        let base_v = u32::try_from(data.positions.len()).unwrap_or(u32::MAX);
        let base_n = u32::try_from(data.normals.len()).unwrap_or(u32::MAX);
        let base_t = u32::try_from(data.uvs.len()).unwrap_or(u32::MAX);
        data.positions.extend(
            m.positions
                .chunks_exact(3)
                .map(|c| Vec3::new(c[0], c[1], c[2])),
        );
        data.normals.extend(
            m.normals
                .chunks_exact(3)
                .map(|c| Vec3::new(c[0], c[1], c[2])),
        );
        data.uvs
            .extend(m.texcoords.chunks_exact(2).map(|c| Vec2::new(c[0], c[1])));
        let arities: Vec<usize> = if m.face_arities.is_empty() {
            vec![3; m.indices.len() / 3]
        } else {
            m.face_arities.iter().map(|&a| a as usize).collect()
        };
        let mut start = 0usize;
        for arity in arities {
            let Some(info) = infos.get(face_no) else {
                return Err(LoadError::Mesh {
                    path: path.to_path_buf(),
                    line: None,
                    message: "tobj returned more faces than the file has".into(),
                });
            };
            if info.corners != arity {
                return Err(mesh_err(
                    path,
                    info.line,
                    format!(
                        "tobj read {arity} corners where the file has {}",
                        info.corners
                    ),
                ));
            }
            let range = start..start + arity;
            let v: Vec<u32> = m.indices[range.clone()]
                .iter()
                .map(|i| i + base_v)
                .collect();
            let n: Option<Vec<u32>> =
                (info.has_vn && m.normal_indices.len() >= range.end).then(|| {
                    m.normal_indices[range.clone()]
                        .iter()
                        .map(|i| i + base_n)
                        .collect()
                });
            let t: Option<Vec<u32>> =
                (info.has_vt && m.texcoord_indices.len() >= range.end).then(|| {
                    m.texcoord_indices[range.clone()]
                        .iter()
                        .map(|i| i + base_t)
                        .collect()
                });
            start += arity;
            let corners: Vec<[usize; 3]> = if arity == 3 {
                vec![[0, 1, 2]]
            } else {
                let pts: Vec<DVec3> = v
                    .iter()
                    .map(|&i| {
                        let p = data.positions[i as usize];
                        DVec3::new(f64::from(p.x), f64::from(p.y), f64::from(p.z))
                    })
                    .collect();
                let tri = polygon::triangulate(
                    &pts,
                    &[],
                    PolygonOptions {
                        check_planarity: false,
                    },
                )
                .map_err(|e| {
                    let corners: Vec<&str> = text
                        .lines()
                        .nth(info.line - 1)
                        .and_then(|l| l.split('#').next())
                        .map(|l| l.split_whitespace().skip(1).collect())
                        .unwrap_or_default();
                    mesh_err(path, info.line, face_error(&e, &corners))
                })?;
                // The CDT triangles wind around the face's Newell normal,
                // which follows the face's own winding.
                tri.triangles
                    .iter()
                    .map(|t| t.map(|i| i as usize))
                    .collect()
            };
            let line = u32::try_from(info.line).unwrap_or(u32::MAX);
            for c in corners {
                data.triangles.push(MeshTri {
                    v: c.map(|k| v[k]),
                    n: n.as_ref().map(|n| c.map(|k| n[k])),
                    t: t.as_ref().map(|t| c.map(|k| t[k])),
                });
                data.lines.push(line);
            }
            face_no += 1;
        }
    }
    if face_no != infos.len() {
        return Err(LoadError::Mesh {
            path: path.to_path_buf(),
            line: None,
            message: format!(
                "tobj returned {face_no} faces where the file has {}",
                infos.len()
            ),
        });
    }
    Ok(data)
}

/// Bytes a loaded mesh holds per position, normal, uv and triangle
/// (`MeshData`'s arrays).
pub(crate) fn mesh_bytes(d: &MeshData) -> u64 {
    (d.positions.len() * 12 + d.normals.len() * 12 + d.uvs.len() * 8 + d.triangles.len() * 44)
        as u64
}

/// [`load_obj_bytes`], reserving the mesh's data in `budget`.
///
/// # Errors
///
/// As [`load_obj_bytes`], or the figure that does not fit the budget.
pub fn load_obj_within(
    path: &Path,
    bytes: &[u8],
    budget: &crate::budget::Budget,
) -> Result<MeshData, LoadError> {
    let d = load_obj_bytes(path, bytes)?;
    budget
        .reserve(mesh_bytes(&d), || {
            format!(
                "the mesh's {} vertices and {} triangles",
                d.positions.len(),
                d.triangles.len()
            )
        })
        .map_err(|e| LoadError::Mesh {
            path: path.to_path_buf(),
            line: None,
            message: e.to_string(),
        })?;
    Ok(d)
}

/// Reads and loads an OBJ file.
///
/// # Errors
///
/// [`LoadError::Read`] or [`LoadError::Mesh`].
pub fn load_obj(path: &Path) -> Result<MeshData, LoadError> {
    let bytes = crate::input::read_file(path).map_err(|source| LoadError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    load_obj_bytes(path, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(text: &str) -> Result<MeshData, LoadError> {
        load_obj_bytes(Path::new("t.obj"), text.as_bytes())
    }

    #[test]
    fn quad_is_triangulated_and_concave_face_is_not_fanned() {
        let m = load("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n").unwrap();
        assert_eq!(m.triangles.len(), 2);
        // A concave "arrow" face: the fan from vertex 1 would leave the face.
        let m = load("v 0 0 0\nv 2 1 0\nv 0 2 0\nv 1 1 0\nf 1 2 3 4\n").unwrap();
        assert_eq!(m.triangles.len(), 2);
        for t in &m.triangles {
            // The reflex vertex (index 3, 0-based) must be in both triangles.
            assert!(t.v.contains(&3), "{:?}", m.triangles);
        }
    }

    #[test]
    fn per_corner_normals_and_uvs_survive() {
        let m = load(
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\nf 1/1/1 2/2/1 3/3/1\nf 1 2 3\n",
        )
        .unwrap();
        assert_eq!(m.triangles[0].t, Some([0, 1, 2]));
        assert_eq!(m.triangles[0].n, Some([0, 0, 0]));
        assert_eq!(m.triangles[1].t, None);
        assert_eq!(m.triangles[1].n, None);
        assert!(!m.has_uv());
        assert_eq!(m.first_face_without_uv(), Some(9));
    }

    #[test]
    fn errors_name_the_line() {
        let e = load("v 0 0 0\nv 1 0 nan\n").unwrap_err().to_string();
        assert!(e.starts_with("t.obj:2:"), "{e}");
        let e = load("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("t.obj:4:") && e.contains("out of range"),
            "{e}"
        );
        let e = load("v 0 0 0\n").unwrap_err().to_string();
        assert!(e.contains("no faces"), "{e}");
        let e = load("v 0 0 0\nbogus 1\n").unwrap_err().to_string();
        assert!(e.starts_with("t.obj:2:"), "{e}");
        let e = load("v 1e39 0 0\n").unwrap_err().to_string();
        assert!(e.starts_with("t.obj:1:"), "{e}");
    }

    #[test]
    fn bad_numbers_and_faces_say_what_is_wrong() {
        let e = load("v 0 0,5 0\n").unwrap_err().to_string();
        assert_eq!(e, "t.obj:1: `0,5` is not a number");
        let e = load("v 0 inf 0\n").unwrap_err().to_string();
        assert_eq!(e, "t.obj:1: `inf` is not a finite number");
        let e = load("v 0 1e39 0\n").unwrap_err().to_string();
        assert!(e.contains("outside the f32 range"), "{e}");
        // A bow-tie quad: its edges are named by the corners as written.
        let e = load("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 3 2 4\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("t.obj:5: the face's edges `1`–`3` and `2`–`4` cross"),
            "{e}"
        );
        let e = load("\x01\x02 3\n").unwrap_err().to_string();
        assert!(
            e.contains("`\\u{1}\\u{2}`") && e.contains("is this an OBJ file?"),
            "{e}"
        );
    }

    #[test]
    fn negative_indices_and_lossy_utf8() {
        let mut bytes = b"# caf\xe9\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n".to_vec();
        bytes.push(b'\n');
        let m = load_obj_bytes(Path::new("t.obj"), &bytes).unwrap();
        assert_eq!(m.triangles.len(), 1);
    }
}
