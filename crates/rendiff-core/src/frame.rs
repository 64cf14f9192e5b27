//! `Frame`: what every backend produces — the pixel colours and, per
//! sample, the G-buffer the verdict reads (colour, depth, triangle id,
//! shading flags).

use std::path::Path;

use rayon::prelude::*;

use crate::color::Rgb;
use crate::huge::Big;
use crate::image_io::{self, ImageIoError, PngEncoding};

/// Triangle id of a sample that sees the background.
pub const BACKGROUND: u32 = u32::MAX;

/// A rendered frame.
///
/// # Guarantees
///
/// `color.len() == width·height`; the sample buffers have
/// `(width·samples)·(height·samples)` entries, row-major from the top of
/// the sample grid (with one sample per pixel the sample colours are the
/// pixel colours: `sample_color` is empty and [`Frame::sample_colors`]
/// returns `color`, which saves a frame-sized buffer and its copy); every
/// colour is finite.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Samples per pixel side.
    pub samples: u32,
    /// Pixel colours (the plain mean of their samples), linear.
    pub color: Big<Rgb>,
    /// Sample colours, linear (empty with one sample per pixel: read them
    /// with [`Frame::sample_colors`]).
    pub sample_color: Big<Rgb>,
    /// Depth per sample: t along the unit primary ray; +∞ for background.
    pub depth: Big<f32>,
    /// Visible primitive per sample ([`BACKGROUND`] for none).
    pub id: Big<u32>,
    /// Shading flags per sample (bit 0: discontinuity; bits 1–31: shadows of lights 0–30).
    pub flags: Big<u32>,
}

/// What a backend found at one sample, as the frame stores it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Linear colour, every channel finite.
    pub color: Rgb,
    /// `t` along the unit primary ray; +∞ for the background.
    pub depth: f32,
    /// Visible primitive, or [`BACKGROUND`].
    pub id: u32,
    /// Shading flags (see [`Frame::flags`]).
    pub flags: u32,
}

impl Sample {
    /// A sample that sees the background.
    #[must_use]
    pub fn background(color: Rgb) -> Sample {
        Sample {
            color,
            depth: f32::INFINITY,
            id: BACKGROUND,
            flags: 0,
        }
    }

    /// A sample that sees primitive `id` at frame depth `depth` (computed
    /// in f64 from the f64 hit point, rounded once to f32 here). A
    /// non-finite colour channel (a NaN from a degenerate shading input)
    /// becomes 0: a frame never holds a NaN pixel.
    #[must_use]
    pub fn hit(color: Rgb, depth: f64, id: u32, flags: u32) -> Sample {
        let finite = |v: f32| if v.is_finite() { v } else { 0.0 };
        #[expect(clippy::cast_possible_truncation, reason = "frame depth is f32")]
        let depth = depth as f32;
        Sample {
            color: Rgb::new(finite(color.r), finite(color.g), finite(color.b)),
            depth,
            id,
            flags,
        }
    }
}

/// A band of consecutive sample rows of a frame, lent to one worker by
/// [`Frame::par_bands`].
#[derive(Debug)]
pub struct Band<'a> {
    /// The first sample row of the band.
    pub y0: u32,
    /// Sample rows in the band (the last band may be shorter).
    pub rows: u32,
    width: u32,
    color: &'a mut [Rgb],
    depth: &'a mut [f32],
    id: &'a mut [u32],
    flags: &'a mut [u32],
}

impl Band<'_> {
    /// Stores `s` at sample column `sx` of the band's row `dy`.
    ///
    /// # Panics
    ///
    /// When `(sx, dy)` lies outside the band.
    #[inline]
    pub fn set(&mut self, sx: u32, dy: u32, s: Sample) {
        assert!(sx < self.width && dy < self.rows, "sample outside the band");
        let i = (dy as usize) * (self.width as usize) + sx as usize;
        self.color[i] = s.color;
        self.depth[i] = s.depth;
        self.id[i] = s.id;
        self.flags[i] = s.flags;
    }
}

impl Frame {
    /// Fills the sample buffers in parallel: `f` is called once per band
    /// of `rows` sample rows (in any order, on rayon's workers) and its
    /// results are returned in band order. Samples `f` does not set keep
    /// the background.
    ///
    /// # Panics
    ///
    /// When `rows` is 0.
    pub fn par_bands<T: Send>(
        &mut self,
        rows: u32,
        f: impl Fn(&mut Band<'_>) -> T + Sync,
    ) -> Vec<T> {
        assert!(rows > 0, "a band has at least one row");
        let width = self.sample_width();
        let height = self.sample_height();
        let len = (rows as usize) * (width as usize);
        let (colors, depths, ids, flags) = self.sample_buffers_mut();
        colors
            .par_chunks_mut(len.max(1))
            .zip(depths.par_chunks_mut(len.max(1)))
            .zip(ids.par_chunks_mut(len.max(1)))
            .zip(flags.par_chunks_mut(len.max(1)))
            .enumerate()
            .map(|(b, (((color, depth), id), flags))| {
                let y0 = u32::try_from(b).map_or(u32::MAX, |b| b.saturating_mul(rows));
                let mut band = Band {
                    y0,
                    rows: rows.min(height - y0),
                    width,
                    color,
                    depth,
                    id,
                    flags,
                };
                f(&mut band)
            })
            .collect()
    }

    /// An empty (background) frame.
    #[must_use]
    pub fn new(width: u32, height: u32, samples: u32, background: Rgb) -> Frame {
        let n = (width as usize) * (height as usize);
        let ns = n * (samples as usize) * (samples as usize);
        Frame {
            width,
            height,
            samples,
            color: Big::filled(n, background),
            sample_color: if samples == 1 {
                Big::default()
            } else {
                Big::filled(ns, background)
            },
            depth: Big::filled(ns, f32::INFINITY),
            id: Big::filled(ns, BACKGROUND),
            flags: Big::zeroed(ns),
        }
    }

    /// Makes this frame the empty (background) frame [`Frame::new`] makes,
    /// equal to it field for field, in the memory it already holds where
    /// that is large enough: a renderer that draws frame after frame into
    /// one `Frame` touches no fresh memory after the first (fresh pages
    /// must be zeroed by the kernel, which costs more than writing them).
    pub fn reset(&mut self, width: u32, height: u32, samples: u32, background: Rgb) {
        let n = (width as usize) * (height as usize);
        let ns = n * (samples as usize) * (samples as usize);
        self.width = width;
        self.height = height;
        self.samples = samples;
        self.color.refill(n, background);
        self.sample_color
            .refill(if samples == 1 { 0 } else { ns }, background);
        self.depth.refill(ns, f32::INFINITY);
        self.id.refill(ns, BACKGROUND);
        self.flags.refill(ns, 0);
    }

    /// Width of the sample grid.
    #[must_use]
    pub fn sample_width(&self) -> u32 {
        self.width * self.samples
    }

    /// Height of the sample grid.
    #[must_use]
    pub fn sample_height(&self) -> u32 {
        self.height * self.samples
    }

    /// Number of samples.
    #[must_use]
    pub fn sample_count(&self) -> usize {
        self.id.len()
    }

    /// The sample colours (the pixel colours with one sample per pixel).
    #[must_use]
    pub fn sample_colors(&self) -> &[Rgb] {
        if self.samples == 1 {
            &self.color
        } else {
            &self.sample_color
        }
    }

    /// The sample colours and the other per-sample buffers at once:
    /// (colour, depth, id, flags).
    fn sample_buffers_mut(&mut self) -> (&mut [Rgb], &mut [f32], &mut [u32], &mut [u32]) {
        let color = if self.samples == 1 {
            &mut self.color
        } else {
            &mut self.sample_color
        };
        (color, &mut self.depth, &mut self.id, &mut self.flags)
    }

    /// Recomputes the pixel colours as the mean of their samples, each
    /// clamped to [0, 1] first (as POV-Ray's anti-aliasing does: a bright
    /// highlight sample counts as full scale, not more); nothing to do with
    /// one sample per pixel.
    pub fn resolve(&mut self) {
        if self.samples == 1 {
            return;
        }
        let n = self.samples as usize;
        let sw = self.sample_width() as usize;
        #[expect(clippy::cast_precision_loss, reason = "n² ≤ 256")]
        let inv = 1.0 / (n * n) as f32;
        let samples = &self.sample_color;
        // Row by row in parallel (each pixel the same sum in the same
        // order: its sample rows top to bottom, each left to right). The
        // pixel row is the accumulator, and each sample row is taken as a
        // slice cut into the pixels' runs of `n`: indexing every sample
        // with its bounds check had cost `dense.toml`'s rasterizer render
        // 5 % of its instructions (185 a pixel).
        self.color
            .par_chunks_mut((self.width as usize).max(1))
            .enumerate()
            .for_each(|(y, row)| {
                row.fill(Rgb::BLACK);
                for b in 0..n {
                    let start = (y * n + b) * sw;
                    let line = &samples[start..start + sw];
                    for (pixel, run) in row.iter_mut().zip(line.chunks_exact(n)) {
                        for s in run {
                            *pixel += s.clamp01();
                        }
                    }
                }
                for pixel in row {
                    *pixel = *pixel * inv;
                }
            });
    }

    /// Writes the colour image (8-bit sRGB or 16-bit linear).
    ///
    /// # Errors
    ///
    /// [`ImageIoError`].
    pub fn write_png(&self, path: &Path, encoding: PngEncoding) -> Result<(), ImageIoError> {
        image_io::write_png(path, self.width, self.height, &self.color, encoding)
    }

    /// Writes the G-buffer of DESIGN.md §5 into `dir`: `depth.pfm`,
    /// `id.png` (id + 1 as RGBA8 little-endian, 0 = background) and
    /// `flags.png`, at the sample resolution.
    ///
    /// # Errors
    ///
    /// [`ImageIoError`].
    pub fn write_gbuffer(&self, dir: &Path) -> Result<(), ImageIoError> {
        std::fs::create_dir_all(dir).map_err(|source| ImageIoError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        let (w, h) = (self.sample_width(), self.sample_height());
        let [depth, id, flags, color] = GBUFFER_FILES;
        image_io::write_pfm(&dir.join(depth), w, h, &self.depth)?;
        let ids: Vec<u32> = self.id.iter().map(|&i| i.wrapping_add(1)).collect();
        image_io::write_png_u32(&dir.join(id), w, h, &ids)?;
        image_io::write_png_u32(&dir.join(flags), w, h, &self.flags)?;
        image_io::write_png(
            &dir.join(color),
            w,
            h,
            self.sample_colors(),
            image_io::PngEncoding::Linear16,
        )
    }
}

/// The files [`Frame::write_gbuffer`] writes into its folder, all at the
/// sample grid: depth, triangle id + 1, shading flags, and the sample
/// colours (16-bit linear) — the folder `rendiff diff --b DIR` reads as
/// another renderer's G-buffer.
pub const GBUFFER_FILES: [&str; 4] = ["depth.pfm", "id.png", "flags.png", "color.png"];

/// Bands a frame's parallel passes want per thread of the pool: a band is
/// one task, and with few of them the threads that draw the costly rows
/// (the middle of a centred mesh) finish last while the others wait.
const BANDS_PER_THREAD: u32 = 16;

/// The sample rows of a pass's bands over `height` rows: `preferred`,
/// or fewer where that would leave fewer than 16 bands for each thread
/// of the current rayon pool, down to `least`; a multiple of `step`.
/// The bands only divide the work: every sample is computed alike
/// whatever their height, so the frame is the same at every thread
/// count.
#[must_use]
pub fn band_rows(height: u32, preferred: u32, least: u32, step: u32) -> u32 {
    let threads = u32::try_from(rayon::current_num_threads()).unwrap_or(u32::MAX);
    let fit = height / threads.saturating_mul(BANDS_PER_THREAD).max(1);
    let step = step.max(1);
    (fit.clamp(least.max(1), preferred.max(1)) / step * step).max(step)
}
