//! The pictures of a comparison: a heat map of the shading error, a map of
//! the visibility classes, and a labelled side-by-side composite drawn with
//! tiny-skia (labels in a built-in 5×7 bitmap font, so no font file is
//! needed).

use tiny_skia::{Color, Paint, Pixmap, PixmapPaint, Rect, Transform};

use super::{Class, Comparison};
use crate::color::{Rgb, to_srgb8};

/// An RGBA8 picture.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Picture {
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// RGBA8, row-major from the top.
    pub rgba: Vec<u8>,
}

impl Picture {
    /// A picture from linear colours (sRGB-encoded).
    #[must_use]
    pub fn from_linear(width: u32, height: u32, px: &[Rgb]) -> Picture {
        let rgba = px
            .iter()
            .flat_map(|c| [to_srgb8(c.r), to_srgb8(c.g), to_srgb8(c.b), 255])
            .collect();
        Picture {
            width,
            height,
            rgba,
        }
    }
}

/// The colour of each visibility class in the mismatch map.
#[must_use]
pub(crate) fn class_color(c: Class) -> [u8; 3] {
    match c {
        Class::Agree => [24, 24, 24],
        Class::EdgeTie => [60, 120, 255],
        Class::DepthTie => [40, 200, 80],
        Class::NearTie => [230, 80, 230],
        Class::Unjudgeable => [255, 160, 0],
        Class::Real => [255, 30, 30],
    }
}

/// Per pixel, the worst class among its samples (real > unjudgeable > near > depth > edge > agree).
#[must_use]
pub(crate) fn visibility_map(cmp: &Comparison, width: u32, height: u32) -> Picture {
    let n = cmp.samples as usize;
    let sw = cmp.grid.0 as usize;
    let mut rgba = Vec::with_capacity((width * height * 4) as usize);
    for y in 0..height as usize {
        for x in 0..width as usize {
            let mut worst = Class::Agree;
            if !cmp.classes.is_empty() {
                for b in 0..n {
                    for a in 0..n {
                        worst = worst.max(cmp.classes[(y * n + b) * sw + x * n + a]);
                    }
                }
            }
            let c = class_color(worst);
            rgba.extend_from_slice(&[c[0], c[1], c[2], 255]);
        }
    }
    Picture {
        width,
        height,
        rgba,
    }
}

/// Per pixel, the largest shading error among its samples, on a log scale
/// from 1e-7 (black) to the tolerance (cyan); above the tolerance from red
/// to yellow (×100); shading ties in grey, unclassified samples in dark red.
#[must_use]
pub(crate) fn heat_map(cmp: &Comparison, width: u32, height: u32, tolerance: f64) -> Picture {
    let n = cmp.samples as usize;
    let sw = cmp.grid.0 as usize;
    let tol = tolerance.max(1e-12);
    let mut rgba = Vec::with_capacity((width * height * 4) as usize);
    for y in 0..height as usize {
        for x in 0..width as usize {
            let mut e = 0.0f64;
            let mut tie = false;
            let mut unclassified = false;
            for b in 0..n {
                for a in 0..n {
                    let i = (y * n + b) * sw + x * n + a;
                    let v = cmp.errors[i];
                    if v.is_nan() {
                        unclassified = true;
                    } else if cmp.ties.get(i).copied().unwrap_or(false) {
                        tie = true;
                    } else {
                        e = e.max(f64::from(v));
                    }
                }
            }
            let c = if e > tol {
                let s = ((e / tol).log10() / 2.0).clamp(0.0, 1.0);
                [255, ramp(s * 230.0), 0]
            } else if e > 1e-7 {
                let s = ((e / 1e-7).log10() / (tol / 1e-7).log10().max(1e-9)).clamp(0.0, 1.0);
                [0, ramp(s * 200.0), ramp(80.0 + s * 175.0)]
            } else if tie {
                [110, 110, 110]
            } else if unclassified {
                [70, 0, 0]
            } else {
                [0, 0, 0]
            };
            rgba.extend_from_slice(&[c[0], c[1], c[2], 255]);
        }
    }
    Picture {
        width,
        height,
        rgba,
    }
}

#[expect(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    reason = "clamped to 0..=255"
)]
fn ramp(v: f64) -> u8 {
    v.clamp(0.0, 255.0) as u8
}

fn to_pixmap(p: &Picture) -> Option<Pixmap> {
    let mut pm = Pixmap::new(p.width, p.height)?;
    pm.data_mut().copy_from_slice(&p.rgba);
    Some(pm)
}

/// A labelled side-by-side composite of several pictures of equal size.
#[must_use]
pub fn composite(panels: &[(&str, &Picture)]) -> Option<Picture> {
    let (w, h) = (panels.first()?.1.width, panels.first()?.1.height);
    let scale = if w < 200 { 1u32 } else { 2 };
    let label_h = 7 * scale + 6;
    let gap = 4u32;
    let count = u32::try_from(panels.len()).ok()?;
    let total_w = count * w + (count - 1) * gap;
    let mut canvas = Pixmap::new(total_w, h + label_h)?;
    canvas.fill(Color::from_rgba8(32, 32, 36, 255));
    let mut paint = Paint::default();
    paint.set_color_rgba8(235, 235, 235, 255);
    for (k, (label, pic)) in panels.iter().enumerate() {
        let x0 = u32::try_from(k).ok()? * (w + gap);
        let pm = to_pixmap(pic)?;
        canvas.draw_pixmap(
            i32::try_from(x0).ok()?,
            i32::try_from(label_h).ok()?,
            pm.as_ref(),
            &PixmapPaint::default(),
            Transform::identity(),
            None,
        );
        draw_text(&mut canvas, label, x0 + 3, 3, scale, &paint);
    }
    Some(Picture {
        width: canvas.width(),
        height: canvas.height(),
        rgba: canvas.data().to_vec(),
    })
}

/// Draws ASCII text with the built-in 5×7 font.
pub(crate) fn draw_text(
    canvas: &mut Pixmap,
    text: &str,
    x: u32,
    y: u32,
    scale: u32,
    paint: &Paint<'_>,
) {
    let mut cx = x;
    for ch in text.chars() {
        let glyph = glyph(ch.to_ascii_uppercase());
        for (row, bits) in glyph.iter().enumerate() {
            for col in 0..5u32 {
                if bits & (0b10000 >> col) != 0 {
                    #[expect(clippy::cast_precision_loss, reason = "small pixel coordinates")]
                    let r = Rect::from_xywh(
                        (cx + col * scale) as f32,
                        (y + u32::try_from(row).unwrap_or(0) * scale) as f32,
                        scale as f32,
                        scale as f32,
                    );
                    if let Some(r) = r {
                        canvas.fill_rect(r, paint, Transform::identity(), None);
                    }
                }
            }
        }
        cx += 6 * scale;
    }
}

#[rustfmt::skip]
fn glyph(c: char) -> [u8; 7] {
    match c {
        'A' => [0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'B' => [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E],
        'C' => [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E],
        'D' => [0x1E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x1E],
        'E' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F],
        'F' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10],
        'G' => [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F],
        'H' => [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'I' => [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'J' => [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C],
        'K' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'L' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F],
        'M' => [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11],
        'N' => [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11],
        'O' => [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'P' => [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10],
        'Q' => [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D],
        'R' => [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11],
        'S' => [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E],
        'T' => [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'U' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'V' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'W' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A],
        'X' => [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11],
        'Y' => [0x11, 0x11, 0x0A, 0x04, 0x04, 0x04, 0x04],
        'Z' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F],
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        '-' => [0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00],
        '.' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C],
        ':' => [0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00],
        '/' => [0x01, 0x01, 0x02, 0x04, 0x08, 0x10, 0x10],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        '_' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F],
        '=' => [0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00],
        '+' => [0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00],
        _ => [0; 7],
    }
}
