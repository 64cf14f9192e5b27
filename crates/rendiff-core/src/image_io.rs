//! Writing and reading images. Every file rendiff writes goes through
//! [`write_atomic`]: a regular file is written to an unpredictable
//! temporary name in its own folder (created exclusively, `O_EXCL`, by the
//! `tempfile` crate) and renamed over the target only when complete, so an
//! interrupted run never leaves a half-written file and a planted link at
//! a predictable name cannot redirect the write; what is not a regular
//! file is never renamed over (see [`write_atomic`]).

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::color::{Rgb, srgb8_table, to_linear16, to_srgb8};

/// Why an image could not be written or read.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ImageIoError {
    /// An I/O error on a path (its Display names the path; the I/O error
    /// is the source).
    #[error("{}", .path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        #[source]
        source: std::io::Error,
    },
    /// PNG encoding or decoding failed.
    #[error("{}: {message}", .path.display())]
    Png {
        /// The file.
        path: PathBuf,
        /// What failed.
        message: String,
    },
    /// The target of a write is something rendiff does not write over.
    #[error("{}: {message}", .path.display())]
    Refused {
        /// The target.
        path: PathBuf,
        /// Why.
        message: String,
    },
}

/// Where a write goes.
#[derive(Debug, PartialEq, Eq)]
pub(crate) enum OutputTarget {
    /// A regular file (or none yet) at this path: replaced atomically.
    File(PathBuf),
    /// A FIFO or a character device the user named (`/dev/null`,
    /// `/dev/stdout`, a pipe): written straight into, never replaced.
    Stream(PathBuf),
}

/// What writing to `path` means, or why rendiff will not write there.
///
/// * a regular file, or nothing yet: replaced (created) atomically;
/// * a symbolic link to a regular file: the link is followed, and the file
///   it points to is replaced atomically (the link stays a link);
/// * a FIFO or a character device, directly or through a link: written
///   straight into (renaming a file over `/dev/null` would replace the
///   device node);
/// * a link to nowhere, a folder, a block device or a socket: refused.
///
/// # Errors
///
/// [`ImageIoError::Refused`] or the I/O error of looking at it.
pub(crate) fn output_target(path: &Path) -> Result<OutputTarget, ImageIoError> {
    use std::os::unix::fs::FileTypeExt;
    let refused = |message: &str| ImageIoError::Refused {
        path: path.to_path_buf(),
        message: message.to_string(),
    };
    let io = |source| ImageIoError::Io {
        path: path.to_path_buf(),
        source,
    };
    let link = match std::fs::symlink_metadata(path) {
        Ok(m) => m.file_type().is_symlink(),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Ok(OutputTarget::File(path.to_path_buf()));
        }
        Err(e) => return Err(io(e)),
    };
    let m = match std::fs::metadata(path) {
        Ok(m) => m,
        Err(e) if link && e.kind() == std::io::ErrorKind::NotFound => {
            return Err(refused(
                "is a symbolic link to nothing; rendiff does not write through it",
            ));
        }
        Err(e) => return Err(io(e)),
    };
    let t = m.file_type();
    if t.is_fifo() || t.is_char_device() {
        return Ok(OutputTarget::Stream(path.to_path_buf()));
    }
    if t.is_dir() {
        return Err(refused("is a folder; expected a file name"));
    }
    if !t.is_file() {
        return Err(refused(
            "is not a regular file, a FIFO or a character device; rendiff does not write over it",
        ));
    }
    if link {
        return std::fs::canonicalize(path)
            .map(OutputTarget::File)
            .map_err(io);
    }
    Ok(OutputTarget::File(path.to_path_buf()))
}

/// Writes a file: `write` fills it, then it is put in place as
/// `output_target` says — for a regular file, a temporary file created
/// exclusively under an unpredictable name in the same folder, flushed,
/// synced and renamed over the target (registered for removal if the run
/// is interrupted before the rename); for a FIFO or a device, the stream
/// itself.
///
/// # Errors
///
/// [`ImageIoError`] (the temporary file is removed).
pub fn write_atomic<F>(path: &Path, write: F) -> Result<(), ImageIoError>
where
    F: FnOnce(&mut dyn Write) -> std::io::Result<()>,
{
    let io = |p: &Path, source| ImageIoError::Io {
        path: p.to_path_buf(),
        source,
    };
    let target = match output_target(path)? {
        OutputTarget::Stream(p) => {
            let f = std::fs::OpenOptions::new()
                .write(true)
                .open(&p)
                .map_err(|e| io(&p, e))?;
            let mut w = BufWriter::new(f);
            return write(&mut w)
                .and_then(|()| w.flush())
                .map_err(|e| io(&p, e));
        }
        OutputTarget::File(p) => p,
    };
    let dir = target
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = target
        .file_name()
        .map_or_else(|| "out".into(), |n| n.to_string_lossy().into_owned());
    let prefix = format!(".{name}.");
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(".tmp");
    // A new file gets rw-r--r--; a replaced one keeps its permissions.
    let perms = std::fs::metadata(&target).map_or_else(
        |_| std::os::unix::fs::PermissionsExt::from_mode(0o644),
        |m| m.permissions(),
    );
    builder.permissions(perms);
    let tmp = builder.tempfile_in(dir).map_err(|e| io(&target, e))?;
    let _guard = crate::cleanup::TempGuard::new(tmp.path());
    let result = (|| {
        let mut w = BufWriter::new(tmp.as_file());
        write(&mut w)?;
        w.flush()?;
        drop(w);
        tmp.as_file().sync_all()?;
        pause_before_rename();
        Ok(())
    })();
    result.map_err(|e| io(&target, e))?;
    tmp.persist(&target).map_err(|e| io(&target, e.error))?;
    Ok(())
}

/// The test hook of the kill test (`tests/it/atomic.rs`; feature
/// `testing`, so a release binary reads no such variable): with
/// `RENDIFF_TEST_PAUSE_BEFORE_RENAME_MS` set, every atomic write waits that
/// long between finishing its temporary file and renaming it, so a SIGKILL
/// can be landed there deterministically.
fn pause_before_rename() {
    #[cfg(feature = "testing")]
    {
        static PAUSE: std::sync::OnceLock<Option<u64>> = std::sync::OnceLock::new();
        let pause = PAUSE.get_or_init(|| {
            std::env::var("RENDIFF_TEST_PAUSE_BEFORE_RENAME_MS")
                .ok()
                .and_then(|v| v.parse().ok())
        });
        if let Some(ms) = pause {
            std::thread::sleep(std::time::Duration::from_millis(*ms));
        }
    }
}

/// How a colour image is encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PngEncoding {
    /// 8-bit sRGB (with an sRGB chunk).
    Srgb8,
    /// 16-bit linear with a gAMA chunk of 1.0.
    Linear16,
}

fn png_err(path: &Path, e: impl std::fmt::Display) -> ImageIoError {
    ImageIoError::Png {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// Encodes linear colours (row-major from the top) as PNG bytes.
///
/// # Errors
///
/// [`ImageIoError::Png`] if the encoder fails.
pub fn encode_png(
    width: u32,
    height: u32,
    pixels: &[Rgb],
    encoding: PngEncoding,
) -> Result<Vec<u8>, ImageIoError> {
    let mut out = Vec::new();
    let p = Path::new("<memory>");
    {
        let mut enc = png::Encoder::new(&mut out, width, height);
        enc.set_compression(PIXEL_COMPRESSION);
        enc.set_color(png::ColorType::Rgb);
        let data: Vec<u8> = match encoding {
            PngEncoding::Srgb8 => {
                enc.set_depth(png::BitDepth::Eight);
                enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
                pixels
                    .iter()
                    .flat_map(|c| [to_srgb8(c.r), to_srgb8(c.g), to_srgb8(c.b)])
                    .collect()
            }
            PngEncoding::Linear16 => {
                enc.set_depth(png::BitDepth::Sixteen);
                enc.set_source_gamma(png::ScaledFloat::new(1.0));
                pixels
                    .iter()
                    .flat_map(|c| [to_linear16(c.r), to_linear16(c.g), to_linear16(c.b)])
                    .flat_map(u16::to_be_bytes)
                    .collect()
            }
        };
        let mut w = enc.write_header().map_err(|e| png_err(p, e))?;
        w.write_image_data(&data).map_err(|e| png_err(p, e))?;
    }
    Ok(out)
}

/// The compression of the images rendiff renders and draws (frames,
/// references, maps): `fdeflate`'s fast mode. The default (`Balanced`,
/// zlib level 6) spent 32 M instructions deflating a 320×240 frame, 6 %
/// of a whole `rendiff render` of `scenes/dense.toml`, for files
/// 10–20 % smaller (`scenes/dense.toml` 22 435 against 24 635 bytes).
const PIXEL_COMPRESSION: png::Compression = png::Compression::Fast;

/// Writes a colour image.
///
/// # Errors
///
/// [`ImageIoError`] on encoding or I/O failure.
pub fn write_png(
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[Rgb],
    encoding: PngEncoding,
) -> Result<(), ImageIoError> {
    let bytes = encode_png(width, height, pixels, encoding).map_err(|e| match e {
        ImageIoError::Png { message, .. } => png_err(path, message),
        other => other,
    })?;
    write_atomic(path, |w| w.write_all(&bytes))
}

/// Writes 16-bit RGB (or RGBA, with `alpha`) samples, row-major from the
/// top, with a gAMA chunk of 1.0: texels as rendiff reads them, for
/// POV-Ray's `image_map { png … gamma 1.0 }`.
///
/// # Errors
///
/// [`ImageIoError`] on encoding or I/O failure.
pub fn write_png16(
    path: &Path,
    width: u32,
    height: u32,
    alpha: bool,
    samples: &[u16],
) -> Result<(), ImageIoError> {
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, width, height);
        enc.set_color(if alpha {
            png::ColorType::Rgba
        } else {
            png::ColorType::Rgb
        });
        enc.set_depth(png::BitDepth::Sixteen);
        enc.set_source_gamma(png::ScaledFloat::new(1.0));
        let data: Vec<u8> = samples.iter().flat_map(|v| v.to_be_bytes()).collect();
        let mut w = enc.write_header().map_err(|e| png_err(path, e))?;
        w.write_image_data(&data).map_err(|e| png_err(path, e))?;
    }
    write_atomic(path, |w| w.write_all(&out))
}

/// Writes RGBA8 pixels given as little-endian u32 words (R the low byte).
///
/// # Errors
///
/// [`ImageIoError`] on encoding or I/O failure.
pub fn write_png_u32(
    path: &Path,
    width: u32,
    height: u32,
    words: &[u32],
) -> Result<(), ImageIoError> {
    let data: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
    write_png_rgba8(path, width, height, &data)
}

/// Writes RGBA8 pixels.
///
/// # Errors
///
/// [`ImageIoError`] on encoding or I/O failure.
pub fn write_png_rgba8(
    path: &Path,
    width: u32,
    height: u32,
    rgba: &[u8],
) -> Result<(), ImageIoError> {
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, width, height);
        enc.set_compression(PIXEL_COMPRESSION);
        enc.set_color(png::ColorType::Rgba);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header().map_err(|e| png_err(path, e))?;
        w.write_image_data(rgba).map_err(|e| png_err(path, e))?;
    }
    write_atomic(path, |w| w.write_all(&out))
}

/// Writes a single-channel float image as PFM (grey, little-endian, rows
/// bottom to top as the format requires).
///
/// # Errors
///
/// [`ImageIoError::Io`].
pub fn write_pfm(path: &Path, width: u32, height: u32, values: &[f32]) -> Result<(), ImageIoError> {
    write_atomic(path, |w| {
        write!(w, "Pf\n{width} {height}\n-1.0\n")?;
        for row in (0..height as usize).rev() {
            let start = row * width as usize;
            for v in &values[start..start + width as usize] {
                w.write_all(&v.to_le_bytes())?;
            }
        }
        Ok(())
    })
}

/// A decoded image in linear floats.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearImage {
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// Pixels, row-major from the top.
    pub pixels: Vec<Rgb>,
    /// `true` when the file was 16-bit with gAMA 1.0 (read as linear).
    pub linear16: bool,
}

/// Reads a PNG as linear colour: 16-bit with a gAMA chunk of 1.0 is
/// linear (`v/65535`), anything else is sRGB (DESIGN.md §5).
///
/// # Errors
///
/// [`ImageIoError`] when the file is unreadable or not a PNG.
pub fn read_png_linear(path: &Path) -> Result<LinearImage, ImageIoError> {
    read_png_linear_within(path, None, &crate::budget::Budget::default())
}

/// Bytes a decoded image holds per pixel beside its decode buffer (the
/// linear colour, three f32).
const LINEAR_BYTES_PER_PIXEL: u64 = 12;

/// Reads a PNG as [`read_png_linear`] does, checking its header before
/// anything is decoded: its size must be `expect` when given (an image
/// that claims 60000×60000 against a 320×240 scene is refused from its 33
/// header bytes), and its decoded size must fit `budget` (reserved while
/// decoding, released after: the caller keeps the result).
///
/// # Errors
///
/// [`ImageIoError`] when the file is unreadable, not a PNG, of another size
/// than expected, or too large for the budget.
pub fn read_png_linear_within(
    path: &Path,
    expect: Option<(u32, u32)>,
    budget: &crate::budget::Budget,
) -> Result<LinearImage, ImageIoError> {
    let size = crate::input::regular_file_size(path).map_err(|source| ImageIoError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    budget
        .reserve(size, || {
            format!("reading the {} image", crate::budget::human(size))
        })
        .map_err(|e| png_err(path, e))?;
    let result = crate::input::read_file(path)
        .map_err(|source| ImageIoError::Io {
            path: path.to_path_buf(),
            source,
        })
        .and_then(|bytes| decode_png_linear_within(path, &bytes, expect, budget));
    budget.release(size);
    result
}

/// Decodes PNG bytes to linear colour with the header checks of
/// [`read_png_linear_within`]; the decoder's own allocations (its chunks,
/// an ICC profile it inflates) are capped at what the budget has left.
///
/// # Errors
///
/// As [`read_png_linear_within`].
pub(crate) fn decode_png_linear_within(
    path: &Path,
    bytes: &[u8],
    expect: Option<(u32, u32)>,
    budget: &crate::budget::Budget,
) -> Result<LinearImage, ImageIoError> {
    let reader = png_reader(bytes, budget).map_err(|e| png_err(path, e))?;
    let info = reader.info();
    let (w, h) = (info.width, info.height);
    if let Some((ew, eh)) = expect
        && (w, h) != (ew, eh)
    {
        return Err(png_err(
            path,
            format!("the image is {w}x{h} but the scene renders {ew}x{eh} (use --size)"),
        ));
    }
    let decoded = reader
        .output_buffer_size()
        .ok_or_else(|| png_err(path, "image too large"))? as u64;
    let need = decoded + u64::from(w) * u64::from(h) * LINEAR_BYTES_PER_PIXEL;
    budget
        .reserve(need, || format!("decoding the {w}x{h} image"))
        .map_err(|e| png_err(path, e))?;
    let result = decode_frame(path, reader);
    budget.release(decoded);
    if result.is_err() {
        budget.release(need - decoded);
    }
    result
}

/// A PNG reader past the header, expanding every colour type to 8 or 16
/// bits per sample (palettes looked up, `tRNS` as alpha), its allocations
/// capped at what `budget` has left, and the chunks rendiff never uses
/// (ICC profiles, text) skipped rather than inflated: a 4 MB `iCCP` chunk
/// that inflates to 4 GiB costs nothing.
///
/// # Errors
///
/// The decoder's error for bytes that are not a PNG or a header over the
/// limits.
pub(crate) fn png_reader<'a>(
    bytes: &'a [u8],
    budget: &crate::budget::Budget,
) -> Result<png::Reader<std::io::Cursor<&'a [u8]>>, png::DecodingError> {
    let limits = png::Limits {
        bytes: usize::try_from(budget.remaining()).unwrap_or(usize::MAX),
    };
    let mut dec = png::Decoder::new_with_limits(std::io::Cursor::new(bytes), limits);
    dec.set_transformations(png::Transformations::EXPAND);
    dec.set_ignore_iccp_chunk(true);
    dec.set_ignore_text_chunk(true);
    dec.read_info()
}

fn decode_frame(
    path: &Path,
    mut reader: png::Reader<std::io::Cursor<&[u8]>>,
) -> Result<LinearImage, ImageIoError> {
    let info = reader.info();
    let gamma_one = info
        .gama_chunk
        .or(info.source_gamma)
        .is_some_and(|g| (g.into_value() - 1.0).abs() < 1e-4);
    let mut buf = vec![
        0u8;
        reader
            .output_buffer_size()
            .ok_or_else(|| png_err(path, "image too large"))?
    ];
    let frame = reader.next_frame(&mut buf).map_err(|e| png_err(path, e))?;
    let (w, h) = (frame.width, frame.height);
    let channels = frame.color_type.samples();
    let sixteen = frame.bit_depth == png::BitDepth::Sixteen;
    let linear16 = sixteen && gamma_one;
    let table = srgb8_table();
    let n = (w as usize) * (h as usize);
    let mut pixels = Vec::with_capacity(n);
    let sample = |i: usize| -> f32 {
        if sixteen {
            let v = u16::from_be_bytes([buf[2 * i], buf[2 * i + 1]]);
            let x = f32::from(v) / 65535.0;
            if linear16 {
                x
            } else {
                crate::color::srgb_decode(x)
            }
        } else {
            table[usize::from(buf[i])]
        }
    };
    for p in 0..n {
        let base = p * channels;
        let c = match channels {
            1 | 2 => {
                let v = sample(base);
                Rgb::splat(v)
            }
            _ => Rgb::new(sample(base), sample(base + 1), sample(base + 2)),
        };
        pixels.push(c);
    }
    Ok(LinearImage {
        width: w,
        height: h,
        pixels,
        linear16,
    })
}

/// Reads a file whole after checking that it is a regular file and that
/// its size fits `budget` (reserved: the caller releases `size` bytes).
fn read_budgeted(path: &Path, budget: &crate::budget::Budget) -> Result<Vec<u8>, ImageIoError> {
    let size = crate::input::regular_file_size(path).map_err(|source| ImageIoError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    budget
        .reserve(size, || {
            format!("reading the {} file", crate::budget::human(size))
        })
        .map_err(|e| png_err(path, e))?;
    let bytes = crate::input::read_file(path).map_err(|source| ImageIoError::Io {
        path: path.to_path_buf(),
        source,
    });
    budget.release(size);
    bytes
}

/// Reads an id image as the frame's `write_gbuffer` writes it:
/// an RGBA8 PNG whose four bytes per pixel are a little-endian `u32`
/// (triangle id + 1; 0 for the background). The size must be `expect`.
///
/// # Errors
///
/// [`ImageIoError`] when the file is unreadable, not an 8-bit RGBA PNG,
/// of another size, or too large for the budget.
pub fn read_png_u32_within(
    path: &Path,
    expect: (u32, u32),
    budget: &crate::budget::Budget,
) -> Result<Vec<u32>, ImageIoError> {
    let bytes = read_budgeted(path, budget)?;
    let mut reader = png_reader(&bytes, budget).map_err(|e| png_err(path, e))?;
    let info = reader.info();
    let (w, h) = (info.width, info.height);
    if (w, h) != expect {
        return Err(png_err(
            path,
            format!(
                "the id image is {w}x{h} but the sample grid is {}x{}",
                expect.0, expect.1
            ),
        ));
    }
    if info.color_type != png::ColorType::Rgba || info.bit_depth != png::BitDepth::Eight {
        return Err(png_err(
            path,
            "expected an 8-bit RGBA PNG (a little-endian u32 per pixel: triangle id + 1, 0 for none)",
        ));
    }
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| png_err(path, "image too large"))?;
    let need = u64::try_from(size).unwrap_or(u64::MAX);
    budget
        .reserve(need, || format!("decoding the {w}x{h} id image"))
        .map_err(|e| png_err(path, e))?;
    let mut buf = vec![0u8; size];
    let result = reader.next_frame(&mut buf).map_err(|e| png_err(path, e));
    budget.release(need);
    result?;
    Ok(buf
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect())
}

/// Reads a single-channel PFM (`Pf`, either byte order, rows bottom to
/// top) as the frame's `write_gbuffer` writes `depth.pfm`; rows are
/// returned top to bottom. The size must be `expect`.
///
/// # Errors
///
/// [`ImageIoError`] naming the file when it is unreadable, not a grey
/// PFM, of another size, short, or too large for the budget.
pub fn read_pfm_within(
    path: &Path,
    expect: (u32, u32),
    budget: &crate::budget::Budget,
) -> Result<Vec<f32>, ImageIoError> {
    let (_, _, channels, values) = read_pfm(path, Some(expect), budget)?;
    if channels != 1 {
        return Err(ImageIoError::Png {
            path: path.to_path_buf(),
            message: "expected a grey PFM (\"Pf\"), got a colour one (\"PF\")".into(),
        });
    }
    Ok(values)
}

/// Reads a PFM image (`PF` colour or `Pf` grey, either byte order) as
/// linear colour, rows top to bottom; `expect` the size when given. Values
/// are kept as stored (a float image is not rounded, nor clamped).
///
/// # Errors
///
/// As [`read_pfm_within`].
pub fn read_pfm_linear_within(
    path: &Path,
    expect: Option<(u32, u32)>,
    budget: &crate::budget::Budget,
) -> Result<LinearImage, ImageIoError> {
    let (width, height, channels, values) = read_pfm(path, expect, budget)?;
    if width == 0 || height == 0 {
        return Err(ImageIoError::Png {
            path: path.to_path_buf(),
            message: format!("the image is {width}x{height}: it has no pixels"),
        });
    }
    if let Some(k) = values.iter().position(|v| !v.is_finite()) {
        let px = k / channels;
        return Err(ImageIoError::Png {
            path: path.to_path_buf(),
            message: format!(
                "pixel ({}, {}) holds {}: a colour must be finite",
                px % width as usize,
                px / width as usize,
                values[k]
            ),
        });
    }
    let pixels = values
        .chunks_exact(channels)
        .map(|c| match c {
            [g] => Rgb::new(*g, *g, *g),
            [r, g, b] => Rgb::new(*r, *g, *b),
            _ => Rgb::BLACK,
        })
        .collect();
    Ok(LinearImage {
        width,
        height,
        pixels,
        linear16: false,
    })
}

/// A PFM's size, channels (1 or 3) and values, rows top to bottom.
fn read_pfm(
    path: &Path,
    expect: Option<(u32, u32)>,
    budget: &crate::budget::Budget,
) -> Result<(u32, u32, usize, Vec<f32>), ImageIoError> {
    let bad = |why: String| ImageIoError::Png {
        path: path.to_path_buf(),
        message: why,
    };
    let bytes = read_budgeted(path, budget)?;
    // The header: three whitespace-separated tokens after "Pf"/"PF", then
    // one whitespace byte before the data.
    let mut tokens = Vec::new();
    let mut i = 0;
    while tokens.len() < 4 && i < bytes.len().min(256) {
        while i < bytes.len() && bytes[i].is_ascii_whitespace() {
            i += 1;
        }
        let start = i;
        while i < bytes.len() && !bytes[i].is_ascii_whitespace() {
            i += 1;
        }
        tokens.push(String::from_utf8_lossy(&bytes[start..i]).into_owned());
    }
    i += 1;
    let channels = match tokens.first().map(String::as_str) {
        Some("Pf") if tokens.len() == 4 => 1usize,
        Some("PF") if tokens.len() == 4 => 3,
        _ => {
            return Err(bad(
                "expected a PFM (\"Pf\" or \"PF\", width, height, scale)".into(),
            ));
        }
    };
    let parse = |t: &str| {
        t.parse::<u32>()
            .map_err(|_| bad(format!("expected a size, got \"{t}\"")))
    };
    let (w, h) = (parse(&tokens[1])?, parse(&tokens[2])?);
    // The scale's sign is the byte order (negative: little-endian); zero
    // or a non-finite scale says neither.
    let scale: f32 = tokens[3]
        .parse()
        .ok()
        .filter(|s: &f32| *s != 0.0 && s.is_finite())
        .ok_or_else(|| {
            bad(format!(
                "expected the scale, a nonzero finite number whose sign is the byte order (negative: little-endian), got \"{}\"",
                tokens[3]
            ))
        })?;
    if let Some((ew, eh)) = expect
        && (w, h) != (ew, eh)
    {
        return Err(bad(format!(
            "the image is {w}x{h} but {ew}x{eh} is expected (the sample grid, or the other image)"
        )));
    }
    let n = (w as usize) * (h as usize);
    let need = u64::try_from(4 * n * channels).unwrap_or(u64::MAX);
    budget
        .reserve(need, || format!("decoding the {w}x{h} PFM"))
        .map_err(|e| bad(e.to_string()))?;
    budget.release(need);
    let data = bytes.get(i..).unwrap_or_default();
    if data.len() < 4 * n * channels {
        return Err(bad(format!(
            "the data holds {} bytes, {w}x{h}x{channels} floats need {}",
            data.len(),
            4 * n * channels
        )));
    }
    let little = scale < 0.0;
    let mut out = vec![0.0f32; n * channels];
    let row = (w as usize) * channels;
    for (k, c) in data.chunks_exact(4).take(n * channels).enumerate() {
        let b = [c[0], c[1], c[2], c[3]];
        let v = if little {
            f32::from_le_bytes(b)
        } else {
            f32::from_be_bytes(b)
        };
        let (y, x) = (k / row, k % row);
        out[(h as usize - 1 - y) * row + x] = v;
    }
    Ok((w, h, channels, out))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear16_round_trips_and_is_recognised() {
        let dir = std::env::temp_dir().join(format!("rendiff-io-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let px = vec![Rgb::new(0.0, 0.5, 1.0), Rgb::new(0.25, 0.125, 0.75)];
        let p16 = dir.join("a.png");
        write_png(&p16, 2, 1, &px, PngEncoding::Linear16).unwrap();
        let img = read_png_linear(&p16).unwrap();
        assert!(img.linear16);
        for (a, b) in img.pixels.iter().zip(&px) {
            assert!(a.max_abs_diff(*b) <= 0.5 / 65535.0 + 1e-7);
        }
        let p8 = dir.join("b.png");
        write_png(&p8, 2, 1, &px, PngEncoding::Srgb8).unwrap();
        let img = read_png_linear(&p8).unwrap();
        assert!(!img.linear16);
        // 8-bit sRGB: the round trip is within half a code, ≤ 1/255 × slope.
        for (a, b) in img.pixels.iter().zip(&px) {
            assert!(a.max_abs_diff(*b) < 0.01, "{a:?} {b:?}");
        }
        // No temporary files are left behind.
        let leftovers: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .filter_map(Result::ok)
            .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
            .collect();
        assert!(leftovers.is_empty());
        std::fs::remove_dir_all(&dir).ok();
    }
}
