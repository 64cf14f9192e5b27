//! OBJ material libraries (`.mtl`): a strict reader that names the line of
//! every problem, and the mapping of an MTL material onto the finish model
//! every backend shares (POV-Ray's, DESIGN.md §3).
//!
//! The mapping, with its reasons, is the table "OBJ materials" in
//! `ARCHITECTURE.md`; in short, with k = max(Kd):
//!
//! | MTL | finish |
//! |---|---|
//! | `Kd`, `map_Kd` | pigment Kd/k (× the texel), `diffuse` k |
//! | `Ka` | `ambient` = mean(Ka) (tinted by the pigment, as POV-Ray's is) |
//! | `Ks`, `Ns` (illum ≥ 2) | `specular` = mean(Ks), `roughness` = 1/max(Ns, 1) (Blinn's half vector, as MTL's) |
//! | `d`, `Tr` | `transmit` = 1 − d (Tr = 1 − d; `d` wins where both are given) |
//! | `Ni` (illum 6, 7, with d < 1) | `ior` |
//! | illum 0 | `emission` k, no ambient, diffuse or highlight (a constant Kd) |
//! | illum 3–7 | `reflection` = mean(Ks) (no Fresnel term) |
//! | `Ke` | `emission` += mean(Ke) |
//! | `bump`, `map_bump` | `bump` = { image, size = `-bm` (1), method = "blinn" } |
//!
//! Texture names are relative to the library's folder, with `\` read as a
//! separator (Windows exporters write `.\tex.jpg`); an absolute name or
//! one whose `..` climbs out of that folder is refused: an asset names the
//! files it ships with, never others on the machine.

use std::path::{Component, Path, PathBuf};
use std::sync::Arc;

use super::error::LoadError;
use super::obj::{lines, parse_f32, shown, tokenize};
use rendiff_core::color::Rgb;
use rendiff_core::shade::{Bump, BumpMethod, Material, Pigment};
use rendiff_core::texture::Texture;

/// A value with the line that stated it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stated<T> {
    /// The value.
    pub value: T,
    /// Its line in the library.
    pub line: u32,
}

/// A texture statement (`map_Kd`, `bump`): the file as written and its
/// `-bm` multiplier (1 unless given; bump maps only).
#[derive(Clone, Debug, PartialEq)]
pub struct TexStatement {
    /// The file name as written (relative to the library's folder).
    pub file: String,
    /// Its line.
    pub line: u32,
    /// `-bm`.
    pub bm: f32,
}

/// One `newmtl` of a library, as written.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MtlMaterial {
    /// The name (may be empty: Blender writes `newmtl` alone).
    pub name: String,
    /// The `newmtl` line.
    pub line: u32,
    /// `Ka`.
    pub ka: Option<Stated<[f32; 3]>>,
    /// `Kd`.
    pub kd: Option<Stated<[f32; 3]>>,
    /// `Ks`.
    pub ks: Option<Stated<[f32; 3]>>,
    /// `Ke`.
    pub ke: Option<Stated<[f32; 3]>>,
    /// `Ns`.
    pub ns: Option<Stated<f32>>,
    /// `d`.
    pub d: Option<Stated<f32>>,
    /// `Tr`.
    pub tr: Option<Stated<f32>>,
    /// `Ni`.
    pub ni: Option<Stated<f32>>,
    /// `illum`.
    pub illum: Option<Stated<u8>>,
    /// `map_Kd`.
    pub map_kd: Option<TexStatement>,
    /// `bump` / `map_bump`.
    pub bump: Option<TexStatement>,
}

/// A parsed library.
#[derive(Clone, Debug, PartialEq)]
pub struct MtlLibrary {
    /// The `.mtl` file.
    pub path: PathBuf,
    /// Its materials, in file order.
    pub materials: Vec<MtlMaterial>,
    /// Statements the finish model has no place for, accepted and not
    /// used (keyword and line), for a warning.
    pub ignored: Vec<Stated<String>>,
}

/// Statements of the MTL format (and its common extensions) that are
/// accepted and not used: maps of terms the finish has no texture for,
/// reflection maps, and the PBR extension's numbers.
const IGNORED: &[&str] = &[
    "Tf",
    "sharpness",
    "map_Ka",
    "map_Ks",
    "map_Ns",
    "map_d",
    "map_Tr",
    "map_Ke",
    "map_aat",
    "disp",
    "decal",
    "refl",
    "norm",
    "Pr",
    "Pm",
    "Ps",
    "Pc",
    "Pcr",
    "aniso",
    "anisor",
    "map_Pr",
    "map_Pm",
    "map_Ps",
];

fn line_err(path: &Path, line: usize, message: impl Into<String>) -> LoadError {
    LoadError::Mesh {
        path: path.to_path_buf(),
        line: Some(line),
        message: message.into(),
    }
}

/// The largest `-bm` accepted: the scene's bump size limit.
const MAX_BM: f32 = 1e6;

/// Reads a material library from its bytes (decoded lossily if not
/// UTF-8).
///
/// # Errors
///
/// [`LoadError::Mesh`] naming the library and the line of the first
/// problem: an unknown statement, a statement before `newmtl`, a name
/// defined twice, a wrong count of numbers, a number that is not finite or
/// outside its range (colours ≥ 0; `d`, `Tr` in [0, 1]; `Ns`, `Ni` ≥ 0;
/// `illum` an integer 0 … 10), a texture option rendiff does not model,
/// or a texture statement without a file.
pub fn parse(path: &Path, bytes: &[u8]) -> Result<MtlLibrary, LoadError> {
    let text = String::from_utf8_lossy(bytes);
    let text = text.strip_prefix('\u{FEFF}').unwrap_or(&text);
    let mut lib = MtlLibrary {
        path: path.to_path_buf(),
        materials: Vec::new(),
        ignored: Vec::new(),
    };
    let mut toks: Vec<&str> = Vec::new();
    for (k, raw) in lines(text).enumerate() {
        let line = k + 1;
        let content = raw.find('#').map_or(raw, |i| &raw[..i]);
        tokenize(content, &mut toks);
        let Some((&kw, args)) = toks.split_first() else {
            continue;
        };
        let err = |m: String| line_err(path, line, m);
        let line32 = u32::try_from(line).unwrap_or(u32::MAX);
        if kw == "newmtl" {
            let c = content.trim_start();
            let name = c.get(kw.len()..).unwrap_or("").trim().to_string();
            if let Some(other) = lib.materials.iter().find(|m| m.name == name) {
                return Err(err(format!(
                    "material `{}` is defined twice (first at line {})",
                    shown(&name),
                    other.line
                )));
            }
            lib.materials.push(MtlMaterial {
                name,
                line: line32,
                ..MtlMaterial::default()
            });
            continue;
        }
        let known = matches!(
            kw,
            "Ka" | "Kd"
                | "Ks"
                | "Ke"
                | "Ns"
                | "d"
                | "Tr"
                | "Ni"
                | "illum"
                | "map_Kd"
                | "bump"
                | "map_bump"
                | "map_Bump"
        ) || IGNORED.contains(&kw);
        if !known {
            let hint = if kw.contains('\u{FFFD}') || kw.chars().any(char::is_control) {
                " (the line is not text: is this an MTL file?)"
            } else {
                ""
            };
            return Err(err(format!(
                "unsupported MTL statement `{}`; expected newmtl, Ka, Kd, Ks, Ke, Ns, d, Tr, Ni, illum, map_Kd, bump or map_bump (or a statement rendiff ignores: {}){hint}",
                shown(kw),
                IGNORED.join(", ")
            )));
        }
        let Some(m) = lib.materials.last_mut() else {
            return Err(err(format!(
                "`{}` before any `newmtl`; every statement belongs to a material",
                shown(kw)
            )));
        };
        if IGNORED.contains(&kw) {
            lib.ignored.push(Stated {
                value: kw.to_string(),
                line: line32,
            });
            continue;
        }
        match kw {
            "Ka" | "Kd" | "Ks" | "Ke" => {
                let c = colour(kw, args).map_err(err)?;
                let s = Some(Stated {
                    value: c,
                    line: line32,
                });
                match kw {
                    "Ka" => m.ka = s,
                    "Kd" => m.kd = s,
                    "Ks" => m.ks = s,
                    _ => m.ke = s,
                }
            }
            "Ns" | "Ni" => {
                let v = one_number(kw, args).map_err(err)?;
                if v < 0.0 {
                    return Err(err(format!("`{kw}` must be ≥ 0, got `{}`", shown(args[0]))));
                }
                let s = Some(Stated {
                    value: v,
                    line: line32,
                });
                if kw == "Ns" {
                    m.ns = s;
                } else {
                    m.ni = s;
                }
            }
            "d" | "Tr" => {
                if args.first() == Some(&"-halo") {
                    return Err(err(
                        "`d -halo` (dissolve by viewing angle) is not modelled; write a plain `d`"
                            .into(),
                    ));
                }
                let v = one_number(kw, args).map_err(err)?;
                if !(0.0..=1.0).contains(&v) {
                    return Err(err(format!(
                        "`{kw}` must be within 0 … 1, got `{}`",
                        shown(args[0])
                    )));
                }
                let s = Some(Stated {
                    value: v,
                    line: line32,
                });
                if kw == "d" {
                    m.d = s;
                } else {
                    m.tr = s;
                }
            }
            "illum" => {
                let [a] = args else {
                    return Err(err(format!(
                        "`illum` needs 1 number (an illumination model 0 … 10), found {}",
                        args.len()
                    )));
                };
                let v = a.parse::<u8>().ok().filter(|v| *v <= 10).ok_or_else(|| {
                    err(format!(
                        "`illum` must be an integer 0 … 10, got `{}`",
                        shown(a)
                    ))
                })?;
                m.illum = Some(Stated {
                    value: v,
                    line: line32,
                });
            }
            _ => {
                let bump = kw != "map_Kd";
                let t = texture_statement(kw, args, bump, line32).map_err(err)?;
                if bump {
                    m.bump = Some(t);
                } else {
                    m.map_kd = Some(t);
                }
            }
        }
    }
    Ok(lib)
}

/// The numbers of `Ka`, `Kd`, `Ks`, `Ke`: one (grey) or three, each ≥ 0.
fn colour(kw: &str, args: &[&str]) -> Result<[f32; 3], String> {
    if let Some(&form @ ("spectral" | "xyz")) = args.first() {
        return Err(format!(
            "`{kw} {form}` colours are not modelled; write `{kw} r g b`"
        ));
    }
    if !(args.len() == 1 || args.len() == 3) {
        return Err(format!(
            "`{kw}` needs 1 or 3 numbers (r [g b]), found {}",
            args.len()
        ));
    }
    let mut c = [0.0; 3];
    for (k, a) in args.iter().enumerate() {
        let v = parse_f32(a)?;
        if v < 0.0 {
            return Err(format!(
                "`{kw}` needs colour channels ≥ 0, got `{}`",
                shown(a)
            ));
        }
        c[k] = v;
    }
    if args.len() == 1 {
        c = [c[0]; 3];
    }
    Ok(c)
}

fn one_number(kw: &str, args: &[&str]) -> Result<f32, String> {
    let [a] = args else {
        return Err(format!("`{kw}` needs 1 number, found {}", args.len()));
    };
    parse_f32(a)
}

/// The options of a texture statement and their file: the options rendiff
/// models take their default values (or `-bm` any bounded value on a
/// bump map, `-imfchan l` there); any other value is refused, naming it.
fn texture_statement(
    kw: &str,
    args: &[&str],
    bump: bool,
    line: u32,
) -> Result<TexStatement, String> {
    let mut bm = 1.0f32;
    let mut i = 0;
    let is_number = |s: &str| s.parse::<f64>().is_ok();
    while i < args.len() && args[i].starts_with('-') && !is_number(args[i]) {
        let opt = args[i];
        // The option's words, and the values that change nothing.
        let (count, defaults): (usize, &[&str]) = match opt {
            "-blendu" | "-blendv" => (1, &["on"]),
            "-clamp" | "-cc" => (1, &["off"]),
            "-boost" | "-texres" => (1, &[]),
            "-mm" => (2, &["0 1"]),
            "-o" | "-t" => (3, &["0", "0 0", "0 0 0"]),
            "-s" => (3, &["1", "1 1", "1 1 1"]),
            "-imfchan" => (1, if bump { &["l"] } else { &[] }),
            "-bm" if bump => (1, &[]),
            "-type" => (1, &[]),
            other => {
                return Err(format!("`{kw}`: unknown option `{}`", shown(other)));
            }
        };
        // -o, -s and -t take 1 to 3 numbers.
        let variable = matches!(opt, "-o" | "-s" | "-t");
        let mut values = Vec::new();
        while values.len() < count
            && i + 1 + values.len() < args.len()
            && (!variable || is_number(args[i + 1 + values.len()]))
        {
            values.push(args[i + 1 + values.len()]);
        }
        if values.is_empty() || (!variable && values.len() < count) {
            return Err(format!("`{kw}`: option `{opt}` needs {count} value(s)"));
        }
        let joined = values
            .iter()
            .map(|v| {
                v.parse::<f64>()
                    .map_or_else(|_| (*v).to_string(), |x| format!("{x}"))
            })
            .collect::<Vec<_>>()
            .join(" ");
        if opt == "-bm" {
            bm = parse_f32(values[0])?;
            if bm.abs() > MAX_BM {
                return Err(format!(
                    "`{kw}`: `-bm {}` is beyond ±{MAX_BM:e}",
                    shown(values[0])
                ));
            }
        } else if !defaults.contains(&joined.as_str()) {
            return Err(format!(
                "`{kw}`: option `{opt} {}` is not modelled by rendiff (only {}); remove it",
                shown(&values.join(" ")),
                if defaults.is_empty() {
                    "its absence".to_string()
                } else {
                    format!("`{opt} {}`", defaults[defaults.len() - 1])
                }
            ));
        }
        i += 1 + values.len();
    }
    let file = args[i..].join(" ");
    if file.is_empty() {
        return Err(format!("`{kw}` needs a file name"));
    }
    Ok(TexStatement { file, line, bm })
}

/// The file an asset names: `written` relative to the folder `base`, with
/// `\` read as a separator. Absolute names (`/x`, `\x`, `C:x`) and names
/// whose `..` climb out of `base` are refused (lexically: a link inside the
/// folder is the folder's business).
///
/// # Errors
///
/// What is wrong with the name.
pub fn asset_path(base: &Path, written: &str) -> Result<PathBuf, String> {
    let name = written.replace('\\', "/");
    let bytes = name.as_bytes();
    if name.starts_with('/')
        || (bytes.len() >= 2 && bytes[1] == b':' && bytes[0].is_ascii_alphabetic())
    {
        return Err(format!(
            "`{}` is an absolute name; an asset names files relative to its own folder",
            shown(written)
        ));
    }
    let mut out = PathBuf::new();
    let mut depth = 0usize;
    for c in Path::new(&name).components() {
        match c {
            Component::Normal(p) => {
                out.push(p);
                depth += 1;
            }
            Component::CurDir => {}
            Component::ParentDir => {
                if depth == 0 {
                    return Err(format!(
                        "`{}` climbs out of the folder {} with `..`; an asset names files inside its own folder",
                        shown(written),
                        base.display()
                    ));
                }
                out.pop();
                depth -= 1;
            }
            Component::RootDir | Component::Prefix(_) => {
                return Err(format!("`{}` is an absolute name", shown(written)));
            }
        }
    }
    if depth == 0 {
        return Err(format!("`{}` names no file", shown(written)));
    }
    Ok(base.join(out))
}

/// The channel mean of a colour.
fn mean(c: [f32; 3]) -> f32 {
    (c[0] + c[1] + c[2]) / 3.0
}

/// What the loader hands [`to_material`]: the library's textures, loaded.
#[derive(Clone, Debug, Default)]
pub struct Textures {
    /// The `map_Kd` image.
    pub map_kd: Option<Arc<Texture>>,
    /// The bump image.
    pub bump: Option<Arc<Texture>>,
}

/// Kd of a material as mapped: its given value, or 0.8 grey (the diffuse
/// grey Blender and assimp give a material without one).
const DEFAULT_KD: [f32; 3] = [0.8; 3];

/// The illumination model of a material without `illum`: 2 (highlights
/// on), what viewers that read Ks do.
const DEFAULT_ILLUM: u8 = 2;

/// Maps an MTL material onto the finish model (the table in the module
/// docs and in `ARCHITECTURE.md`). `name` is the material's name in the
/// scene; a `map_Kd` whose Kd is not grey is tinted by Kd/max(Kd)
/// ([`Texture::tinted`]), the tinted texels reserved in `budget`.
///
/// # Errors
///
/// [`LoadError::Mesh`] naming the library's line: a refracting material
/// (illum 6 or 7, d < 1, Ni ≠ 1) with `Ni` 0; `d < 1` with a `map_Kd`
/// that has an alpha channel (its alpha is the transmission already); or
/// the tinted texture not fitting the budget.
pub fn to_material(
    lib: &MtlLibrary,
    m: &MtlMaterial,
    name: String,
    tex: &Textures,
    budget: &rendiff_core::budget::Budget,
) -> Result<Material, LoadError> {
    let at = |line: u32, msg: String| line_err(&lib.path, line as usize, msg);
    let illum = m.illum.map_or(DEFAULT_ILLUM, |s| s.value);
    let kd = m.kd.map_or(DEFAULT_KD, |s| s.value);
    let k = kd[0].max(kd[1]).max(kd[2]);
    let tint = if k > 0.0 {
        Rgb::new(kd[0] / k, kd[1] / k, kd[2] / k)
    } else {
        Rgb::BLACK
    };
    let pigment = match &tex.map_kd {
        Some(t) if tint == Rgb::WHITE => Pigment::Image(t.clone()),
        Some(t) => {
            let bytes = u64::from(t.width()) * u64::from(t.height()) * Texture::BYTES_PER_TEXEL;
            budget
                .reserve(bytes, || {
                    format!("the {}x{} texture tinted by Kd", t.width(), t.height())
                })
                .map_err(|e| at(m.map_kd.as_ref().map_or(m.line, |s| s.line), e.to_string()))?;
            Pigment::Image(Arc::new(t.tinted(tint)))
        }
        None => Pigment::Color(tint),
    };
    let transmit = match (m.d, m.tr) {
        (Some(d), _) => 1.0 - d.value,
        (None, Some(tr)) => tr.value,
        (None, None) => 0.0,
    };
    if transmit > 0.0
        && let Some(t) = &tex.map_kd
        && t.has_alpha()
    {
        let line = m.d.or(m.tr).map_or(m.line, |s| s.line);
        return Err(at(
            line,
            format!(
                "material `{}`: its map_Kd has an alpha channel, which sets transmit = 1 − alpha itself; remove the dissolve (d/Tr) or the alpha channel",
                shown(&m.name)
            ),
        ));
    }
    let refracts = matches!(illum, 6 | 7) && transmit > 0.0;
    let ior = match m.ni {
        Some(ni) if refracts => {
            if ni.value <= 0.0 {
                return Err(at(
                    ni.line,
                    format!(
                        "material `{}` refracts (illum {illum} with d < 1) but Ni is {}; an index of refraction must be > 0",
                        shown(&m.name),
                        ni.value
                    ),
                ));
            }
            ni.value
        }
        _ => 1.0,
    };
    let ks = m.ks.map_or(0.0, |s| mean(s.value));
    let ke = m.ke.map_or(0.0, |s| mean(s.value));
    let lit = illum >= 1;
    let highlight = illum >= 2;
    let ray_traced = (3..=7).contains(&illum);
    let bump = match (&m.bump, &tex.bump) {
        (Some(s), Some(t)) => Some(Bump {
            texture: t.clone(),
            size: s.bm,
            method: BumpMethod::Blinn,
        }),
        _ => None,
    };
    Ok(Material {
        name,
        pigment,
        ambient: if lit {
            m.ka.map_or(0.0, |s| mean(s.value))
        } else {
            0.0
        },
        diffuse: if lit { k } else { 0.0 },
        brilliance: 1.0,
        phong: 0.0,
        phong_size: 40.0,
        specular: if highlight { ks } else { 0.0 },
        roughness: 1.0 / m.ns.map_or(1.0, |s| s.value).max(1.0),
        metallic: 0.0,
        reflection: if ray_traced { ks } else { 0.0 },
        filter: 0.0,
        transmit,
        ior,
        emission: if lit { ke } else { k + ke },
        bump,
    })
}

/// The material of faces that no `usemtl` names: the mapping of an MTL
/// material with no statements (Kd 0.8 grey, nothing else).
#[must_use]
pub fn default_material(name: String) -> Material {
    let lib = MtlLibrary {
        path: PathBuf::new(),
        materials: Vec::new(),
        ignored: Vec::new(),
    };
    to_material(
        &lib,
        &MtlMaterial::default(),
        name,
        &Textures::default(),
        &rendiff_core::budget::Budget::default(),
    )
    .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lib(text: &str) -> Result<MtlLibrary, LoadError> {
        parse(Path::new("t.mtl"), text.as_bytes())
    }

    fn err(text: &str) -> String {
        lib(text).unwrap_err().to_string()
    }

    fn mapped(text: &str) -> Material {
        let l = lib(text).unwrap();
        to_material(
            &l,
            &l.materials[0],
            "m".into(),
            &Textures::default(),
            &rendiff_core::budget::Budget::default(),
        )
        .unwrap()
    }

    #[test]
    fn the_spiders_library_parses() {
        let l = lib("#\n# spider.mtl\n#\n\nnewmtl Skin\nKa 0.200000 0.200000 0.200000\nKd 0.827451 0.792157 0.772549\nKs 0.000000 0.000000 0.000000\nNs 0.000000\nmap_Kd .\\wal67ar_small.jpg\n\nnewmtl Brusttex\nKd 0.8 0.8 0.8\n").unwrap();
        assert_eq!(l.materials.len(), 2);
        let skin = &l.materials[0];
        assert_eq!((skin.name.as_str(), skin.line), ("Skin", 5));
        assert_eq!(skin.map_kd.as_ref().unwrap().file, ".\\wal67ar_small.jpg");
        assert_eq!(skin.map_kd.as_ref().unwrap().line, 10);
        assert_eq!(l.materials[1].kd.unwrap().value, [0.8; 3]);
    }

    #[test]
    fn kd_ka_ks_ns_map_onto_the_finish() {
        // Grey Kd: pigment white, diffuse Kd; Ka's mean is the ambient,
        // Ks's the specular, 1/Ns the roughness (illum 2 by default).
        let m = mapped("newmtl a\nKa 0.2 0.2 0.2\nKd 0.5 0.5 0.5\nKs 0.3 0.3 0.3\nNs 50\n");
        assert_eq!(m.pigment, Pigment::Color(Rgb::WHITE));
        assert_eq!(m.diffuse, 0.5);
        assert!((m.ambient - 0.2).abs() < 1e-7);
        assert!((m.specular - 0.3).abs() < 1e-7);
        assert_eq!(m.roughness, 1.0 / 50.0);
        assert_eq!(
            (m.phong, m.reflection, m.transmit, m.ior),
            (0.0, 0.0, 0.0, 1.0)
        );
        // A coloured Kd: diffuse·pigment = Kd exactly, the pigment at most 1.
        let m = mapped("newmtl a\nKd 0.8 0.4 0.2\n");
        let Pigment::Color(p) = m.pigment else {
            panic!()
        };
        assert_eq!(m.diffuse, 0.8);
        assert_eq!(
            (p.r * m.diffuse, p.g * m.diffuse, p.b * m.diffuse),
            (0.8, 0.4, 0.2)
        );
        // Ns below 1 (and Ns 0, the spider's) is the broadest lobe, 1.
        assert_eq!(mapped("newmtl a\nNs 0\nKs 1 1 1\n").roughness, 1.0);
    }

    #[test]
    fn illumination_models() {
        // 0: a constant Kd (emission), no ambient, diffuse or highlight.
        let m = mapped("newmtl a\nillum 0\nKd 0.6 0.3 0.3\nKa 1 1 1\nKs 1 1 1\n");
        assert_eq!((m.ambient, m.diffuse, m.specular), (0.0, 0.0, 0.0));
        assert_eq!(m.emission, 0.6);
        // 1: no highlight even with Ks.
        let m = mapped("newmtl a\nillum 1\nKs 0.5 0.5 0.5\n");
        assert_eq!((m.specular, m.reflection), (0.0, 0.0));
        // 3: Ks also reflects; 8 (reflection maps) does not.
        let m = mapped("newmtl a\nillum 3\nKs 0.5 0.5 0.5\n");
        assert_eq!((m.specular, m.reflection), (0.5, 0.5));
        assert_eq!(
            mapped("newmtl a\nillum 8\nKs 0.5 0.5 0.5\n").reflection,
            0.0
        );
        // Dissolve is transmit for every model; Ni refracts only in 6 and 7.
        let m = mapped("newmtl a\nillum 4\nd 0.25\nNi 1.5\n");
        assert_eq!((m.transmit, m.ior), (0.75, 1.0));
        let m = mapped("newmtl a\nillum 7\nd 0.25\nNi 1.5\n");
        assert_eq!((m.transmit, m.ior), (0.75, 1.5));
        // Tr is 1 − d; d wins where both are given.
        assert_eq!(mapped("newmtl a\nTr 0.4\n").transmit, 0.4);
        assert_eq!(mapped("newmtl a\nTr 0.4\nd 1\n").transmit, 0.0);
        // Ke adds emission.
        assert_eq!(mapped("newmtl a\nKe 0.3 0.3 0.3\n").emission, 0.3);
    }

    #[test]
    fn a_material_without_statements_is_diffuse_grey() {
        let m = default_material("d".into());
        assert_eq!(m.pigment, Pigment::Color(Rgb::WHITE));
        assert_eq!((m.diffuse, m.ambient, m.specular), (0.8, 0.0, 0.0));
        let named = Material {
            name: "d".into(),
            ..mapped("newmtl a\n")
        };
        assert_eq!(m, named);
    }

    #[test]
    fn errors_name_the_line() {
        assert_eq!(
            err("newmtl a\nKd 0.5 zero 0.5\n"),
            "t.mtl:2: `zero` is not a number"
        );
        assert_eq!(
            err("newmtl a\nKd 0.5 0.5\n"),
            "t.mtl:2: `Kd` needs 1 or 3 numbers (r [g b]), found 2"
        );
        assert_eq!(
            err("newmtl a\nKd 0.5 -1 0.5\n"),
            "t.mtl:2: `Kd` needs colour channels ≥ 0, got `-1`"
        );
        assert_eq!(
            err("newmtl a\nd 1.5\n"),
            "t.mtl:2: `d` must be within 0 … 1, got `1.5`"
        );
        assert_eq!(
            err("newmtl a\nillum 11\n"),
            "t.mtl:2: `illum` must be an integer 0 … 10, got `11`"
        );
        assert_eq!(
            err("newmtl a\nNs inf\n"),
            "t.mtl:2: `inf` is not a finite number"
        );
        assert_eq!(
            err("Kd 1 1 1\n"),
            "t.mtl:1: `Kd` before any `newmtl`; every statement belongs to a material"
        );
        assert_eq!(
            err("newmtl a\n\nnewmtl a\n"),
            "t.mtl:3: material `a` is defined twice (first at line 1)"
        );
        assert!(err("newmtl a\nKq 1\n").starts_with("t.mtl:2: unsupported MTL statement `Kq`"));
        assert_eq!(
            err("newmtl a\nmap_Kd\n"),
            "t.mtl:2: `map_Kd` needs a file name"
        );
        assert_eq!(
            err("newmtl a\nmap_Kd -clamp on t.png\n"),
            "t.mtl:2: `map_Kd`: option `-clamp on` is not modelled by rendiff (only `-clamp off`); remove it"
        );
        assert_eq!(
            err("newmtl a\nmap_Kd -bm 2 t.png\n"),
            "t.mtl:2: `map_Kd`: unknown option `-bm`"
        );
        assert_eq!(
            err("newmtl a\nKd spectral x.rfl\n"),
            "t.mtl:2: `Kd spectral` colours are not modelled; write `Kd r g b`"
        );
        let e = err("\u{1}\u{2} 3\n");
        assert!(e.contains("is this an MTL file?"), "{e}");
    }

    #[test]
    fn texture_options_and_names() {
        let l = lib("newmtl a\nmap_Kd -s 1 1 1 -o 0 0 -blendu on my tex.png\nbump -bm 0.25 -imfchan l h.png\n").unwrap();
        let m = &l.materials[0];
        assert_eq!(m.map_kd.as_ref().unwrap().file, "my tex.png");
        assert_eq!(m.bump.as_ref().unwrap().bm, 0.25);
        assert_eq!(m.bump.as_ref().unwrap().file, "h.png");
        // Ignored statements are recorded with their lines.
        let l = lib("newmtl a\nTf 1 1 1\nmap_Ks s.png\n").unwrap();
        let ignored: Vec<_> = l
            .ignored
            .iter()
            .map(|s| (s.value.as_str(), s.line))
            .collect();
        assert_eq!(ignored, [("Tf", 2), ("map_Ks", 3)]);
    }

    #[test]
    fn asset_paths_stay_in_their_folder() {
        let base = Path::new("/m");
        assert_eq!(
            asset_path(base, ".\\t.jpg").unwrap(),
            PathBuf::from("/m/t.jpg")
        );
        assert_eq!(
            asset_path(base, "a/../t.jpg").unwrap(),
            PathBuf::from("/m/t.jpg")
        );
        assert_eq!(
            asset_path(base, "sub\\t.jpg").unwrap(),
            PathBuf::from("/m/sub/t.jpg")
        );
        for bad in [
            "../t.jpg",
            "a/../../t.jpg",
            "..\\t.jpg",
            "/etc/passwd",
            "C:\\t.jpg",
            "\\t.jpg",
            ".",
        ] {
            assert!(asset_path(base, bad).is_err(), "{bad}");
        }
        assert!(
            asset_path(base, "../t.jpg")
                .unwrap_err()
                .contains("climbs out of the folder /m")
        );
    }
}
