//! Image metrics: the reftest pair (largest 8-bit sRGB channel difference,
//! number of differing pixels), PSNR on linear values, and SSIM.

use crate::color::{Rgb, to_srgb8};

/// The reftest-style fuzzy pair and SSIM over pixel colours.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct ImageStats {
    /// Largest difference of an 8-bit sRGB channel.
    pub max_channel_8bit: u8,
    /// Pixels with any 8-bit channel different.
    pub differing_pixels: u64,
    /// Mean SSIM of the luminance (11×11 Gaussian window, σ = 1.5).
    pub ssim: f64,
    /// LDR-FLIP (perceptual) pooled over the pixels, at the reference's
    /// default viewing condition ([`super::flip::DEFAULT_PPD`]).
    pub flip: super::flip::FlipStats,
}

/// Compares two images of the same size (linear colours, clamped to [0, 1]);
/// also returns the FLIP map (empty if FLIP refused the input), computed
/// once for the statistics and the `flip.png` picture.
#[must_use]
pub(crate) fn image_stats(w: u32, h: u32, a: &[Rgb], b: &[Rgb]) -> (ImageStats, Vec<f32>) {
    let mut max = 0u8;
    let mut differing = 0u64;
    for (p, q) in a.iter().zip(b) {
        let (p8, q8) = (srgb8(*p), srgb8(*q));
        let d = p8
            .iter()
            .zip(&q8)
            .map(|(x, y)| x.abs_diff(*y))
            .max()
            .unwrap_or(0);
        max = max.max(d);
        if d > 0 {
            differing += 1;
        }
    }
    let (flip_map, flip) =
        super::flip::flip(b, a, w, h, super::flip::DEFAULT_PPD).unwrap_or_default();
    (
        ImageStats {
            max_channel_8bit: max,
            differing_pixels: differing,
            ssim: ssim(w, h, a, b),
            flip,
        },
        flip_map,
    )
}

fn srgb8(c: Rgb) -> [u8; 3] {
    [to_srgb8(c.r), to_srgb8(c.g), to_srgb8(c.b)]
}

/// PSNR in dB for a peak of 1.0 (linear units); ∞ for identical images.
#[must_use]
pub fn psnr(rmse: f64) -> f64 {
    if rmse <= 0.0 {
        f64::INFINITY
    } else {
        -20.0 * rmse.log10()
    }
}

/// Mean SSIM (Wang et al. 2004) of the luminance of the sRGB-encoded
/// images, with an 11×11 Gaussian window (σ = 1.5), K1 = 0.01, K2 = 0.03.
#[must_use]
pub fn ssim(w: u32, h: u32, a: &[Rgb], b: &[Rgb]) -> f64 {
    let (w, h) = (w as usize, h as usize);
    if w == 0 || h == 0 {
        return 1.0;
    }
    let lum = |c: &Rgb| {
        let s = srgb8(*c);
        (0.2126 * f64::from(s[0]) + 0.7152 * f64::from(s[1]) + 0.0722 * f64::from(s[2])) / 255.0
    };
    let la: Vec<f64> = a.iter().map(lum).collect();
    let lb: Vec<f64> = b.iter().map(lum).collect();
    let radius = 5i64;
    let kernel: Vec<f64> = (-radius..=radius)
        .map(|i| {
            #[expect(clippy::cast_precision_loss, reason = "tiny integers")]
            let x = i as f64;
            (-x * x / (2.0 * 1.5 * 1.5)).exp()
        })
        .collect();
    let ksum: f64 = kernel.iter().sum();
    let kernel: Vec<f64> = kernel.iter().map(|k| k / ksum).collect();
    // Separable blur with clamped borders.
    let blur = |img: &[f64]| -> Vec<f64> {
        let mut tmp = vec![0.0; w * h];
        let mut out = vec![0.0; w * h];
        let clampi = |v: i64, n: usize| -> usize {
            let max = i64::try_from(n).unwrap_or(i64::MAX) - 1;
            usize::try_from(v.clamp(0, max)).unwrap_or(0)
        };
        for y in 0..h {
            for x in 0..w {
                let mut s = 0.0;
                for (k, kv) in kernel.iter().enumerate() {
                    let xi = clampi(
                        i64::try_from(x).unwrap_or(0) + i64::try_from(k).unwrap_or(0) - radius,
                        w,
                    );
                    s += kv * img[y * w + xi];
                }
                tmp[y * w + x] = s;
            }
        }
        for y in 0..h {
            for x in 0..w {
                let mut s = 0.0;
                for (k, kv) in kernel.iter().enumerate() {
                    let yi = clampi(
                        i64::try_from(y).unwrap_or(0) + i64::try_from(k).unwrap_or(0) - radius,
                        h,
                    );
                    s += kv * tmp[yi * w + x];
                }
                out[y * w + x] = s;
            }
        }
        out
    };
    let prod = |p: &[f64], q: &[f64]| p.iter().zip(q).map(|(x, y)| x * y).collect::<Vec<f64>>();
    let ma = blur(&la);
    let mb = blur(&lb);
    let saa = blur(&prod(&la, &la));
    let sbb = blur(&prod(&lb, &lb));
    let sab = blur(&prod(&la, &lb));
    let (c1, c2) = (0.01f64.powi(2), 0.03f64.powi(2));
    let mut total = 0.0;
    for i in 0..w * h {
        let (mua, mub) = (ma[i], mb[i]);
        let va = saa[i] - mua * mua;
        let vb = sbb[i] - mub * mub;
        let cov = sab[i] - mua * mub;
        total += ((2.0 * mua * mub + c1) * (2.0 * cov + c2))
            / ((mua * mua + mub * mub + c1) * (va + vb + c2));
    }
    #[expect(clippy::cast_precision_loss, reason = "pixel counts below 2^28")]
    let n = (w * h) as f64;
    total / n
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

    #[test]
    fn identical_images_are_perfect() {
        let a: Vec<Rgb> = (0..64).map(|i| Rgb::splat(i as f32 / 64.0)).collect();
        let (s, _) = image_stats(8, 8, &a, &a);
        assert_eq!(s.max_channel_8bit, 0);
        assert_eq!(s.differing_pixels, 0);
        assert!((s.ssim - 1.0).abs() < 1e-12);
        assert_eq!(psnr(0.0), f64::INFINITY);
        assert!((psnr(0.1) - 20.0).abs() < 1e-12);
    }

    #[test]
    fn a_changed_pixel_is_counted() {
        let a = vec![Rgb::splat(0.5); 100];
        let mut b = a.clone();
        b[42] = Rgb::new(0.5, 0.6, 0.5);
        let (s, _) = image_stats(10, 10, &a, &b);
        assert_eq!(s.differing_pixels, 1);
        assert!(s.max_channel_8bit > 0);
        assert!(s.ssim < 1.0);
    }
}
