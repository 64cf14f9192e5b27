//! Linear RGB colour and the sRGB transfer function.
//!
//! All shading arithmetic is on [`Rgb`] (linear, `f32`); sRGB appears only
//! when an 8-bit PNG is written or read.

use std::ops::{Add, AddAssign, Mul, MulAssign, Sub};

/// A linear RGB colour (not clamped; lights may exceed 1).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Rgb {
    /// Red.
    pub r: f32,
    /// Green.
    pub g: f32,
    /// Blue.
    pub b: f32,
}

impl Rgb {
    /// Black.
    pub const BLACK: Rgb = Rgb::new(0.0, 0.0, 0.0);
    /// White.
    pub const WHITE: Rgb = Rgb::new(1.0, 1.0, 1.0);

    /// A colour from its three channels.
    #[must_use]
    pub const fn new(r: f32, g: f32, b: f32) -> Rgb {
        Rgb { r, g, b }
    }

    /// The same value in every channel.
    #[must_use]
    pub const fn splat(v: f32) -> Rgb {
        Rgb::new(v, v, v)
    }

    /// The channels as an array.
    #[must_use]
    pub fn to_array(self) -> [f32; 3] {
        [self.r, self.g, self.b]
    }

    /// A colour from an array.
    #[must_use]
    pub fn from_array(a: [f32; 3]) -> Rgb {
        Rgb::new(a[0], a[1], a[2])
    }

    /// The largest channel.
    #[must_use]
    pub fn max_channel(self) -> f32 {
        self.r.max(self.g).max(self.b)
    }

    /// `true` when every channel is finite.
    #[must_use]
    pub fn is_finite(self) -> bool {
        self.r.is_finite() && self.g.is_finite() && self.b.is_finite()
    }

    /// `true` when every channel is zero.
    #[must_use]
    pub fn is_black(self) -> bool {
        self.r == 0.0 && self.g == 0.0 && self.b == 0.0
    }

    /// Each channel clamped to `[0, 1]` (NaN becomes 0).
    #[must_use]
    pub fn clamp01(self) -> Rgb {
        let c = |v: f32| if v > 0.0 { v.min(1.0) } else { 0.0 };
        Rgb::new(c(self.r), c(self.g), c(self.b))
    }

    /// POV-Ray's grey weights for bump-map heights: 0.297 R + 0.589 G + 0.114 B.
    #[must_use]
    pub fn pov_grey(self) -> f32 {
        0.297 * self.r + 0.589 * self.g + 0.114 * self.b
    }

    /// Largest absolute channel difference.
    #[must_use]
    pub fn max_abs_diff(self, o: Rgb) -> f32 {
        (self.r - o.r)
            .abs()
            .max((self.g - o.g).abs())
            .max((self.b - o.b).abs())
    }
}

impl Add for Rgb {
    type Output = Rgb;
    fn add(self, o: Rgb) -> Rgb {
        Rgb::new(self.r + o.r, self.g + o.g, self.b + o.b)
    }
}

impl AddAssign for Rgb {
    fn add_assign(&mut self, o: Rgb) {
        *self = *self + o;
    }
}

impl Sub for Rgb {
    type Output = Rgb;
    fn sub(self, o: Rgb) -> Rgb {
        Rgb::new(self.r - o.r, self.g - o.g, self.b - o.b)
    }
}

impl Mul for Rgb {
    type Output = Rgb;
    fn mul(self, o: Rgb) -> Rgb {
        Rgb::new(self.r * o.r, self.g * o.g, self.b * o.b)
    }
}

impl MulAssign for Rgb {
    fn mul_assign(&mut self, o: Rgb) {
        *self = *self * o;
    }
}

impl Mul<f32> for Rgb {
    type Output = Rgb;
    fn mul(self, s: f32) -> Rgb {
        Rgb::new(self.r * s, self.g * s, self.b * s)
    }
}

impl Mul<Rgb> for f32 {
    type Output = Rgb;
    fn mul(self, c: Rgb) -> Rgb {
        c * self
    }
}

/// sRGB encoding of a linear value in `[0, 1]` (IEC 61966-2-1).
#[must_use]
pub(crate) fn srgb_encode(v: f32) -> f32 {
    let v = if v > 0.0 { v.min(1.0) } else { 0.0 };
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// sRGB decoding of an encoded value in [0, 1] to a linear value.
#[must_use]
pub fn srgb_decode(v: f32) -> f32 {
    if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// A linear value as an 8-bit sRGB code (clamped, rounded to nearest).
#[must_use]
#[expect(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    reason = "the value is clamped to [0, 255] before the cast"
)]
pub fn to_srgb8(v: f32) -> u8 {
    (srgb_encode(v) * 255.0 + 0.5).floor().clamp(0.0, 255.0) as u8
}

/// A linear value as a 16-bit linear code (clamped, rounded half up, as POV-Ray does).
#[must_use]
#[expect(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    reason = "the value is clamped to [0, 65535] before the cast"
)]
pub fn to_linear16(v: f32) -> u16 {
    let v = if v > 0.0 { v.min(1.0) } else { 0.0 };
    (v * 65535.0 + 0.5).floor().clamp(0.0, 65535.0) as u16
}

/// The 256-entry table decoding 8-bit sRGB codes to linear values.
#[must_use]
pub(crate) fn srgb8_table() -> [f32; 256] {
    let mut t = [0.0f32; 256];
    for (i, v) in t.iter_mut().enumerate() {
        *v = srgb_decode(f32::from(u8::try_from(i).unwrap_or(u8::MAX)) / 255.0);
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_round_trips_every_code() {
        let table = srgb8_table();
        for (code, &lin) in table.iter().enumerate() {
            assert_eq!(usize::from(to_srgb8(lin)), code);
        }
    }

    #[test]
    fn srgb_matches_povray_measurement() {
        // POVRAY.md §1: 0.5 -> 48192 = round(65535 * sRGB(0.5)).
        let v = (srgb_encode(0.5) * 65535.0).round();
        assert_eq!(v, 48192.0);
    }

    #[test]
    fn linear16_rounds_half_up() {
        assert_eq!(to_linear16(0.5), 32768);
        assert_eq!(to_linear16(100.5 / 65535.0), 101);
        assert_eq!(to_linear16(2.0), 65535);
        assert_eq!(to_linear16(-1.0), 0);
        assert_eq!(to_linear16(f32::NAN), 0);
    }
}
