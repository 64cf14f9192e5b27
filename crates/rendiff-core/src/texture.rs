//! Image textures: decoding PNG and JPEG bytes into linear texels, and the
//! bilinear lookup of DESIGN.md §3 / POVRAY.md §6 (texel centres at
//! `(k + 0.5)/w`, uv (0, 0) at the image's bottom-left corner, repeat
//! outside [0, 1)).
//!
//! Texels are read as *linear* values (`v/255` or `v/65535`), never
//! sRGB-decoded: POV-Ray with `gamma 1.0` does the same, so a texture means
//! the same number to every renderer. The format is told by the file's
//! first bytes (the PNG signature, JPEG's start-of-image marker), never by
//! its name. JPEG is decoded by `zune-jpeg` (the decoder behind the image
//! crate's `jpeg` feature) without its SIMD paths and in strict mode, so
//! every machine gets the same texels and a truncated or corrupt file is
//! an error, not a grey patch.

use std::path::{Path, PathBuf};

use crate::color::Rgb;
use crate::math::Vec2;

/// A decoded texture.
///
/// # Guarantees
///
/// `1 ≤ width, height ≤ 16384`; `texels.len() == width·height`; every texel
/// channel is finite and in `[0, 1]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    path: PathBuf,
    width: u32,
    height: u32,
    /// Row-major from the top row, RGBA (alpha 1 where the file has none).
    texels: Vec<[f32; 4]>,
    has_alpha: bool,
    grey: bool,
    bit_depth: u8,
    format: ImageFormat,
    tint: Option<Rgb>,
}

/// The file format a texture was decoded from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFormat {
    /// PNG (8 or 16 bits, any colour type).
    Png,
    /// JPEG (baseline or progressive, 8 bits; grey, YCbCr, CMYK).
    Jpeg,
    /// Made in memory ([`Texture::from_texels`]).
    Texels,
}

/// The PNG signature.
const PNG_SIGNATURE: &[u8] = b"\x89PNG\r\n\x1a\n";

/// JPEG's start-of-image marker and the first byte of the next marker.
const JPEG_SOI: &[u8] = &[0xFF, 0xD8, 0xFF];

/// A texel sample: colour and alpha (alpha is 1 for opaque images).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TexSample {
    /// Colour (linear).
    pub rgb: Rgb,
    /// Alpha in `[0, 1]`.
    pub alpha: f32,
}

/// Why a texture could not be decoded.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct TextureError {
    /// What was wrong.
    pub message: String,
}

impl Texture {
    /// Largest accepted side in texels.
    pub const MAX_SIDE: u32 = crate::options::MAX_SIDE;

    /// Decodes PNG or JPEG bytes (told apart by their first bytes) within
    /// `budget`, as [`Texture::from_png_bytes_within`] and
    /// [`Texture::from_jpeg_bytes_within`] do.
    ///
    /// # Errors
    ///
    /// [`TextureError`] when the bytes are neither, or as those functions.
    pub fn from_bytes_within(
        path: &Path,
        bytes: &[u8],
        budget: &crate::budget::Budget,
    ) -> Result<Texture, TextureError> {
        if bytes.starts_with(JPEG_SOI) {
            Texture::from_jpeg_bytes_within(path, bytes, budget)
        } else if bytes.starts_with(PNG_SIGNATURE) || !bytes.starts_with(&JPEG_SOI[..2]) {
            // Anything that is not a JPEG is reported as PNG's decoder
            // sees it (the message names what was expected).
            Texture::from_png_bytes_within(path, bytes, budget).map_err(|e| {
                if bytes.starts_with(PNG_SIGNATURE) {
                    e
                } else {
                    TextureError {
                        message: "not a PNG or JPEG image: it starts with neither signature".into(),
                    }
                }
            })
        } else {
            Err(TextureError {
                message: "not a readable JPEG: the file ends after its start-of-image marker"
                    .into(),
            })
        }
    }

    /// [`Texture::from_bytes_within`] within the default memory budget.
    ///
    /// # Errors
    ///
    /// As [`Texture::from_bytes_within`].
    pub fn from_bytes(path: &Path, bytes: &[u8]) -> Result<Texture, TextureError> {
        Texture::from_bytes_within(path, bytes, &crate::budget::Budget::default())
    }

    /// Bytes the JPEG decoder holds per pixel while it decodes, at most:
    /// its RGB output (3 B) and, for a progressive file, the i16
    /// coefficients of three components (6 B).
    const JPEG_DECODE_BYTES_PER_PIXEL: u64 = 9;

    /// Decodes JPEG bytes: the header's size is checked against
    /// [`Texture::MAX_SIDE`] and the texels reserved in `budget` before
    /// anything is decoded (the decoder's own buffers are checked against
    /// what is left), then the image is decoded in strict mode to RGB and
    /// each sample divided by 255. JPEG has no alpha.
    ///
    /// # Errors
    ///
    /// [`TextureError`] for a file the decoder refuses (truncated, corrupt,
    /// an unsupported coding such as arithmetic), a side beyond
    /// [`Texture::MAX_SIDE`], or a figure that does not fit the budget.
    pub fn from_jpeg_bytes_within(
        path: &Path,
        bytes: &[u8],
        budget: &crate::budget::Budget,
    ) -> Result<Texture, TextureError> {
        use zune_jpeg::zune_core::bytestream::ZCursor;
        use zune_jpeg::zune_core::colorspace::ColorSpace;
        use zune_jpeg::zune_core::options::DecoderOptions;
        let err = |m: String| TextureError { message: m };
        // JPEG's own limit is 65535 a side: the header is read whatever it
        // says, and the side checked here with the PNG's message.
        let options = DecoderOptions::new_safe()
            .set_strict_mode(true)
            .set_max_width(usize::from(u16::MAX))
            .set_max_height(usize::from(u16::MAX))
            .jpeg_set_out_colorspace(ColorSpace::RGB);
        let mut dec = zune_jpeg::JpegDecoder::new_with_options(ZCursor::new(bytes), options);
        // The decoder's messages may end in a newline.
        let words = |e: zune_jpeg::errors::DecodeErrors| e.to_string().trim().to_string();
        dec.decode_headers()
            .map_err(|e| err(format!("not a readable JPEG: {}", words(e))))?;
        let (w, h) = dec
            .dimensions()
            .ok_or_else(|| err("not a readable JPEG: no frame header".into()))?;
        let side = |v: usize| u32::try_from(v).unwrap_or(u32::MAX);
        let (w, h) = (side(w), side(h));
        if w == 0 || h == 0 || w > Self::MAX_SIDE || h > Self::MAX_SIDE {
            return Err(err(format!(
                "image is {w}x{h}; each side must be 1 … {}",
                Self::MAX_SIDE
            )));
        }
        let texels = u64::from(w) * u64::from(h);
        budget
            .reserve(texels * Self::BYTES_PER_TEXEL, || {
                format!("the {w}x{h} texture's texels")
            })
            .map_err(|e| err(e.to_string()))?;
        let decoded = (|| {
            budget
                .check(texels * Self::JPEG_DECODE_BYTES_PER_PIXEL, || {
                    format!("decoding the {w}x{h} texture")
                })
                .map_err(|e| e.to_string())?;
            let rgb = dec
                .decode()
                .map_err(|e| format!("not a readable JPEG: {}", words(e)))?;
            let n = (w as usize) * (h as usize);
            if rgb.len() < 3 * n {
                return Err(format!(
                    "not a readable JPEG: {} bytes decoded for {w}x{h} RGB pixels",
                    rgb.len()
                ));
            }
            Ok(rgb[..3 * n]
                .chunks_exact(3)
                .map(|p| {
                    let v = |b: u8| f32::from(b) / 255.0;
                    [v(p[0]), v(p[1]), v(p[2]), 1.0]
                })
                .collect::<Vec<[f32; 4]>>())
        })();
        match decoded {
            Ok(texels) => Ok(Texture {
                path: path.to_path_buf(),
                width: w,
                height: h,
                texels,
                has_alpha: false,
                grey: false,
                bit_depth: 8,
                format: ImageFormat::Jpeg,
                tint: None,
            }),
            Err(m) => {
                budget.release(texels * Self::BYTES_PER_TEXEL);
                Err(err(m))
            }
        }
    }

    /// Decodes PNG bytes; `path` names the file in errors and exports.
    ///
    /// # Errors
    ///
    /// [`TextureError`] when the bytes are not a PNG the decoder accepts or
    /// the image is larger than [`Texture::MAX_SIDE`] on a side.
    pub fn from_png_bytes(path: &Path, bytes: &[u8]) -> Result<Texture, TextureError> {
        Texture::from_png_bytes_within(path, bytes, &crate::budget::Budget::default())
    }

    /// Bytes a texture holds per texel (four f32 channels).
    pub const BYTES_PER_TEXEL: u64 = 16;

    /// [`Texture::from_png_bytes`], reserving the texels in `budget` from
    /// the header's size before anything is decoded; the decoder's own
    /// allocations are capped at what the budget has left, and the chunks
    /// a texture never uses (an ICC profile, text) are skipped, never
    /// inflated.
    ///
    /// # Errors
    ///
    /// As [`Texture::from_png_bytes`], or the figure that does not fit.
    pub fn from_png_bytes_within(
        path: &Path,
        bytes: &[u8],
        budget: &crate::budget::Budget,
    ) -> Result<Texture, TextureError> {
        let err = |m: String| TextureError { message: m };
        let reader = crate::image_io::png_reader(bytes, budget)
            .map_err(|e| err(format!("not a readable PNG: {e}")))?;
        let info = reader.info();
        let (w, h) = (info.width, info.height);
        if w == 0 || h == 0 || w > Self::MAX_SIDE || h > Self::MAX_SIDE {
            return Err(err(format!(
                "image is {w}x{h}; each side must be 1 … {}",
                Self::MAX_SIDE
            )));
        }
        // The texels stay; the decoded rows (the expanded PNG's bytes per
        // pixel) are freed once converted, so decoding needs that much
        // more for a moment.
        let texels = u64::from(w) * u64::from(h);
        let decoded = reader
            .output_buffer_size()
            .ok_or_else(|| err("image too large".into()))? as u64;
        budget
            .reserve(texels * Self::BYTES_PER_TEXEL, || {
                format!("the {w}x{h} texture's texels")
            })
            .map_err(|e| err(e.to_string()))?;
        if let Err(e) = budget.check(decoded, || format!("decoding the {w}x{h} texture")) {
            budget.release(texels * Self::BYTES_PER_TEXEL);
            return Err(err(e.to_string()));
        }
        let result = Self::decode(path, reader);
        if result.is_err() {
            budget.release(texels * Self::BYTES_PER_TEXEL);
        }
        result.map_err(err)
    }

    /// Decodes the frame `reader` stands at: every colour type expanded to
    /// RGBA (grey replicated, a palette looked up, `tRNS` as alpha), each
    /// sample divided by 255 or 65 535.
    fn decode(
        path: &Path,
        mut reader: png::Reader<std::io::Cursor<&[u8]>>,
    ) -> Result<Texture, String> {
        let mut buf = vec![
            0u8;
            reader
                .output_buffer_size()
                .ok_or_else(|| "image too large".to_string())?
        ];
        let frame = reader
            .next_frame(&mut buf)
            .map_err(|e| format!("not a readable PNG: {e}"))?;
        let (w, h) = (frame.width, frame.height);
        let channels = frame.color_type.samples();
        let sixteen = frame.bit_depth == png::BitDepth::Sixteen;
        let has_alpha = matches!(
            frame.color_type,
            png::ColorType::GrayscaleAlpha | png::ColorType::Rgba
        );
        let grey = matches!(
            frame.color_type,
            png::ColorType::Grayscale | png::ColorType::GrayscaleAlpha
        );
        let sample = |i: usize| -> f32 {
            if sixteen {
                f32::from(u16::from_be_bytes([buf[2 * i], buf[2 * i + 1]])) / 65535.0
            } else {
                f32::from(buf[i]) / 255.0
            }
        };
        let n = (w as usize) * (h as usize);
        let texels: Vec<[f32; 4]> = (0..n)
            .map(|p| {
                let b = p * channels;
                match channels {
                    1 => {
                        let v = sample(b);
                        [v, v, v, 1.0]
                    }
                    2 => {
                        let v = sample(b);
                        [v, v, v, sample(b + 1)]
                    }
                    3 => [sample(b), sample(b + 1), sample(b + 2), 1.0],
                    _ => [sample(b), sample(b + 1), sample(b + 2), sample(b + 3)],
                }
            })
            .collect();
        Ok(Texture {
            path: path.to_path_buf(),
            width: w,
            height: h,
            texels,
            has_alpha,
            grey,
            bit_depth: if sixteen { 16 } else { 8 },
            format: ImageFormat::Png,
            tint: None,
        })
    }

    /// Reads and decodes a PNG or JPEG file.
    ///
    /// # Errors
    ///
    /// [`TextureError`] naming what failed (the caller adds the path).
    pub fn load(path: &Path) -> Result<Texture, TextureError> {
        let bytes = crate::input::read_file(path).map_err(|e| TextureError {
            message: format!("could not read: {e}"),
        })?;
        Texture::from_bytes(path, &bytes)
    }

    /// A texture from texels (row-major from the top row), for tests and
    /// generated images.
    ///
    /// # Panics
    ///
    /// If `texels.len() != width·height` or a side is 0.
    #[must_use]
    pub fn from_texels(width: u32, height: u32, texels: Vec<[f32; 4]>) -> Texture {
        assert!(width > 0 && height > 0);
        assert_eq!(texels.len(), (width as usize) * (height as usize));
        let has_alpha = texels.iter().any(|t| t[3] != 1.0);
        Texture {
            path: PathBuf::new(),
            width,
            height,
            texels,
            has_alpha,
            grey: false,
            bit_depth: 16,
            format: ImageFormat::Texels,
            tint: None,
        }
    }

    /// The same image with every texel's colour multiplied by `tint`
    /// (alpha unchanged): an OBJ material's `Kd` colour on its `map_Kd`
    /// (`scene::mtl`). Each channel of `tint` must lie in [0, 1], so the
    /// texels stay in [0, 1].
    ///
    /// # Panics
    ///
    /// If a channel of `tint` is outside [0, 1] (or NaN).
    #[must_use]
    pub fn tinted(&self, tint: Rgb) -> Texture {
        let t = [tint.r, tint.g, tint.b];
        assert!(t.iter().all(|c| (0.0..=1.0).contains(c)), "tint {t:?}");
        let texels = self
            .texels
            .iter()
            .map(|x| [x[0] * t[0], x[1] * t[1], x[2] * t[2], x[3]])
            .collect();
        let before = self.tint.unwrap_or(Rgb::WHITE);
        Texture {
            texels,
            tint: Some(Rgb::new(before.r * t[0], before.g * t[1], before.b * t[2])),
            grey: self.grey && t[0] == t[1] && t[1] == t[2],
            ..self.clone()
        }
    }

    /// The format the texels were decoded from.
    #[must_use]
    pub fn format(&self) -> ImageFormat {
        self.format
    }

    /// The colour the file's texels were multiplied by ([`Texture::tinted`]),
    /// if any: the texels are then not the file's.
    #[must_use]
    pub fn tint(&self) -> Option<Rgb> {
        self.tint
    }

    /// The file the texture came from.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }
    /// Width in texels.
    #[must_use]
    pub fn width(&self) -> u32 {
        self.width
    }
    /// Height in texels.
    #[must_use]
    pub fn height(&self) -> u32 {
        self.height
    }
    /// `true` when the file has an alpha channel.
    #[must_use]
    pub fn has_alpha(&self) -> bool {
        self.has_alpha
    }
    /// `true` when the file is greyscale (POV-Ray misreads 8-bit greyscale, POVRAY.md §9.2).
    #[must_use]
    pub fn is_grey(&self) -> bool {
        self.grey
    }
    /// 8 or 16.
    #[must_use]
    pub fn bit_depth(&self) -> u8 {
        self.bit_depth
    }
    /// The texels, row-major from the top row.
    #[must_use]
    pub fn texels(&self) -> &[[f32; 4]] {
        &self.texels
    }

    /// The texel in column `x`, row `y`, both already wrapped into the
    /// texture (`x < width`, `y < height`).
    fn texel(&self, x: usize, y: usize) -> [f32; 4] {
        self.texels[y * self.width as usize + x]
    }

    /// Bilinear lookup at uv, wrapping (repeat) outside [0, 1).
    ///
    /// Image coordinates are `x = u·w`, `y = (1 − v)·h` (row 0 at the top),
    /// and texel `(k, r)` has its centre at `(k + 0.5, r + 0.5)`; colour and
    /// alpha are interpolated separately (not premultiplied), as POV-Ray's
    /// `interpolate 2` does.
    #[must_use]
    pub fn sample(&self, uv: Vec2) -> TexSample {
        let t = self.bilinear(
            f64::from(uv.x) * f64::from(self.width),
            (1.0 - f64::from(uv.y)) * f64::from(self.height),
        );
        TexSample {
            rgb: Rgb::new(t[0], t[1], t[2]),
            alpha: t[3],
        }
    }

    /// Bilinear lookup at image coordinates `(x, y)` (texel centres at +0.5).
    #[must_use]
    #[expect(
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss,
        clippy::cast_precision_loss,
        reason = "floor of a finite coordinate wrapped into 0 ..= w (w < 2^32); non-finite input is mapped to 0 first"
    )]
    pub fn bilinear(&self, x: f64, y: f64) -> [f32; 4] {
        let x = if x.is_finite() { x } else { 0.0 };
        let y = if y.is_finite() { y } else { 0.0 };
        // Wrap first so huge coordinates keep their fractional part.
        let x = wrap(x - 0.5, f64::from(self.width));
        let y = wrap(y - 0.5, f64::from(self.height));
        // Both lie in 0 ..= w (`wrap` can round up to w itself, as
        // `rem_euclid` does), so the cast is the floor.
        let (x0, y0) = (x as usize, y as usize);
        let fx = (x - x0 as f64) as f32;
        let fy = (y - y0 as f64) as f32;
        // The texel columns x0 and x0 + 1 wrapped into 0 … w − 1 (x0 is w
        // only where `wrap` rounded up): a comparison, not a division.
        let (w, h) = (self.width as usize, self.height as usize);
        let next = |i: usize, n: usize| if i + 1 >= n { i + 1 - n } else { i + 1 };
        let (x0, y0) = (
            if x0 >= w { x0 - w } else { x0 },
            if y0 >= h { y0 - h } else { y0 },
        );
        let (x1, y1) = (next(x0, w), next(y0, h));
        let a = self.texel(x0, y0);
        let b = self.texel(x1, y0);
        let c = self.texel(x0, y1);
        let d = self.texel(x1, y1);
        let mut out = [0.0f32; 4];
        for k in 0..4 {
            let top = a[k] + (b[k] - a[k]) * fx;
            let bot = c[k] + (d[k] - c[k]) * fx;
            out[k] = top + (bot - top) * fy;
        }
        out
    }
}

/// `x.rem_euclid(w)` for a finite `x` and a whole `w` in 1 … 2³², but a
/// zero result always `+0.0`, without the bit-by-bit loop of libm's `fmod`
/// that `rem_euclid` calls (5 % of `grazing`'s render).
///
/// Exactness: `q = trunc(fl(x/w))` differs from `trunc(x/w)` only where
/// `x/w` lies just below a whole number and rounds up to it (rounding is
/// monotone and whole numbers are representable), so `q` is the true
/// quotient or one more in magnitude. `q·w` is a whole number below 2⁵³,
/// exact. `x − q·w` is then the true remainder `m` or `m ∓ w`, a multiple of
/// `ulp(x)` smaller than `w ≤ |x|` in magnitude (for `|x| < w`, `q` is 0 or
/// ±1 with `x − q·w` exact by Sterbenz), so it is exact too. Where it is
/// negative, `r + w` is `rem_euclid`'s own last step (`m + w`, rounded) or,
/// after the overshoot, the representable `m` itself. A zero result is
/// `+0.0` where `rem_euclid` gives `−0.0`; both floor to texel 0, and the
/// caller's fraction is `+0.0` either way, as it was.
///
/// From 2⁵² up the standard remainder is used (the bound is generous:
/// the argument needs `|x| + w < 2⁵³`), its `−0.0` made `+0.0` as well:
/// the caller's fraction `x − floor(x)` had been `+0.0` for both zeros,
/// and `x − 0` keeps the sign (a `−0.0` texel channel times a `−0.0`
/// fraction would otherwise turn from `+0.0` into `−0.0`).
fn wrap(x: f64, w: f64) -> f64 {
    const EXACT: f64 = 4_503_599_627_370_496.0; // 2^52
    if x.abs() >= EXACT {
        // (`abs` changes only a −0.0: the remainder is never negative.)
        return x.rem_euclid(w).abs();
    }
    #[expect(
        clippy::cast_possible_truncation,
        clippy::cast_precision_loss,
        reason = "|x / w| < 2^52: the cast is trunc, exact both ways"
    )]
    let q = (x / w) as i64 as f64;
    let r = x - q * w;
    if r < 0.0 { r + w } else { r }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn checker() -> Texture {
        // 2x2: top row red, green; bottom row blue, white.
        Texture::from_texels(
            2,
            2,
            vec![
                [1.0, 0.0, 0.0, 1.0],
                [0.0, 1.0, 0.0, 1.0],
                [0.0, 0.0, 1.0, 1.0],
                [1.0, 1.0, 1.0, 1.0],
            ],
        )
    }

    #[test]
    fn uv_origin_is_bottom_left_and_centres_are_exact() {
        let t = checker();
        // Centre of the bottom-left texel: u = 0.25, v = 0.25 -> blue.
        assert_eq!(t.sample(Vec2::new(0.25, 0.25)).rgb, Rgb::new(0.0, 0.0, 1.0));
        // Centre of the top-right texel -> green.
        assert_eq!(t.sample(Vec2::new(0.75, 0.75)).rgb, Rgb::new(0.0, 1.0, 0.0));
    }

    #[test]
    fn bilinear_blends_and_wraps() {
        let t = checker();
        // Midway between the two top texels: (red + green) / 2.
        let s = t.sample(Vec2::new(0.5, 0.75)).rgb;
        assert!((s.r - 0.5).abs() < 1e-6 && (s.g - 0.5).abs() < 1e-6 && s.b.abs() < 1e-6);
        // u = 0 lies between the last and first columns (wrap): red/green blend.
        let s = t.sample(Vec2::new(0.0, 0.75)).rgb;
        assert!((s.r - 0.5).abs() < 1e-6 && (s.g - 0.5).abs() < 1e-6);
        // Repeat: u + 3 gives the same value.
        assert_eq!(
            t.sample(Vec2::new(3.25, -1.75)),
            t.sample(Vec2::new(0.25, 0.25))
        );
    }

    /// The lookup as it was with `rem_euclid` (libm's `fmod`) and integer
    /// `rem_euclid` on the texel indices: the reference `bilinear` must
    /// match bit for bit.
    #[expect(
        clippy::cast_possible_truncation,
        reason = "the lookup as it was, casts included"
    )]
    fn bilinear_by_rem_euclid(t: &Texture, x: f64, y: f64) -> [f32; 4] {
        let x = if x.is_finite() { x } else { 0.0 };
        let y = if y.is_finite() { y } else { 0.0 };
        let x = (x - 0.5).rem_euclid(f64::from(t.width));
        let y = (y - 0.5).rem_euclid(f64::from(t.height));
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let at = |i: i64, j: i64| {
            let xi = i.rem_euclid(i64::from(t.width)) as usize;
            let yi = j.rem_euclid(i64::from(t.height)) as usize;
            t.texels[yi * t.width as usize + xi]
        };
        let (a, b, c, d) = (
            at(x0, y0),
            at(x0 + 1, y0),
            at(x0, y0 + 1),
            at(x0 + 1, y0 + 1),
        );
        let mut out = [0.0f32; 4];
        for k in 0..4 {
            let top = a[k] + (b[k] - a[k]) * fx;
            let bot = c[k] + (d[k] - c[k]) * fx;
            out[k] = top + (bot - top) * fy;
        }
        out
    }

    #[expect(clippy::cast_precision_loss, reason = "test values of a few bits")]
    fn graded(w: u32, h: u32) -> Texture {
        let n = (w * h) as usize;
        Texture::from_texels(
            w,
            h,
            (0..n)
                .map(|i| {
                    let v = i as f32 / n as f32;
                    // Some −0.0 channels: a lookup's zero fractions must
                    // keep their sign as before (`0·(−0)` is −0).
                    let b = if i % 7 == 0 {
                        -0.0
                    } else {
                        (i % 7) as f32 / 7.0
                    };
                    [v, 1.0 - v, b, 1.0]
                })
                .collect(),
        )
    }

    #[expect(clippy::cast_precision_loss, reason = "test values of a few bits")]
    #[test]
    fn wrap_is_rem_euclid_up_to_the_sign_of_zero() {
        // Just below and above whole multiples (where fl(x / w) rounds up
        // to the next quotient), tiny negatives (where rem_euclid rounds up
        // to w itself), subnormals, and the 2^52 switch.
        let mut xs = vec![0.0, -0.0, 5e-324, -5e-324, 1e-300, -1e-300, 0.5, -0.5];
        for w in [
            1.0f64,
            2.0,
            3.0,
            7.0,
            64.0,
            1000.0,
            4096.0,
            65_535.0,
            4_294_967_295.0,
        ] {
            for k in [
                -1e15f64, -12_345.0, -3.0, -2.0, -1.0, 0.0, 1.0, 2.0, 3.0, 1e6, 1e15,
            ] {
                let m = k * w;
                for x in [m, m.next_up(), m.next_down(), m + 0.5, m - 0.5] {
                    xs.push(x);
                }
            }
            for x in [
                2f64.powi(52),
                2f64.powi(52).next_down(),
                -(2f64.powi(52).next_down()),
                1e300,
            ] {
                xs.push(x);
            }
            let mut seed = 0x9e37_79b9_7f4a_7c15u64;
            for _ in 0..20_000 {
                seed = seed
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1_442_695_040_888_963_407);
                let e = ((seed >> 58) as i32) - 20; // 2^-20 … 2^43
                let u = (seed >> 11) as f64 / (1u64 << 53) as f64;
                let x = (u - 0.5) * 2f64.powi(e) * w;
                xs.push(x);
            }
            for &x in &xs {
                let (a, b) = (wrap(x, w), x.rem_euclid(w));
                assert!(
                    a == b && (0.0..=w).contains(&a),
                    "wrap({x:e}, {w}) = {a:e}, rem_euclid {b:e}"
                );
            }
        }
    }

    #[expect(clippy::cast_precision_loss, reason = "test values of a few bits")]
    #[test]
    fn bilinear_is_the_rem_euclid_lookup_bit_for_bit() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        for (w, h) in [(1, 1), (1, 3), (2, 2), (5, 3), (16, 9), (64, 64)] {
            let t = graded(w, h);
            for i in 0..20_000 {
                seed ^= seed << 13;
                seed ^= seed >> 7;
                seed ^= seed << 17;
                let e = (seed >> 60) as i32 - 4; // scales 2^-4 … 2^11 texels
                let fx = ((seed & 0xffff_ffff) as f64 / 4_294_967_296.0 - 0.5)
                    * 2f64.powi(e)
                    * f64::from(w);
                let fy = (((seed >> 32) & 0x0fff_ffff) as f64 / 268_435_456.0 - 0.5)
                    * 2f64.powi(e)
                    * f64::from(h);
                // Every 7th coordinate on a texel centre or edge exactly.
                let (x, y) = if i % 7 == 0 {
                    (fx.round() + 0.5, fy.round())
                } else {
                    (fx, fy)
                };
                let (a, b) = (t.bilinear(x, y), bilinear_by_rem_euclid(&t, x, y));
                assert!(
                    a.iter().zip(&b).all(|(p, q)| p.to_bits() == q.to_bits()),
                    "{w}x{h} at ({x:e}, {y:e}): {a:?} against {b:?}"
                );
            }
            // Beyond 2^52 (the standard remainder's side of `wrap`), on
            // and off whole multiples of the size.
            for (x, y) in [
                (f64::NAN, 1.0),
                (f64::INFINITY, -2.5),
                (-1e-300, 0.5),
                (1e300, -1e300),
                (0.5, 0.5),
                (-1e17, -1e17),
                (-1e17 + 0.5, -1e17 + 0.5),
                (2f64.powi(60) + 0.5, -(2f64.powi(53)) + 0.5),
                (-(2f64.powi(52)) - 64.0, 2f64.powi(52) + 64.0),
            ] {
                let (a, b) = (t.bilinear(x, y), bilinear_by_rem_euclid(&t, x, y));
                assert!(
                    a.iter().zip(&b).all(|(p, q)| p.to_bits() == q.to_bits()),
                    "{w}x{h} at ({x:e}, {y:e}): {a:?} against {b:?}"
                );
            }
        }
    }

    fn jpeg() -> Vec<u8> {
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/obj/mtl/tiles.jpg");
        std::fs::read(p).unwrap()
    }

    #[test]
    fn jpeg_texels_are_linear_codes_and_cut_files_are_errors() {
        let t = Texture::from_bytes(Path::new("t.jpg"), &jpeg()).unwrap();
        assert_eq!(
            (t.width(), t.height(), t.format()),
            (16, 16, ImageFormat::Jpeg)
        );
        assert!(!t.has_alpha());
        for x in t.texels() {
            for &c in &x[..3] {
                let code = c * 255.0;
                assert!((code - code.round()).abs() < 1e-3, "{c} is not v/255");
            }
            assert_eq!(x[3], 1.0);
        }
        // Cut anywhere inside its scans: an error, never a grey patch.
        let j = jpeg();
        for keep in [j.len() / 3, j.len() / 2, j.len() - 40] {
            let e = Texture::from_bytes(Path::new("t.jpg"), &j[..keep]).unwrap_err();
            assert!(
                e.message.starts_with("not a readable JPEG: "),
                "{keep}: {e}"
            );
        }
        let e = Texture::from_bytes(Path::new("t.jpg"), &[0xFF, 0xD8]).unwrap_err();
        assert!(e.message.contains("JPEG"), "{e}");
    }

    #[test]
    fn a_tint_multiplies_the_colour_and_keeps_alpha() {
        let t = checker().tinted(Rgb::new(0.5, 1.0, 0.25));
        assert_eq!(t.texels()[3], [0.5, 1.0, 0.25, 1.0]);
        assert_eq!(t.tint(), Some(Rgb::new(0.5, 1.0, 0.25)));
        assert_eq!(checker().tint(), None);
    }

    #[test]
    fn garbage_bytes_are_an_error_not_a_panic() {
        let e = Texture::from_png_bytes(Path::new("x.png"), b"\x89PNG\r\n\x1a\nnope").unwrap_err();
        assert!(e.message.contains("PNG"), "{e}");
        assert!(Texture::from_png_bytes(Path::new("x.png"), b"").is_err());
    }
}
