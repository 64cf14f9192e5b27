//! Linear RGB colour and the sRGB transfer function.
//!
//! All shading arithmetic is on [`Rgb`] (linear, `f32`); sRGB appears only
//! when an 8-bit PNG is written or read.

use std::ops::{Add, AddAssign, Mul, MulAssign, Sub};

/// A linear RGB colour (not clamped; lights may exceed 1). Plain old
/// data (three `f32`s, no padding), so a frame's colours can live in
/// memory mapped for huge pages (the frame's buffers).
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
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

/// A linear value as an 8-bit sRGB code (clamped, rounded to nearest): the
/// code [`srgb8_by_formula`] gives, found among the 255 linear values where
/// the code steps up (`srgb8_thresholds`) by eight comparisons instead of
/// a power and a floor (a frame of 76 800 pixels spent 27 M instructions in
/// the formula). `tests::the_threshold_table_is_the_formula` holds the two
/// equal around every step and on a million values between.
#[must_use]
pub fn to_srgb8(v: f32) -> u8 {
    let t = srgb8_thresholds();
    // The number of thresholds at or below v, by halving: T is sorted, so
    // v ≥ T[i + step − 1] moves past `step` of them. NaN passes none.
    let mut i = 0usize;
    for step in [128, 64, 32, 16, 8, 4, 2, 1] {
        if v >= t[i + step - 1] {
            i += step;
        }
    }
    u8::try_from(i).unwrap_or(u8::MAX)
}

/// The 8-bit sRGB code of a linear value by the formula: clamped to [0, 1],
/// encoded (sRGB's transfer function), scaled to 255 and rounded half up.
#[must_use]
#[expect(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    reason = "the value is clamped to [0, 255] before the cast"
)]
pub fn srgb8_by_formula(v: f32) -> u8 {
    (srgb_encode(v) * 255.0 + 0.5).floor().clamp(0.0, 255.0) as u8
}

/// `T[k − 1]`, k = 1 … 255: the least `f32` in [0, 1] whose code by
/// [`srgb8_by_formula`] is k or more, found once by bisection over the bit
/// patterns of [0, 1] (which order as the values do). The formula is
/// monotone where it matters: its power and its two roundings are each
/// within an ulp or so of the exact increasing function, so its code can
/// only step back within a few ulps of an exact step, which the test
/// checks exhaustively.
fn srgb8_thresholds() -> &'static [f32; 255] {
    static T: std::sync::OnceLock<[f32; 255]> = std::sync::OnceLock::new();
    T.get_or_init(|| {
        let mut t = [1.0f32; 255];
        for (k, slot) in t.iter_mut().enumerate() {
            let code = u8::try_from(k + 1).unwrap_or(u8::MAX);
            // Invariant: formula(lo) < code ≤ formula(hi).
            let (mut lo, mut hi) = (0u32, 1.0f32.to_bits());
            while hi - lo > 1 {
                let mid = lo + (hi - lo) / 2;
                if srgb8_by_formula(f32::from_bits(mid)) >= code {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            *slot = f32::from_bits(hi);
        }
        t
    })
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

    /// The table's code is the formula's at every `f32` from 0 to 1 (about
    /// 10⁹ values: run with `cargo test --release -p rendiff-core --
    /// --ignored`; 20 s on the build machine).
    #[test]
    #[ignore = "exhaustive: about 10⁹ evaluations of the formula"]
    fn the_threshold_table_is_the_formula_everywhere_in_0_1() {
        for bits in 0..=1.0f32.to_bits() {
            let v = f32::from_bits(bits);
            assert_eq!(to_srgb8(v), srgb8_by_formula(v), "{v:e}");
        }
    }

    /// The table's code is the formula's: at every `f32` within 4 096 ulps
    /// of each of the 255 steps (where a rounding could make the formula
    /// step back), at the format's edges, and at a million values spread
    /// over [0, 1] and beyond.
    #[test]
    fn the_threshold_table_is_the_formula() {
        let t = srgb8_thresholds();
        assert!(t.windows(2).all(|w| w[0] < w[1]), "the steps are sorted");
        for &step in t {
            let b = step.to_bits();
            for bits in b.saturating_sub(4096)..=b.saturating_add(4096) {
                let v = f32::from_bits(bits);
                assert_eq!(to_srgb8(v), srgb8_by_formula(v), "{v:e}");
            }
        }
        for v in [
            f32::NAN,
            f32::NEG_INFINITY,
            -1.0,
            -0.0,
            0.0,
            f32::from_bits(1),
            0.003_130_8,
            1.0,
            1.0f32.next_up(),
            2.0,
            f32::MAX,
            f32::INFINITY,
        ] {
            assert_eq!(to_srgb8(v), srgb8_by_formula(v), "{v:e}");
        }
        let mut z = 0x853c_49e6_748f_ea9bu64;
        for _ in 0..1_000_000 {
            z = z
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            let bits = u32::try_from(z >> 34).unwrap_or(0) % 0x3F90_0000;
            let v = f32::from_bits(bits);
            assert_eq!(to_srgb8(v), srgb8_by_formula(v), "{v:e}");
        }
    }

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
