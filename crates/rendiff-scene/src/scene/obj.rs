//! OBJ meshes: a strict reader in one pass that names the line of every
//! problem, collects positions, normals, uvs and faces as it reads them,
//! triangulates faces with more than three corners by the constrained
//! Delaunay triangulation, and reserves what it builds in the memory
//! budget as it goes.
//!
//! The data it gives is laid out as `tobj` (which loaded the data before)
//! laid it out, so meshes, their triangles and every image made of them
//! are unchanged: the faces are grouped into models at `o` and `g`
//! statements (a new model once the current one has faces); each model
//! lists the positions, normals and uvs its faces use in the order they
//! are first used, and the triangles index those lists. A model whose
//! first corner has no uv while the file has uvs by the model's end starts
//! its uv list with the file's first uv (tobj's stand-in for the missing
//! one); normals alike. Faces without a uv (or a normal) on every corner
//! get none.
//!
//! `mtllib` and `usemtl` are recorded (names and lines), not resolved:
//! only an object that asks for the file's own materials (`material =
//! "obj"`) reads its libraries (`scene::mtl`), so a missing `.mtl` does not
//! stop a mesh rendered with a scene material.

use std::path::{Path, PathBuf};

use super::error::LoadError;
use crate::polygon::{self, PolygonError, PolygonOptions};
use rendiff_core::budget::Budget;
use rendiff_core::math::{DVec3, Vec2, Vec3};

/// Bytes the budget counts per `v` and per `vn` line while reading: the
/// file's position (12 B) and the index of its copy in the model (4 B).
pub(crate) const BYTES_PER_READ_VERTEX: u64 = 16;

/// Bytes counted per `vt` line while reading: 8 B and a 4 B index.
pub(crate) const BYTES_PER_READ_UV: u64 = 12;

/// Bytes counted per position, normal and uv a model copies (12, 12, 8 B:
/// the arrays of [`MeshData`]).
const BYTES_PER_COPY: [u64; 3] = [12, 12, 8];

/// Bytes counted per triangle a face will become (its corners minus 2):
/// what tessellation counts per triangle (`tessellate::BYTES_PER_TRIANGLE`,
/// which `scene` may not name; `tests/it/bad_input.rs` checks the two
/// agree), so a mesh too big to render is refused while it is read.
pub const BYTES_PER_TRIANGLE_TO_BE: u64 = 200;

/// Lines read between two reservations (a face of many corners reserves
/// at once).
const LINES_PER_RESERVATION: usize = 4096;

/// Bytes counted since the last reservation that make one at once.
const BYTES_PER_RESERVATION: u64 = 1 << 20;

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
    /// The `mtllib` statements, in file order.
    pub mtllibs: Vec<Named>,
    /// The material names `usemtl` selects, each once, in order of first
    /// use (with that line).
    pub usemtl: Vec<Named>,
    /// Per triangle, its face's `usemtl` (an index into
    /// [`MeshData::usemtl`]), [`NO_USEMTL`] for faces before the first
    /// one; empty when the file has no `usemtl`.
    pub tri_usemtl: Vec<u32>,
}

/// A name an OBJ statement gives (the rest of its line, trimmed: names
/// may hold spaces) and the line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Named {
    /// The name (possibly empty: Blender writes `usemtl` and `newmtl` of a
    /// material without a name).
    pub name: String,
    /// The line.
    pub line: u32,
}

/// In [`MeshData::tri_usemtl`]: a face before any `usemtl`.
pub const NO_USEMTL: u32 = u32::MAX;

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

fn mesh_err(path: &Path, line: usize, message: impl Into<String>) -> LoadError {
    LoadError::Mesh {
        path: path.to_path_buf(),
        line: Some(line),
        message: message.into(),
    }
}

/// A number of the file, or what is wrong with it: `str::parse::<f32>`
/// (correctly rounded) and its checks, with a fast path for the plain
/// decimals meshes are written in ([`plain_decimal`]).
pub(super) fn parse_f32(tok: &str) -> Result<f32, String> {
    if let Some(v) = plain_decimal(tok) {
        return Ok(v);
    }
    match tok.parse::<f32>() {
        Ok(v) if v.is_finite() => Ok(v),
        parsed => match tok.parse::<f64>() {
            Ok(v) if v.is_finite() => Err(format!(
                "`{}` is outside the f32 range (a magnitude above {:e})",
                shown(tok),
                f32::MAX
            )),
            Ok(_) => Err(format!("`{}` is not a finite number", shown(tok))),
            Err(_) if parsed.is_ok() => Err(format!("`{}` is not a finite number", shown(tok))),
            Err(_) => Err(format!("`{}` is not a number", shown(tok))),
        },
    }
}

/// `tok` as `str::parse::<f32>` reads it, where `tok` is an optional
/// sign, digits with at most one `.` among them (at least one digit, at
/// most nineteen), whose value as an integer is below 2⁵³, and at most
/// twenty-two after the point; `None` for anything else (exponents,
/// longer numbers, words), which std reads instead.
///
/// Why it is exact (Clinger's fast path, then one more rounding): the
/// digits as an integer `w < 2⁵³` and `10^k` (k ≤ 22) are exact
/// in `f64`, so `d = w / 10^k` is the correctly rounded `f64` of the
/// decimal `x`. Rounding `d` to `f32` gives the correctly rounded `f32` of
/// `x` unless `d` is exactly halfway between two `f32`s: a halfway point
/// `m` is an `f64`, and were `x` and `d` on opposite sides of it, `m`
/// would be nearer to `x` than `d` is. That one case, and results outside
/// the normal `f32` range, go to std. A test compares the two on a
/// million tokens.
fn plain_decimal(tok: &str) -> Option<f32> {
    let b = tok.as_bytes();
    let mut i = 0;
    let v = scan_decimal(b, &mut i)?;
    // The whole token, or it is not plain.
    (i == b.len()).then_some(v)
}

/// The plain decimal ([`plain_decimal`]'s) that starts at `b[*i]` and
/// runs to the first byte that is neither a digit nor its first `.`,
/// with `*i` moved to that byte; `None` where the digits so far are not
/// plain (none, more than nineteen, …). Whether the number ends there is
/// the caller's to check: the quick lines read each number in the same
/// pass that finds its end.
#[inline]
fn scan_decimal(b: &[u8], i: &mut usize) -> Option<f32> {
    const POW10: [f64; 23] = [
        1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
        1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
    ];
    let neg = match b.get(*i) {
        Some(b'-') => {
            *i += 1;
            true
        }
        Some(b'+') => {
            *i += 1;
            false
        }
        _ => false,
    };
    // Digits (at most 19: no overflow), and where the point stood.
    let (mut w, mut count, mut point) = (0u64, 0usize, None);
    while let Some(&c) = b.get(*i) {
        if c.is_ascii_digit() {
            count += 1;
            if count > 19 {
                return None;
            }
            w = w * 10 + u64::from(c - b'0');
        } else if c == b'.' && point.is_none() {
            point = Some(count);
        } else {
            break;
        }
        *i += 1;
    }
    let frac = point.map_or(0, |p| count - p);
    if count == 0 || frac >= POW10.len() || w >= 1 << 53 {
        return None;
    }
    #[expect(clippy::cast_precision_loss, reason = "w < 2^53 is exact in f64")]
    let d = w as f64 / POW10[frac];
    if d == 0.0 {
        return Some(if neg { -0.0 } else { 0.0 });
    }
    // Halfway between two normal f32s: the 29 bits below an f32's
    // mantissa are exactly 1000…0.
    let halfway = d.to_bits() & 0x1FFF_FFFF == 0x1000_0000;
    if halfway || d < f64::from(f32::MIN_POSITIVE) || d > f64::from(f32::MAX) {
        return None;
    }
    #[expect(
        clippy::cast_possible_truncation,
        reason = "the rounding to f32 that the comment above shows correct"
    )]
    let v = d as f32;
    Some(if neg { -v } else { v })
}

/// `s` as `str::parse::<i64>` reads it where `s` is an optional sign and
/// one to eighteen ASCII digits (no overflow possible); `None` otherwise
/// (std then reads it, or says what is wrong).
fn plain_integer(s: &str) -> Option<i64> {
    let b = s.as_bytes();
    let (neg, digits) = match b.first()? {
        b'-' => (true, &b[1..]),
        b'+' => (false, &b[1..]),
        _ => (false, b),
    };
    if digits.is_empty() || digits.len() > 18 {
        return None;
    }
    let mut v = 0i64;
    for &c in digits {
        if !c.is_ascii_digit() {
            return None;
        }
        v = v * 10 + i64::from(c - b'0');
    }
    Some(if neg { -v } else { v })
}

/// The first three of `corner.split('/')` and whether there are more, by
/// one pass over the bytes: a corner is a few characters, and `split`'s
/// searcher (set up per call) cost 2 % of loading `scenes/dense.toml`.
/// `/` is ASCII, so the cuts fall on character boundaries.
fn corner_parts(corner: &str) -> (Option<&str>, Option<&str>, Option<&str>, bool) {
    let mut cuts = [corner.len(); 3];
    let mut found = 0;
    for (i, &c) in corner.as_bytes().iter().enumerate() {
        if c == b'/' {
            if found == 3 {
                break;
            }
            cuts[found] = i;
            found += 1;
        }
    }
    let v = &corner[..cuts[0]];
    let t = (found >= 1).then(|| &corner[cuts[0] + 1..cuts[1]]);
    let n = (found >= 2).then(|| &corner[cuts[1] + 1..cuts[2]]);
    (Some(v), t, n, found == 3)
}

/// A token as shown in a message: [`rendiff_core::escape::excerpt`].
pub(super) fn shown(tok: &str) -> String {
    rendiff_core::escape::excerpt(tok.as_bytes())
}

/// The lines of a text: `\n`, `\r\n` and a lone `\r` each end one.
pub(super) fn lines(text: &str) -> impl Iterator<Item = &str> {
    let mut rest = text;
    std::iter::from_fn(move || {
        if rest.is_empty() {
            return None;
        }
        let bytes = rest.as_bytes();
        let Some(end) = bytes.iter().position(|&b| b == b'\n' || b == b'\r') else {
            let line = rest;
            rest = "";
            return Some(line);
        };
        let line = &rest[..end];
        let skip = if bytes[end] == b'\r' && bytes.get(end + 1) == Some(&b'\n') {
            2
        } else {
            1
        };
        rest = &rest[end + skip..];
        Some(line)
    })
}

/// [`BYTE_CLASS`]: a byte of a word.
const WORD: u8 = 0;
/// [`BYTE_CLASS`]: an ASCII character `char::is_whitespace` accepts.
const SPACE: u8 = 1;
/// [`BYTE_CLASS`]: `#` (a comment) or a byte of a non-ASCII character.
const STOP: u8 = 2;

/// The class of every byte, for [`tokenize`]: one load a byte instead of
/// seven comparisons.
const BYTE_CLASS: [u8; 256] = {
    let mut t = [WORD; 256];
    let mut b = 0u8;
    loop {
        t[b as usize] = match b {
            b' ' | b'\t' | b'\n' | 0x0B | 0x0C | b'\r' => SPACE,
            b'#' | 0x80..=0xFF => STOP,
            _ => WORD,
        };
        if b == u8::MAX {
            break;
        }
        b += 1;
    }
    t
};

/// The first line of `text` as [`lines`] cuts it, tokenized into `out` as
/// [`tokenize`] does, and the text after it: one pass over the bytes of
/// a plain ASCII line, which both found the line's end and its words
/// (`lines` then `tokenize` read every byte twice: 7 % of loading
/// `scenes/dense.toml`). A comment or a non-ASCII byte sends the line to
/// `tokenize`, once its end is known.
pub(super) fn first_line<'a>(text: &'a str, out: &mut Vec<&'a str>) -> (&'a str, &'a str) {
    out.clear();
    let bytes = text.as_bytes();
    let n = bytes.len();
    let mut i = 0;
    loop {
        while i < n
            && BYTE_CLASS[usize::from(bytes[i])] == SPACE
            && !matches!(bytes[i], b'\n' | b'\r')
        {
            i += 1;
        }
        let start = i;
        while i < n && BYTE_CLASS[usize::from(bytes[i])] == WORD {
            i += 1;
        }
        if i > start {
            out.push(&text[start..i]);
        }
        if i >= n {
            return (text, "");
        }
        match bytes[i] {
            b'\n' | b'\r' => return split_line(text, i),
            b if BYTE_CLASS[usize::from(b)] == STOP => {
                let end = bytes[i..]
                    .iter()
                    .position(|&b| b == b'\n' || b == b'\r')
                    .map_or(n, |k| i + k);
                let (line, rest) = split_line(text, end);
                tokenize(line, out);
                return (line, rest);
            }
            // Other ASCII white space: the next word.
            _ => {}
        }
    }
}

/// `text` cut at the line end at byte `end` (`\n`, `\r\n` or a lone `\r`;
/// or the text's end): the line and what follows its end.
fn split_line(text: &str, end: usize) -> (&str, &str) {
    let bytes = text.as_bytes();
    let skip = match bytes.get(end) {
        None => 0,
        Some(b'\r') if bytes.get(end + 1) == Some(&b'\n') => 2,
        Some(_) => 1,
    };
    (&text[..end], &text[end + skip..])
}

/// Splits a line into `out` at white space (`char::is_whitespace`), up to
/// a `#` (a comment starts anywhere), with one pass over the bytes for
/// ASCII lines.
pub(super) fn tokenize<'a>(line: &'a str, out: &mut Vec<&'a str>) {
    out.clear();
    let bytes = line.as_bytes();
    let mut i = 0;
    while i < bytes.len() {
        while i < bytes.len() && BYTE_CLASS[usize::from(bytes[i])] == SPACE {
            i += 1;
        }
        let start = i;
        while i < bytes.len() && BYTE_CLASS[usize::from(bytes[i])] == WORD {
            i += 1;
        }
        if i < bytes.len() && !bytes[i].is_ascii() {
            // Other white space: the rest of the line the slow way.
            let rest = &line[start..];
            let content = rest.find('#').map_or(rest, |k| &rest[..k]);
            out.extend(content.split_whitespace());
            return;
        }
        if i > start {
            out.push(&line[start..i]);
        }
        if bytes.get(i) == Some(&b'#') {
            return;
        }
    }
}

/// The file index (from 0) of a face's index `i` (1 … `count` from the
/// start, −1 … −`count` back from the last defined), or `None` when it is
/// out of range.
fn resolve_index(i: i64, count: usize) -> Option<usize> {
    let back = usize::try_from(i.unsigned_abs()).unwrap_or(usize::MAX);
    match i.signum() {
        1 if back <= count => Some(back - 1),
        -1 if back <= count => Some(count - back),
        _ => None,
    }
}

/// Whether `b` ends a word of a quick line ([`Reader::quick_line`]): a
/// space, a tab or a line end.
#[inline]
fn ends_quick_word(b: Option<&u8>) -> bool {
    matches!(b, None | Some(b' ' | b'\t' | b'\n' | b'\r'))
}

/// The corner `v`, `v/vt`, `v//vn` or `v/vt/vn` that starts at `b[*i]`
/// and ends at a space, a tab, a line end or the text's end
/// ([`ends_quick_word`]), of plain integer indices ([`plain_integer`]'s:
/// a sign and one to eighteen digits) within range, resolved as
/// [`Reader::parse_corners`] resolves it, with `*i` moved to its end, in
/// one pass over its bytes (`corner_parts` and then `plain_integer` on
/// each part were 160 instructions a corner); `None` for any other corner,
/// which `parse_corners` then reads or names.
#[inline]
fn scan_corner(b: &[u8], i: &mut usize, counts: [usize; 3]) -> Option<Corner> {
    let mut out = [None; 3];
    for (k, slot) in out.iter_mut().enumerate() {
        let start = *i;
        let neg = b.get(*i) == Some(&b'-');
        if neg || b.get(*i) == Some(&b'+') {
            *i += 1;
        }
        let digits = *i;
        let mut v = 0i64;
        while let Some(&c) = b.get(*i).filter(|c| c.is_ascii_digit()) {
            if *i - digits == 18 {
                return None;
            }
            v = v * 10 + i64::from(c - b'0');
            *i += 1;
        }
        if *i == digits {
            // No digits: an empty part is none (an empty position then
            // makes the corner not plain, below); a lone sign is not plain.
            if *i != start {
                return None;
            }
        } else {
            *slot = Some(resolve_index(if neg { -v } else { v }, counts[k])?);
        }
        match b.get(*i) {
            Some(b'/') => *i += 1,
            end if ends_quick_word(end) => {
                return Some(Corner {
                    v: out[0]?,
                    t: out[1],
                    n: out[2],
                });
            }
            _ => return None,
        }
    }
    // A fourth part.
    None
}

/// A polygon error of a face with more than three corners, in the face's
/// own terms: its corners as written on the line.
/// The rings of a face as corner indices: the face itself, or, for a
/// keyhole face, its outline first and then its holes. A keyhole face
/// (how several exporters write a face with a hole: LightWave, assimp's
/// `concave_polygon.obj`) walks a bridge edge from the outline to a hole
/// and, after going round the hole, straight back; cutting both copies of
/// every such edge (the same two positions, once each way) leaves closed
/// rings. The ring of the largest area is the outline (it keeps the
/// face's winding); the rest are its holes. Faces without a bridge, and
/// any cut that would leave a ring of fewer than three corners, stay as
/// given (the triangulator then names the spike).
fn keyhole_rings(v: &[u32], pts: &[DVec3]) -> Vec<Vec<usize>> {
    // Each ring is searched once with a table of its directed edges (linear
    // in its corners); a face with more bridges than this is left as given
    // (a hostile face must not make the search quadratic).
    const MAX_CUTS: usize = 256;
    let bridge = |ring: &[usize]| -> Option<(usize, usize)> {
        let n = ring.len();
        let at = |k: usize| v[ring[k % n]];
        let mut starts: std::collections::HashMap<(u32, u32), usize> =
            std::collections::HashMap::with_capacity(n);
        for k in 0..n {
            starts.entry((at(k), at(k + 1))).or_insert(k);
        }
        (0..n).find_map(|i| {
            let (a, b) = (at(i), at(i + 1));
            let j = *starts.get(&(b, a))?;
            // Both rings keep at least three corners.
            (a != b && j > i && j - i > 3 && n - (j - i) > 3).then_some((i, j))
        })
    };
    let mut done = Vec::new();
    let mut todo = vec![(0..v.len()).collect::<Vec<usize>>()];
    let mut cuts = 0;
    while let Some(ring) = todo.pop() {
        match bridge(&ring).filter(|_| cuts < MAX_CUTS) {
            Some((i, j)) => {
                // ring[i+1 .. j] (from b round to before the second b) and
                // ring[j+1 ..] + ring[.. i] (from a round to before the
                // first a).
                cuts += 1;
                let n = ring.len();
                let inner: Vec<usize> = ring[i + 1..j].to_vec();
                let outer: Vec<usize> = ring[(j + 1).min(n)..]
                    .iter()
                    .chain(&ring[..i])
                    .copied()
                    .collect();
                todo.push(outer);
                todo.push(inner);
            }
            None => done.push(ring),
        }
    }
    let mut rings = done;
    if rings.len() > 1 {
        let area = |ring: &[usize]| {
            let mut s = DVec3::ZERO;
            for k in 0..ring.len() {
                s += pts[ring[k]].cross(pts[ring[(k + 1) % ring.len()]]);
            }
            s.length()
        };
        let outer = (0..rings.len())
            .max_by(|&x, &y| area(&rings[x]).total_cmp(&area(&rings[y])))
            .unwrap_or(0);
        rings.swap(0, outer);
    }
    rings
}

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

/// No copy yet.
const NONE: u32 = u32::MAX;

/// The entries of one kind (positions, normals or uvs) as the file gives
/// them, and where the current model has copied each.
struct Pool<T> {
    /// The file's entries, in file order.
    file: Vec<T>,
    /// For each file entry, the index of its copy in the mesh's list;
    /// stale below `start` (an earlier model's).
    copy: Vec<u32>,
    /// Where the current model's entries start in the mesh's list.
    start: u32,
    /// The model's first corner had no entry of this kind: the file's
    /// first entry stands in as the model's first one, once it is known
    /// that the file has one by the model's end (tobj).
    stand_in: bool,
}

impl<T: Copy> Pool<T> {
    fn new() -> Pool<T> {
        Pool {
            file: Vec::new(),
            copy: Vec::new(),
            start: 0,
            stand_in: false,
        }
    }

    fn push(&mut self, entry: T) {
        self.file.push(entry);
        self.copy.push(NONE);
    }

    /// The mesh's index of file entry `g`, copying it on first use in the
    /// model; also says how many entries it copied.
    #[inline(always)]
    fn index(&mut self, g: usize, out: &mut Vec<T>) -> (u32, u64) {
        let stand_in = u64::from(self.place_stand_in(out));
        let c = self.copy[g];
        if c != NONE && c >= self.start {
            return (c, stand_in);
        }
        let i = u32::try_from(out.len()).unwrap_or(NONE - 1);
        out.push(self.file[g]);
        self.copy[g] = i;
        (i, stand_in + 1)
    }

    /// [`Pool::index`] of a corner's optional entry (`None` and no copy
    /// where the corner has none, which, on the model's `first` corner,
    /// asks for the file's first entry as its stand-in: tobj's).
    #[inline(always)]
    fn index_or_stand_in(
        &mut self,
        g: Option<usize>,
        first: bool,
        out: &mut Vec<T>,
    ) -> (Option<u32>, u64) {
        match g {
            Some(g) => {
                let (i, new) = self.index(g, out);
                (Some(i), new)
            }
            None => {
                self.stand_in |= first;
                (None, 0)
            }
        }
    }

    /// Puts the pending stand-in in place (the file has entries now).
    fn place_stand_in(&mut self, out: &mut Vec<T>) -> bool {
        if !self.stand_in || self.file.is_empty() {
            return false;
        }
        self.stand_in = false;
        self.copy[0] = u32::try_from(out.len()).unwrap_or(NONE - 1);
        out.push(self.file[0]);
        true
    }

    /// Ends the model.
    fn end_model(&mut self, out: &mut Vec<T>) -> bool {
        let placed = self.place_stand_in(out);
        self.stand_in = false;
        self.start = u32::try_from(out.len()).unwrap_or(NONE - 1);
        placed
    }
}

/// A face corner: file indices (from 0) of its position, uv and normal.
#[derive(Clone, Copy)]
struct Corner {
    v: usize,
    t: Option<usize>,
    n: Option<usize>,
}

/// The reader's state.
struct Reader<'a> {
    path: &'a Path,
    budget: &'a Budget,
    positions: Pool<Vec3>,
    normals: Pool<Vec3>,
    uvs: Pool<Vec2>,
    data: MeshData,
    /// Faces and corners of the current model.
    model_faces: usize,
    model_corners: usize,
    /// Triangles the faces become, at most (corners − 2 each).
    triangles_to_be: u64,
    /// Bytes reserved so far, and counted since.
    reserved: u64,
    pending: u64,
    lines_since: usize,
    /// The corners of the face being read.
    corners: Vec<Corner>,
    /// The current `usemtl` ([`NO_USEMTL`] before the first).
    current_mtl: u32,
}

impl Reader<'_> {
    fn err(&self, line: usize, message: impl Into<String>) -> LoadError {
        mesh_err(self.path, line, message)
    }

    /// Counts `bytes` and reserves what was counted when it is enough.
    fn count(&mut self, line: usize, bytes: u64) -> Result<(), LoadError> {
        self.pending = self.pending.saturating_add(bytes);
        if self.pending >= BYTES_PER_RESERVATION {
            self.reserve(line)?;
        }
        Ok(())
    }

    /// Reserves what was counted since the last reservation.
    fn reserve(&mut self, line: usize) -> Result<(), LoadError> {
        self.lines_since = 0;
        if self.pending == 0 {
            return Ok(());
        }
        let total = self.reserved.saturating_add(self.pending);
        self.budget
            .reserve(self.pending, || {
                format!(
                    "the mesh up to line {line} ({} in all: {} positions, {} normals, {} uvs, {} triangles to be)",
                    rendiff_core::budget::human(total),
                    self.positions.file.len(),
                    self.normals.file.len(),
                    self.uvs.file.len(),
                    self.triangles_to_be
                )
            })
            .map_err(|e| self.err(line, e.to_string()))?;
        self.reserved = total;
        self.pending = 0;
        Ok(())
    }

    /// The numbers of a `v`, `vt` or `vn` line.
    fn numbers(
        &self,
        line: usize,
        kw: &str,
        args: &[&str],
        counts: &[usize],
        what: &str,
    ) -> Result<[f32; 6], LoadError> {
        if !counts.contains(&args.len()) {
            let accepted = match counts {
                [n] => n.to_string(),
                [a, b] => format!("{a} or {b}"),
                [first, .., last] if counts.windows(2).all(|w| w[1] == w[0] + 1) => {
                    format!("{first} to {last}")
                }
                [init @ .., last] => {
                    let init: Vec<String> = init.iter().map(usize::to_string).collect();
                    format!("{} or {last}", init.join(", "))
                }
                [] => "no".to_string(),
            };
            return Err(self.err(
                line,
                format!(
                    "`{kw}` needs {accepted} numbers ({what}), found {}",
                    args.len()
                ),
            ));
        }
        let mut out = [0.0; 6];
        for (o, a) in out.iter_mut().zip(args) {
            *o = parse_f32(a).map_err(|m| self.err(line, m))?;
        }
        Ok(out)
    }

    fn vertex(&mut self, line: usize, args: &[&str]) -> Result<(), LoadError> {
        let x = self.numbers(line, "v", args, &[3, 4, 6], "x y z, x y z w or x y z r g b")?;
        if args.len() == 4 && x[3] <= 0.0 {
            return Err(self.err(
                line,
                format!(
                    "the weight w = `{}` of `v` must be > 0 (x y z w; w is otherwise ignored)",
                    shown(args[3])
                ),
            ));
        }
        self.positions.push(Vec3::new(x[0], x[1], x[2]));
        self.count(line, BYTES_PER_READ_VERTEX)
    }

    fn uv(&mut self, line: usize, args: &[&str]) -> Result<(), LoadError> {
        let x = self.numbers(line, "vt", args, &[1, 2, 3], "u [v] [w]")?;
        if let Some(a) = args
            .iter()
            .zip(x)
            .take(2)
            .find(|(_, v)| f64::from(v.abs()) > super::MAX_UV)
        {
            return Err(self.err(
                line,
                format!(
                    "texture coordinate `{}` is beyond ±{:e} (f32 resolves it to a sixteenth of a repeat or worse)",
                    shown(a.0),
                    super::MAX_UV
                ),
            ));
        }
        self.uvs.push(Vec2::new(x[0], x[1]));
        self.count(line, BYTES_PER_READ_UV)
    }

    fn normal(&mut self, line: usize, args: &[&str]) -> Result<(), LoadError> {
        let x = self.numbers(line, "vn", args, &[3], "x y z")?;
        self.normals.push(Vec3::new(x[0], x[1], x[2]));
        self.count(line, BYTES_PER_READ_VERTEX)
    }

    /// Parses and checks the corners of a face into `self.corners`.
    fn parse_corners(&mut self, line: usize, args: &[&str]) -> Result<(), LoadError> {
        let counts = [
            self.positions.file.len(),
            self.uvs.file.len(),
            self.normals.file.len(),
        ];
        let mut corners = std::mem::take(&mut self.corners);
        corners.clear();
        for corner in args {
            let (v, t, n, more) = corner_parts(corner);
            if more || v.is_none_or(str::is_empty) {
                return Err(self.err(
                    line,
                    format!(
                        "malformed face corner `{}`; expected v, v/vt, v//vn or v/vt/vn",
                        shown(corner)
                    ),
                ));
            }
            let idx = |s: &str, kind: usize| -> Result<usize, LoadError> {
                let count = counts[kind];
                let i: i64 = plain_integer(s)
                    .map_or_else(|| s.parse(), Ok)
                    .map_err(|_| {
                        self.err(
                            line,
                            format!(
                                "`{}` in corner `{}` is not an integer index",
                                shown(s),
                                shown(corner)
                            ),
                        )
                    })?;
                resolve_index(i, count).ok_or_else(|| {
                    self.err(
                        line,
                        format!(
                            "{} index {i} in corner `{}` is out of range (1 … {count}, or -1 … -{count}, defined so far)",
                            ["vertex", "texture", "normal"][kind],
                            shown(corner)
                        ),
                    )
                })
            };
            let v = idx(v.unwrap_or(""), 0)?;
            let t = t.filter(|s| !s.is_empty()).map(|s| idx(s, 1)).transpose()?;
            let n = n.filter(|s| !s.is_empty()).map(|s| idx(s, 2)).transpose()?;
            corners.push(Corner { v, t, n });
        }
        self.corners = corners;
        Ok(())
    }

    fn face(&mut self, line: usize, args: &[&str]) -> Result<(), LoadError> {
        if args.len() < 3 {
            return Err(self.err(
                line,
                format!("a face needs at least 3 corners, found {}", args.len()),
            ));
        }
        self.parse_corners(line, args)?;
        self.add_face(line, args)
    }

    /// The mesh's indices of a corner's position, uv and normal, each
    /// copied into the mesh on its first use in the model; adds the bytes
    /// copied to `copied`.
    #[inline(always)]
    fn corner_indices(&mut self, c: Corner, copied: &mut u64) -> (u32, Option<u32>, Option<u32>) {
        let first = self.model_corners == 0;
        self.model_corners += 1;
        let (v, new_v) = self.positions.index(c.v, &mut self.data.positions);
        let (t, new_t) = self.uvs.index_or_stand_in(c.t, first, &mut self.data.uvs);
        let (n, new_n) = self
            .normals
            .index_or_stand_in(c.n, first, &mut self.data.normals);
        *copied +=
            new_v * BYTES_PER_COPY[0] + new_n * BYTES_PER_COPY[1] + new_t * BYTES_PER_COPY[2];
        (v, t, n)
    }

    /// Appends a triangle of the face on `line`.
    #[inline]
    fn push_triangle(&mut self, line: usize, tri: MeshTri) {
        let data = &mut self.data;
        data.triangles.push(tri);
        data.lines.push(u32::try_from(line).unwrap_or(u32::MAX));
        if !data.usemtl.is_empty() {
            data.tri_usemtl.push(self.current_mtl);
        }
    }

    /// Adds a face of three corners (from [`Reader::quick_line`] or
    /// [`Reader::add_face`]): one triangle, without the buffers a face
    /// of more corners needs (`add_face`'s general path had been about
    /// 500 instructions a triangle of `scenes/dense.toml`'s meshes).
    fn add_triangle(&mut self, line: usize, corners: [Corner; 3]) -> Result<(), LoadError> {
        self.triangles_to_be += 1;
        self.count(line, BYTES_PER_TRIANGLE_TO_BE)?;
        let mut copied = 0u64;
        let [a, b, c] = corners.map(|k| self.corner_indices(k, &mut copied));
        self.model_faces += 1;
        self.data.faces += 1;
        self.pending += copied;
        let all = |x: Option<u32>, y: Option<u32>, z: Option<u32>| Some([x?, y?, z?]);
        let tri = MeshTri {
            v: [a.0, b.0, c.0],
            n: all(a.2, b.2, c.2),
            t: all(a.1, b.1, c.1),
        };
        self.push_triangle(line, tri);
        Ok(())
    }

    /// Adds the face whose corners [`Reader::parse_corners`] left in
    /// `self.corners`; `args` are the corners as written, which only a
    /// face of more than three corners names (in a triangulation's error).
    fn add_face(&mut self, line: usize, args: &[&str]) -> Result<(), LoadError> {
        if let [a, b, c] = self.corners[..] {
            return self.add_triangle(line, [a, b, c]);
        }
        let to_be = (self.corners.len() - 2) as u64;
        self.triangles_to_be += to_be;
        self.count(line, to_be * BYTES_PER_TRIANGLE_TO_BE)?;

        // The mesh's indices of the corners, copying on first use.
        let corners = std::mem::take(&mut self.corners);
        let (mut v, mut t, mut n) = (Vec::new(), Vec::new(), Vec::new());
        let mut copied = 0u64;
        for &c in &corners {
            let (i, ti, ni) = self.corner_indices(c, &mut copied);
            v.push(i);
            t.extend(ti);
            n.extend(ni);
        }
        let has_t = t.len() == corners.len();
        let has_n = n.len() == corners.len();
        self.model_faces += 1;
        self.data.faces += 1;
        self.pending += copied;

        let pts: Vec<DVec3> = v
            .iter()
            .map(|&i| {
                let p = self.data.positions[i as usize];
                DVec3::new(f64::from(p.x), f64::from(p.y), f64::from(p.z))
            })
            .collect();
        // A keyhole face (a ring with a hole, joined by a bridge edge
        // walked once each way) is its outline and holes.
        let rings = keyhole_rings(&v, &pts);
        let at = |ring: &[usize]| ring.iter().map(|&k| pts[k]).collect::<Vec<DVec3>>();
        let outline = at(&rings[0]);
        let holes: Vec<Vec<DVec3>> = rings[1..].iter().map(|r| at(r)).collect();
        let flat: Vec<usize> = rings.iter().flatten().copied().collect();
        let tri = polygon::triangulate(
            &outline,
            &holes,
            PolygonOptions {
                check_planarity: false,
            },
        )
        .map_err(|e| {
            // The triangulator names points of the rings, in ring order.
            let named: Vec<&str> = flat.iter().map(|&k| args[k]).collect();
            self.err(line, face_error(&e, &named))
        })?;
        // The CDT triangles wind around the outline's Newell normal,
        // which follows the face's own winding.
        for c in &tri.triangles {
            let c = c.map(|i| flat[i as usize]);
            self.push_triangle(
                line,
                MeshTri {
                    v: c.map(|k| v[k]),
                    n: has_n.then(|| c.map(|k| n[k])),
                    t: has_t.then(|| c.map(|k| t[k])),
                },
            );
        }
        self.corners = corners;
        Ok(())
    }

    /// Ends the current model (tobj's models: at `o`, `g` and the end).
    fn end_model(&mut self) {
        let mut copied = 0;
        if self.normals.end_model(&mut self.data.normals) {
            copied += BYTES_PER_COPY[1];
        }
        if self.uvs.end_model(&mut self.data.uvs) {
            copied += BYTES_PER_COPY[2];
        }
        self.positions.end_model(&mut self.data.positions);
        self.pending += copied;
        self.model_faces = 0;
        self.model_corners = 0;
    }

    /// `usemtl NAME`: the faces that follow use material NAME.
    fn usemtl(&mut self, line: usize, name: &str) {
        let line = u32::try_from(line).unwrap_or(u32::MAX);
        let data = &mut self.data;
        let k = match data.usemtl.iter().position(|n| n.name == name) {
            Some(k) => k,
            None => {
                if data.usemtl.is_empty() {
                    // The faces before the first usemtl had none.
                    data.tri_usemtl = vec![NO_USEMTL; data.triangles.len()];
                    self.pending += 4 * data.triangles.len() as u64;
                }
                data.usemtl.push(Named {
                    name: name.to_string(),
                    line,
                });
                data.usemtl.len() - 1
            }
        };
        self.current_mtl = u32::try_from(k).unwrap_or(NO_USEMTL - 1);
    }

    /// The two lines a mesh file is made of, read without tokenizing:
    /// `v` and three plain decimals ([`plain_decimal`]), or `f` and three
    /// corners of plain integer indices within range ([`scan_corner`]),
    /// the words apart by spaces or tabs, nothing after the last but
    /// spaces or tabs. Returns the text after the line; `None`, having
    /// changed nothing, for any other line (white space before the
    /// keyword, a comment, an exponent, a fourth number or corner, an
    /// index out of range …), which [`Reader::statement`] then reads and,
    /// where it is wrong, names. A line read here leaves the reader as
    /// `statement` leaves it: the same numbers (`parse_f32` returns
    /// `plain_decimal`'s where it has one), the same indices, the same
    /// counting. Tokenizing the line and matching its keyword had been
    /// about 1 450 instructions a line of `scenes/dense.toml`'s meshes.
    fn quick_line<'t>(&mut self, line: usize, text: &'t str) -> Result<Option<&'t str>, LoadError> {
        let b = text.as_bytes();
        let vertex = match b {
            [b'v', b' ' | b'\t', ..] => true,
            [b'f', b' ' | b'\t', ..] => false,
            _ => return Ok(None),
        };
        // Each word is read where it starts, in the pass that finds its
        // end: a space, a tab, a line end or the text's end (a word
        // ending anywhere else, `#` or a non-ASCII byte among them, is
        // not plain, and so the line is not quick).
        let mut i = 1;
        let skip_blanks = |i: &mut usize| {
            while matches!(b.get(*i), Some(b' ' | b'\t')) {
                *i += 1;
            }
        };
        // After the third word: blanks, then the line's (or text's) end.
        let ends_line = |i: &mut usize| {
            skip_blanks(i);
            matches!(b.get(*i), None | Some(b'\n' | b'\r'))
        };
        if vertex {
            let mut x = [0.0f32; 3];
            for v in &mut x {
                skip_blanks(&mut i);
                match scan_decimal(b, &mut i) {
                    Some(d) if ends_quick_word(b.get(i)) => *v = d,
                    _ => return Ok(None),
                }
            }
            if !ends_line(&mut i) {
                return Ok(None);
            }
            self.positions.push(Vec3::from_array(x));
            self.count(line, BYTES_PER_READ_VERTEX)?;
        } else {
            let counts = [
                self.positions.file.len(),
                self.uvs.file.len(),
                self.normals.file.len(),
            ];
            let mut corners = [Corner {
                v: 0,
                t: None,
                n: None,
            }; 3];
            for c in &mut corners {
                skip_blanks(&mut i);
                let Some(read) = scan_corner(b, &mut i, counts) else {
                    return Ok(None);
                };
                *c = read;
            }
            if !ends_line(&mut i) {
                return Ok(None);
            }
            self.add_triangle(line, corners)?;
        }
        self.lines_since += 1;
        if self.lines_since >= LINES_PER_RESERVATION {
            self.reserve(line)?;
        }
        Ok(Some(split_line(text, i).1))
    }

    /// One statement: `toks` are its words, `raw` the whole line.
    fn statement(&mut self, line: usize, toks: &[&str], raw: &str) -> Result<(), LoadError> {
        let Some((&kw, args)) = toks.split_first() else {
            return Ok(());
        };
        // What follows the keyword up to a comment, trimmed (a name with
        // spaces).
        let rest = || {
            let c = raw.find('#').map_or(raw, |i| &raw[..i]).trim_start();
            c.get(kw.len()..).unwrap_or("").trim()
        };
        let named = |what: &str| -> Result<(), LoadError> {
            if args.is_empty() {
                return Err(self.err(line, format!("`{kw}` needs {what}")));
            }
            Ok(())
        };
        match kw {
            "v" => self.vertex(line, args)?,
            "vt" => self.uv(line, args)?,
            "vn" => self.normal(line, args)?,
            "f" => self.face(line, args)?,
            "o" | "g" => {
                named(if kw == "o" {
                    "an object name"
                } else {
                    "a group name"
                })?;
                if self.model_faces > 0 {
                    self.end_model();
                }
            }
            // A material without a name (Blender writes `usemtl` alone for
            // one) is the material named "" of the libraries.
            "usemtl" => self.usemtl(line, rest()),
            "mtllib" => {
                named("a file name")?;
                self.data.mtllibs.push(Named {
                    name: rest().to_string(),
                    line: u32::try_from(line).unwrap_or(u32::MAX),
                });
            }
            "s" => named("a smoothing group (a number, or `off`)")?,
            "l" | "p" => {}
            other => {
                let hint = if other.contains('\u{FFFD}') || other.chars().any(char::is_control) {
                    " (the line is not text: is this an OBJ file?)"
                } else {
                    ""
                };
                return Err(self.err(
                    line,
                    format!(
                        "unsupported OBJ statement `{}`; expected v, vt, vn, f, o, g, s, usemtl, mtllib, l or p{hint}",
                        shown(other)
                    ),
                ));
            }
        }
        self.lines_since += 1;
        if self.lines_since >= LINES_PER_RESERVATION {
            self.reserve(line)?;
        }
        Ok(())
    }
}

/// Reads an OBJ text, reserving what it builds in `budget` as it goes;
/// `reserved` says how much it reserved, error or not.
fn read(
    path: &Path,
    bytes: &[u8],
    budget: &Budget,
    reserved: &mut u64,
) -> Result<MeshData, LoadError> {
    // Valid UTF-8 (every ASCII file) is borrowed after one fast check;
    // only other bytes go through the slower lossy decoding.
    let text = std::str::from_utf8(bytes).map_or_else(
        |_| String::from_utf8_lossy(bytes),
        std::borrow::Cow::Borrowed,
    );
    let text = text.strip_prefix('\u{FEFF}').unwrap_or(&text);
    let mut r = Reader {
        path,
        budget,
        positions: Pool::new(),
        normals: Pool::new(),
        uvs: Pool::new(),
        data: MeshData {
            path: path.to_path_buf(),
            positions: Vec::new(),
            normals: Vec::new(),
            uvs: Vec::new(),
            triangles: Vec::new(),
            lines: Vec::new(),
            faces: 0,
            mtllibs: Vec::new(),
            usemtl: Vec::new(),
            tri_usemtl: Vec::new(),
        },
        model_faces: 0,
        model_corners: 0,
        triangles_to_be: 0,
        reserved: 0,
        pending: 0,
        lines_since: 0,
        corners: Vec::new(),
        current_mtl: NO_USEMTL,
    };
    let mut toks: Vec<&str> = Vec::new();
    let mut last = 0;
    let result = (|| {
        let mut rest: &str = text;
        while !rest.is_empty() {
            last += 1;
            if let Some(after) = r.quick_line(last, rest)? {
                rest = after;
                continue;
            }
            let (raw, after) = first_line(rest, &mut toks);
            rest = after;
            r.statement(last, &toks, raw)?;
        }
        r.end_model();
        if r.data.faces == 0 {
            return Err(LoadError::Mesh {
                path: path.to_path_buf(),
                line: None,
                message: "the mesh has no faces".into(),
            });
        }
        r.reserve(last.max(1))
    })();
    *reserved = r.reserved;
    result.map(|()| r.data)
}

/// Loads an OBJ file from its bytes (decoded lossily if not UTF-8) within
/// the default memory budget.
///
/// # Errors
///
/// [`LoadError::Mesh`] naming the file and line of the first problem.
pub fn load_obj_bytes(path: &Path, bytes: &[u8]) -> Result<MeshData, LoadError> {
    read(path, bytes, &Budget::default(), &mut 0)
}

/// Bytes a loaded mesh holds per position, normal, uv and triangle
/// (`MeshData`'s arrays).
pub(crate) fn mesh_bytes(d: &MeshData) -> u64 {
    (d.positions.len() * 12
        + d.normals.len() * 12
        + d.uvs.len() * 8
        + d.triangles.len() * 44
        + d.tri_usemtl.len() * 4) as u64
}

/// [`load_obj_bytes`] within `budget`: what the reader builds is reserved
/// while it reads (every 4096 lines, or at once for a face of many
/// corners), so a mesh too big for the budget is refused at the line it
/// reached; once read, what the mesh holds stays reserved.
///
/// # Errors
///
/// As [`load_obj_bytes`], or the figure that does not fit the budget.
pub(crate) fn load_obj_within(
    path: &Path,
    bytes: &[u8],
    budget: &Budget,
) -> Result<MeshData, LoadError> {
    let mut reserved = 0;
    let d = read(path, bytes, budget, &mut reserved);
    budget.release(reserved);
    let d = d?;
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

#[cfg(test)]
#[allow(
    clippy::cast_possible_truncation,
    clippy::cast_precision_loss,
    clippy::cast_sign_loss,
    clippy::cast_possible_wrap,
    reason = "test fixtures: small generated counts and indices, where a wrong cast fails the test"
)]
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

    /// The quick path (`Reader::quick_line`) reads what the tokenizing
    /// path reads: random files of plain and unusual lines give the same
    /// mesh, or the same error at the same line, as the same files with a
    /// space before every line (which no quick line has, so the statement
    /// path reads them all). Half the files hold only lines a mesh may
    /// have, so that most of those load.
    #[test]
    fn quick_lines_read_as_statements_do() {
        let mut z = 0x2545_f491_4f6c_dd1du64;
        let mut next = move |n: u64| {
            z ^= z << 13;
            z ^= z >> 7;
            z ^= z << 17;
            z % n
        };
        type Next<'a> = &'a mut dyn FnMut(u64) -> u64;
        let number = |next: Next<'_>, odd: bool| -> String {
            match if odd { next(13) } else { 3 + next(7) } {
                0 => "1e-3".into(),
                1 => "-".into(),
                2 => "1234567890123456789012".into(),
                // A plain decimal and more word after it, which would
                // read as two numbers if a number's end went unchecked.
                10 => "1-2".into(),
                11 => "3.5.5".into(),
                12 => "2+7".into(),
                3 => format!("{}", f32::from_bits(next(1 << 31) as u32 & 0x4FFF_FFFF)),
                _ => format!(
                    "{}{}.{}",
                    ["", "-", "+"][next(3) as usize],
                    next(100),
                    next(100_000)
                ),
            }
        };
        // An index among `count` entries (uvs, normals: 3).
        let index = |next: Next<'_>, odd: bool, count: u64| -> String {
            match if odd {
                next(12)
            } else {
                2 + 2 * next(2) + 6 * next(2)
            } {
                0 => "0".into(),
                1 => "-0".into(),
                2 => format!("-{}", 1 + next(count)),
                3 => "99".into(),
                4 => format!("+{}", 1 + next(count)),
                5 => "1234567890123456789".into(),
                6 => String::new(),
                7 => "x".into(),
                _ => format!("{}", 1 + next(count)),
            }
        };
        let corner = |next: Next<'_>, odd: bool| -> String {
            let odd_v = odd && next(4) == 0;
            let v = index(next, odd_v, 9);
            match if odd {
                next(9)
            } else {
                [0, 1, 2, 5, 6, 6][next(6) as usize]
            } {
                0 => format!("{v}/{}", index(next, odd, 3)),
                1 => format!("{v}//{}", index(next, odd, 3)),
                2 => format!("{v}/{}/{}", index(next, odd, 3), index(next, odd, 3)),
                3 => format!("{v}/1/1/1"),
                4 => format!("{v}//"),
                5 => format!("{v}/"),
                _ => v,
            }
        };
        let (mut quick, mut loaded) = (0, 0);
        for _ in 0..3000 {
            let odd = next(2) == 0;
            let mut lines: Vec<String> = (0..9)
                .map(|k| format!("v {k}.5 {}.25 -{k}", k % 3))
                .chain((0..3).map(|k| format!("vn 0 {k} 1")))
                .chain((0..3).map(|k| format!("vt 0.{k} 1")))
                .collect();
            for _ in 0..1 + next(12) {
                let sep = [" ", " ", " ", "\t", "  ", " \t"][next(6) as usize];
                let tail = if odd {
                    ["", "", " ", "\t", " # note", "#", "\u{b}", " 7", "é"][next(9) as usize]
                } else {
                    ["", "", "", " ", "\t", " # note", "#"][next(7) as usize]
                };
                let line = match next(if odd { 8 } else { 7 }) {
                    0..=2 => {
                        let n = if odd && next(8) == 0 { 2 + next(3) } else { 3 };
                        let nums: Vec<String> = (0..n).map(|_| number(&mut next, odd)).collect();
                        format!("v{sep}{}{tail}", nums.join(sep))
                    }
                    3..=5 => {
                        let n = if next(8) == 0 { 4 } else { 3 };
                        let cs: Vec<String> = (0..n).map(|_| corner(&mut next, odd)).collect();
                        format!("f{sep}{}{tail}", cs.join(sep))
                    }
                    6 => ["g part", "o x", "usemtl red", "s off", "vn 1 0 0", ""][next(6) as usize]
                        .into(),
                    _ => format!("{}v 1 2 3", ["\t", "v", "F"][next(3) as usize]),
                };
                quick += usize::from(line.starts_with("v ") || line.starts_with("f "));
                lines.push(line);
            }
            let end = ["\n", "\r\n", "\r"][next(3) as usize];
            let text = lines.join(end);
            let spaced = lines
                .iter()
                .map(|l| format!(" {l}"))
                .collect::<Vec<_>>()
                .join(end);
            match (load(&text), load(&spaced)) {
                (Ok(a), Ok(b)) => {
                    loaded += 1;
                    assert_eq!(a, b, "{text:?}");
                }
                (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string(), "{text:?}"),
                (a, b) => panic!("{text:?}: {:?} against {:?}", a.map(|_| ()), b.map(|_| ())),
            }
        }
        assert!(quick > 10_000, "{quick} lines could take the quick path");
        assert!(loaded > 1_000, "{loaded} of 3000 files loaded");
    }

    /// Every bundled mesh (`v`, `vt`, `vn`, `f` with all corner forms,
    /// `o`, `g`, `usemtl`, comments) and every input of the OBJ fuzz
    /// corpus (`fuzz/corpus/obj_bytes`: binary garbage, odd white space,
    /// huge indices) reads as it does with every line sent to the
    /// statement path: the same mesh, or the same error.
    #[test]
    fn bundled_meshes_and_the_fuzz_corpus_read_as_statements_do() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let meshes = root.join("scenes/meshes");
        let mut files = vec![meshes.join("spider/spider.obj")];
        for dir in [meshes, root.join("fuzz/corpus/obj_bytes")] {
            for e in std::fs::read_dir(&dir).unwrap() {
                let p = e.unwrap().path();
                if p.is_file() && p.extension().is_none_or(|x| x == "obj") {
                    files.push(p);
                }
            }
        }
        assert!(files.len() >= 500, "{} files", files.len());
        let (mut loaded, mut quick) = (0, 0);
        for p in files {
            let bytes = std::fs::read(&p).unwrap();
            let text = String::from_utf8_lossy(&bytes);
            let text = text.strip_prefix('\u{FEFF}').unwrap_or(&text);
            quick += lines(text)
                .filter(|l| l.starts_with("v ") || l.starts_with("f "))
                .count();
            let spaced: String = lines(text).map(|l| format!(" {l}\n")).collect();
            let path = Path::new("m.obj");
            match (
                load_obj_bytes(path, &bytes),
                load_obj_bytes(path, spaced.as_bytes()),
            ) {
                (Ok(a), Ok(b)) => {
                    loaded += 1;
                    assert!(a == b, "{} reads differently", p.display());
                }
                (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string(), "{}", p.display()),
                (a, b) => panic!("{}: {:?} against {:?}", p.display(), a.err(), b.err()),
            }
        }
        assert!(
            loaded >= 100 && quick >= 100_000,
            "{loaded} loaded, {quick} quick lines"
        );
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

    fn err(text: &str) -> String {
        load(text).unwrap_err().to_string()
    }

    const TRI: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";

    /// The one-pass tokenizer splits every line as "cut at the first `#`,
    /// then `split_whitespace`" does, ASCII or not.
    /// The fast paths read what std reads, bit for bit, or leave the
    /// token to it: a million tokens of signs, digits and points (and
    /// f32 values printed at every precision), and the odd forms.
    #[test]
    fn plain_numbers_read_as_std_reads_them() {
        let mut z = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            z ^= z << 13;
            z ^= z >> 7;
            z ^= z << 17;
            z
        };
        let alphabet = b"0123456789.-+e";
        let mut fast = 0;
        for k in 0..1_000_000u32 {
            let tok = if k % 2 == 0 {
                let len = 1 + (next() % 12) as usize;
                (0..len)
                    .map(|_| char::from(alphabet[(next() % 13) as usize]))
                    .collect::<String>()
            } else if k % 4 == 1 {
                // As `{}` prints an f32: the shortest digits that read back.
                let v = f32::from_bits((next() >> 32) as u32 & 0x4FFF_FFFF);
                format!("{v}")
            } else {
                let v = f32::from_bits((next() >> 32) as u32 & 0x4FFF_FFFF);
                let sign = if next() % 2 == 0 { "-" } else { "" };
                format!("{sign}{:.*}", (next() % 23) as usize, v.abs())
            };
            if let Some(v) = plain_decimal(&tok) {
                fast += 1;
                let want: f32 = tok.parse().expect("a plain decimal is a number");
                assert_eq!(v.to_bits(), want.to_bits(), "{tok}");
            }
            if let Some(i) = plain_integer(&tok) {
                assert_eq!(Ok(i), tok.parse::<i64>(), "{tok}");
            }
        }
        assert!(fast > 200_000, "{fast} tokens took the fast path");
        for tok in [
            "", "-", "+", ".", "-.", "1.2.3", "1e5", "nan", "inf", "0x10", " 1", "1 ",
        ] {
            assert_eq!(plain_decimal(tok), None, "{tok:?}");
        }
        for tok in [
            "-0",
            "-0.0",
            "+.5",
            "5.",
            "0.0000000001",
            "9999999",
            "0009999999",
            "0.031708304",
        ] {
            let want: f32 = tok.parse().unwrap();
            assert_eq!(
                plain_decimal(tok).map(f32::to_bits),
                Some(want.to_bits()),
                "{tok}"
            );
        }
        for tok in [
            "12345678901234567",
            "0.00000000000000000000001",
            "1e-50",
            "340282350000000000000000000000000000000",
        ] {
            assert_eq!(
                plain_decimal(tok),
                None,
                "{tok}: more than the fast path holds"
            );
        }
        // Halfway between two f32s (2²⁴ + 1 lies between 2²⁴ and 2²⁴ + 2,
        // exactly an f64): std rounds to even, the fast path leaves it.
        assert_eq!(plain_decimal("16777217"), None);
        assert_eq!(plain_decimal("16777219.0"), None);
        assert_eq!(plain_decimal("16777218"), Some(16_777_218.0));
        assert_eq!("16777217".parse::<f32>(), Ok(16_777_216.0));
        assert_eq!(plain_integer("-9223372036854775808"), None);
        assert_eq!(plain_integer("+12"), Some(12));
        assert_eq!(plain_integer("1_0"), None);
    }

    /// `first_line`, line after line, against `lines` then `tokenize`: the
    /// same lines, the same words, the same count.
    fn lines_then_tokens(text: &str) -> Vec<(String, Vec<String>)> {
        let mut toks = Vec::new();
        lines(text)
            .map(|l| {
                tokenize(l, &mut toks);
                (l.to_owned(), toks.iter().map(|t| (*t).to_owned()).collect())
            })
            .collect()
    }

    fn by_first_line(text: &str) -> Vec<(String, Vec<String>)> {
        let mut toks = Vec::new();
        let mut out = Vec::new();
        let mut rest = text;
        while !rest.is_empty() {
            let (line, after) = first_line(rest, &mut toks);
            out.push((
                line.to_owned(),
                toks.iter().map(|t| (*t).to_owned()).collect(),
            ));
            rest = after;
        }
        out
    }

    #[test]
    fn first_line_is_lines_then_tokenize() {
        let alphabet = [
            'a', '1', ' ', '\t', '\n', '\r', '#', '\u{b}', '\u{c}', '\u{85}', '\u{e9}', '\u{a0}',
            '/',
        ];
        let mut texts: Vec<String> = vec![
            "v 1 2 3\nf 1 2 3\r\nvt 0 0\rvn 0 0 1".into(),
            "# a comment\n\n\r\n\r\rv 1 2 3 # trailing\n".into(),
            "g caf\u{e9} n\u{e4}me\nv\u{a0}1\u{2003}2 3\n\u{85}v 1 2 3\u{85}".into(),
        ];
        // Every text of up to four characters over the alphabet.
        for len in 1..=4u32 {
            for mut k in 0..alphabet.len().pow(len) {
                let mut t = String::new();
                for _ in 0..len {
                    t.push(alphabet[k % alphabet.len()]);
                    k /= alphabet.len();
                }
                texts.push(t);
            }
        }
        // And longer ones, drawn.
        let mut seed = 0x853c_49e6_748f_ea9bu64;
        for _ in 0..20_000 {
            let mut t = String::new();
            for _ in 0..(seed >> 59) + 8 {
                seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
                t.push(alphabet[(seed >> 33) as usize % alphabet.len()]);
            }
            texts.push(t);
        }
        for t in &texts {
            assert_eq!(by_first_line(t), lines_then_tokens(t), "{t:?}");
        }
    }

    #[test]
    fn corner_parts_match_split() {
        let mut corners: Vec<String> = [
            "1", "1/2", "1/2/3", "1//3", "/", "//", "///", "1/2/3/4", "1/2/3/", "/2/3", "-1/-2/-3",
            "é/ü/ß", "1/é//", "",
        ]
        .iter()
        .map(|s| (*s).to_owned())
        .collect();
        // Every string of up to five characters over `1`, `/` and `x`.
        for len in 1..=5u32 {
            for mut k in 0..3usize.pow(len) {
                let mut c = String::new();
                for _ in 0..len {
                    c.push(['1', '/', 'x'][k % 3]);
                    k /= 3;
                }
                corners.push(c);
            }
        }
        for c in &corners {
            let mut parts = c.split('/');
            let want = (
                parts.next(),
                parts.next(),
                parts.next(),
                parts.next().is_some(),
            );
            assert_eq!(corner_parts(c), want, "{c:?}");
        }
    }

    #[test]
    fn tokenizer_matches_cut_then_split() {
        let lines = [
            "v 1 2 3",
            "  f 1/2/3\t4//5 6 ",
            "v 1#2 3",
            "#only a comment",
            "v 1 2 3 # trailing",
            "g caf\u{e9} n\u{e4}me # x",
            "v\u{a0}1\u{2003}2 3",
            "usemtl \u{fffd}\u{fffd}#\u{a0}x",
            "f 1 2 3\u{a0}#\u{a0}4",
            "\u{85}v 1 2 3\u{85}",
            "",
            "   ",
            "x\u{a0}",
        ];
        let mut got = Vec::new();
        for line in lines {
            tokenize(line, &mut got);
            let cut = line.find('#').map_or(line, |i| &line[..i]);
            let want: Vec<&str> = cut.split_whitespace().collect();
            assert_eq!(got, want, "{line:?}");
        }
    }

    #[test]
    fn comments_start_anywhere() {
        let m = load(&format!("{TRI}f 1 2 3#4\nv 9 9 9# a comment\n# f 1 2 4\n")).unwrap();
        assert_eq!(m.triangles.len(), 1);
        assert_eq!(m.triangles[0].v, [0, 1, 2]);
        let m = load(&format!("{TRI}f 1 2 3 # 4\n")).unwrap();
        assert_eq!(m.triangles.len(), 1);
    }

    #[test]
    fn line_endings_and_a_byte_order_mark() {
        let lf = load(&format!("{TRI}f 1 2 3\n")).unwrap();
        for text in [
            "v 0 0 0\r\nv 1 0 0\r\nv 0 1 0\r\nf 1 2 3\r\n",
            "v 0 0 0\rv 1 0 0\rv 0 1 0\rf 1 2 3\r",
            "v 0 0 0\rv 1 0 0\nv 0 1 0\r\nf 1 2 3",
            "\u{FEFF}v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        ] {
            assert_eq!(load(text).unwrap(), lf, "{text:?}");
        }
        // Lines are counted at every kind of break.
        let e = err("v 0 0 0\rv 1 0 0\r\nv 0 1 0\rf 1 2 4\n");
        assert!(e.starts_with("t.obj:4: vertex index 4"), "{e}");
        let e = err("\u{FEFF}v 0 0\n");
        assert!(e.starts_with("t.obj:1: `v` needs"), "{e}");
    }

    #[test]
    fn vertex_counts_and_weights() {
        // x y z w (w ignored, as Blender does) and x y z r g b.
        let m = load("v 0 0 0 2\nv 1 0 0 0.5\nv 0 1 0 0.1 0.2 0.3\nf 1 2 3\n").unwrap();
        assert_eq!(
            m.positions,
            [Vec3::ZERO, Vec3::X, Vec3::Y],
            "positions as written"
        );
        for n in [0, 1, 2, 5, 7] {
            let v = vec!["1"; n].join(" ");
            let e = err(&format!("{TRI}v {v}\n"));
            assert_eq!(
                e,
                format!(
                    "t.obj:4: `v` needs 3, 4 or 6 numbers (x y z, x y z w or x y z r g b), found {n}"
                )
            );
        }
        for w in ["0", "-1", "-0"] {
            let e = err(&format!("{TRI}v 1 2 3 {w}\n"));
            assert_eq!(
                e,
                format!(
                    "t.obj:4: the weight w = `{w}` of `v` must be > 0 (x y z w; w is otherwise ignored)"
                )
            );
        }
        let e = err("v 1 2 3 inf\n");
        assert_eq!(e, "t.obj:1: `inf` is not a finite number");
    }

    #[test]
    fn uv_and_normal_counts() {
        // `vt u` has v = 0; a third number is ignored.
        let m = load(&format!("{TRI}vt 0.5\nvt 0.25 0.75 1\nf 1/1 2/2 3/1\n")).unwrap();
        assert_eq!(m.uvs, [Vec2::new(0.5, 0.0), Vec2::new(0.25, 0.75)]);
        for n in [0, 4] {
            let e = err(&format!("vt {}\n", vec!["0"; n].join(" ")));
            assert_eq!(
                e,
                format!("t.obj:1: `vt` needs 1 to 3 numbers (u [v] [w]), found {n}")
            );
        }
        for n in [2, 4] {
            let e = err(&format!("vn {}\n", vec!["0"; n].join(" ")));
            assert_eq!(
                e,
                format!("t.obj:1: `vn` needs 3 numbers (x y z), found {n}")
            );
        }
    }

    #[test]
    fn statements_need_their_names() {
        let ok = format!(
            "mtllib a.mtl\no thing\ng left right\nusemtl red\ns off\ns 0\ns 1\nl 1 2\np 1\n{TRI}f 1 2 3\n"
        );
        assert_eq!(load(&ok).unwrap().triangles.len(), 1);
        for (line, message) in [
            ("o", "`o` needs an object name"),
            ("g", "`g` needs a group name"),
            ("mtllib # a.mtl", "`mtllib` needs a file name"),
            ("s", "`s` needs a smoothing group (a number, or `off`)"),
        ] {
            let e = err(&format!("{TRI}f 1 2 3\n{line}\n"));
            assert_eq!(e, format!("t.obj:5: {message}"));
        }
    }

    #[test]
    fn usemtl_and_mtllib_are_recorded_per_face() {
        let m = load(&format!(
            "mtllib my lib.mtl\n{TRI}f 1 2 3\nusemtl  red  paint \nf 1 2 3\nusemtl\nv 1 1 0\nf 1 2 4 3\nusemtl red  paint\nf 3 2 1\n"
        ))
        .unwrap();
        let named = |v: &[Named]| {
            v.iter()
                .map(|n| (n.name.clone(), n.line))
                .collect::<Vec<_>>()
        };
        assert_eq!(named(&m.mtllibs), [("my lib.mtl".to_string(), 1)]);
        // A name keeps its inner spaces; a bare `usemtl` names "" (Blender).
        assert_eq!(
            named(&m.usemtl),
            [("red  paint".to_string(), 6), (String::new(), 8)]
        );
        // Before any usemtl, then red paint, the quad's two triangles "",
        // red paint again.
        assert_eq!(m.tri_usemtl, [NO_USEMTL, 0, 1, 1, 0]);
        // Without usemtl nothing is stored per triangle.
        assert!(
            load(&format!("{TRI}f 1 2 3\n"))
                .unwrap()
                .tri_usemtl
                .is_empty()
        );
    }

    #[test]
    fn binary_garbage_is_quoted_briefly() {
        // 8 MB of NULs: one line, one token.
        let nuls = vec![0u8; 8 << 20];
        let e = load_obj_bytes(Path::new("t.obj"), &nuls)
            .unwrap_err()
            .to_string();
        assert!(e.len() < 400, "{} bytes: {e}", e.len());
        let quoted = "\\0".repeat(40);
        assert!(
            e.starts_with(&format!("t.obj:1: unsupported OBJ statement `{quoted}…`"))
                && e.ends_with("(the line is not text: is this an OBJ file?)"),
            "{e}"
        );
        // A number of a million digits (1e100).
        let e = err(&format!(
            "v 0 0 {}1{}\n",
            "0".repeat(1_000_000),
            "0".repeat(100)
        ));
        assert_eq!(
            e,
            format!(
                "t.obj:1: `{}…` is outside the f32 range (a magnitude above {:e})",
                "0".repeat(40),
                f32::MAX
            )
        );
        let e = err(&format!("{TRI}f 1 2 {}\n", "3/".repeat(100)));
        assert!(e.len() < 300, "{e}");
    }

    #[test]
    fn models_list_what_they_use_in_order_of_use() {
        // As tobj laid meshes out: each model (at `o`/`g`, once it has
        // faces) copies the positions, uvs and normals its faces use, in
        // the order they are first used; unused ones are left out.
        let m = load(
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 5 5 5\n\
             vt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\n\
             g a\nf 2/3 3/2 4/1\ng b\ng c\nf 1 2 3\nf 3/1/1 2/1/1 1/2/1\no d\n",
        )
        .unwrap();
        let p = |x: f32, y: f32| Vec3::new(x, y, 0.0);
        assert_eq!(
            m.positions,
            [
                p(1.0, 0.0),
                p(0.0, 1.0),
                p(1.0, 1.0),
                p(0.0, 0.0),
                p(1.0, 0.0),
                p(0.0, 1.0)
            ]
        );
        let tris: Vec<_> = m.triangles.iter().map(|t| (t.v, t.t, t.n)).collect();
        assert_eq!(
            tris,
            [
                ([0, 1, 2], Some([0, 1, 2]), None),
                ([3, 4, 5], None, None),
                ([5, 4, 3], Some([3, 3, 4]), Some([1, 1, 1])),
            ]
        );
        // Model a's uvs: vt 3, 2, 1. Model b+c's first corner has no uv:
        // the file's first uv stands in as its first one (tobj), then vt
        // 1 is that one, vt 2 a new one. Normals: model a's first corner
        // has none and the file has one by the model's end, so it stands
        // in there; model b+c's likewise, and `vn 1` is it.
        assert_eq!(
            m.uvs,
            [
                Vec2::new(0.0, 1.0),
                Vec2::new(1.0, 0.0),
                Vec2::new(0.0, 0.0),
                Vec2::new(0.0, 0.0),
                Vec2::new(1.0, 0.0),
            ]
        );
        assert_eq!(m.normals, [Vec3::Z, Vec3::Z]);
        assert_eq!(m.lines, [11, 14, 15]);
        assert_eq!(m.faces, 3);
    }

    #[test]
    fn a_face_of_100_000_corners_is_quick() {
        let n = 100_000;
        let mut text = String::new();
        for k in 0..n {
            let a = std::f64::consts::TAU * f64::from(k) / f64::from(n);
            let r = if k % 2 == 1 { 0.6 } else { 1.0 };
            text += &format!("v {} {} 0\n", r * a.cos(), r * a.sin());
        }
        text += "f";
        for k in 1..=n {
            text += &format!(" {k}");
        }
        text += "\n";
        let m = load(&text).unwrap();
        assert_eq!(m.triangles.len(), n as usize - 2);
    }

    #[test]
    fn the_budget_is_reserved_while_reading() {
        // 1 M faces would be 200 MB of triangles: refused at the line
        // reached, long before the end, with the figure.
        let mut text = String::from(TRI);
        text += &"f 1 2 3\n".repeat(1 << 20);
        let budget = Budget::new(16 << 20);
        let e = load_obj_within(Path::new("t.obj"), text.as_bytes(), &budget).unwrap_err();
        let LoadError::Mesh {
            line: Some(line),
            message,
            ..
        } = &e
        else {
            panic!("{e}")
        };
        assert!(*line < 100_000, "{e}");
        assert!(
            message.starts_with(&format!("the mesh up to line {line} (")),
            "{message}"
        );
        assert!(
            message.contains("triangles to be)")
                && message.contains("over the memory budget of 16.0 MiB"),
            "{message}"
        );
        assert_eq!(budget.used(), 0, "what was reserved is given back");
        // One face of many corners reserves at once, before it is
        // triangulated.
        let mut text = String::from(TRI);
        text += "f";
        text += &" 1 2 3".repeat(100_000);
        let budget = Budget::new(1 << 20);
        let e = load_obj_within(Path::new("t.obj"), text.as_bytes(), &budget)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("t.obj:4: the mesh up to line 4 ("), "{e}");
        // What fits: the mesh's arrays stay reserved, nothing else.
        let budget = Budget::new(1 << 20);
        let m = load_obj_within(
            Path::new("t.obj"),
            format!("{TRI}f 1 2 3\n").as_bytes(),
            &budget,
        )
        .unwrap();
        assert_eq!(budget.used(), mesh_bytes(&m));
    }
}
