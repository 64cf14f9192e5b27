//! LDR-FLIP, a perceptual difference of two images (Andersson et al.,
//! "FLIP: A Difference Evaluator for Alternating Images", HPG 2020), beside
//! SSIM in [`super::metrics`].
//!
//! FLIP models a viewer flipping between the two images at a given number
//! of pixels per degree of visual angle. Its error map, in [0, 1], is a
//! colour difference raised to a feature difference:
//!
//! 1. Both images (linear RGB, clamped to [0, 1]) go to the opponent space
//!    YCxCz and are blurred per channel by the contrast sensitivity
//!    functions of the eye (Gaussians, or a sum of two for blue–yellow,
//!    whose width follows the pixels per degree); back in linear RGB they
//!    are clamped again, moved to CIELAB with the Hunt adjustment, and
//!    compared with HyAB (|ΔL| + ‖Δab‖), raised to `q_c` and remapped to
//!    [0, 1] (the `p_c`·`c_max` knee maps to `p_t`).
//! 2. The luminance of each image is convolved with the first and second
//!    derivatives of a Gaussian (edges and points); the feature difference
//!    is the larger of the two magnitudes' differences, over √2, raised to
//!    `q_f`.
//! 3. Per pixel, FLIP = colour difference ^ (1 − feature difference).
//!
//! The reference implementation is NVlabs/flip (<https://github.com/NVlabs/flip>,
//! BSD-3-Clause, © NVIDIA); its C++ `FLIP.h` (v1.7) is where each constant
//! below was read. No code was copied: the algorithm is re-expressed here
//! with the reference's constants. Every filter is separable, as in the
//! reference (the blue–yellow sum of two Gaussians is two separable
//! passes, per the repository's `misc/separatedConvolutions.pdf`), with
//! the edge pixel repeated past the borders, as the reference does. The
//! arithmetic is `f32` in the reference's order of operations, so the maps
//! agree with its to the bit on the test pairs.
//!
//! The reference's C++ API takes linear RGB (its tool decodes sRGB PNGs
//! first); so does [`flip`]: the caller's linear values are clamped to
//! [0, 1] as the reference clamps them, with no sRGB round trip.
//!
//! `crates/rendiff/tests/data/flip/` holds synthetic pairs and the
//! reference's error maps and pooled values for them (see its README).

use rayon::prelude::*;
use serde::Serialize;

use super::maps::Picture;
use crate::color::Rgb;

/// The reference's default pixels per degree: a 0.7 m wide monitor of
/// 3840 pixels seen from 0.7 m (`FLIP::Parameters::PPD`, from
/// `calculatePPD(0.7, 3840, 0.7)` = distance · pixels / width · π/180 ≈
/// 67.02; the reference evaluates it in `f32`, 67.020645).
pub const DEFAULT_PPD: f64 = 0.7 * (3840.0 / 0.7) * std::f64::consts::PI / 180.0;

// The FLIP constants (`FLIP::xFLIPConstants` in FLIP.h, the values the
// paper gives).
/// `q_c`: the exponent on the HyAB colour difference.
const QC: f32 = 0.7;
/// `p_c`: the fraction of `c_max` where the colour remap bends.
const PC: f32 = 0.4;
/// `p_t`: the remapped value at `p_c`·`c_max`.
const PT: f32 = 0.95;
/// `w`: the peak-to-trough width, in degrees, of the edge detector (twice
/// its Gaussian's standard deviation).
const GW: f32 = 0.082;
/// `q_f`: the exponent on the feature difference.
const QF: f32 = 0.5;

/// The contrast sensitivity functions, per channel (Y, Cx, Cz), as sums of
/// two Gaussians `a · √(π/b) · exp(−π² x² / b)` in degrees
/// (`FLIP::xGaussianConstants` in FLIP.h). Y and Cx have a
/// single Gaussian (`a2` = 0; the reference sets `b2` = 1e-5 only to keep
/// the formula finite).
const CSF_A1: [f32; 3] = [1.0, 1.0, 34.1];
const CSF_B1: [f32; 3] = [0.0047, 0.0053, 0.04];
const CSF_A2: f32 = 13.5; // Cz only
const CSF_B2: f32 = 0.025; // Cz only
/// The largest scale parameter among all six `b` (`calculateSpatialFilterRadius`):
/// the filter radius is three standard deviations of that Gaussian.
const CSF_B_MAX: f32 = 0.04;

/// D65 white in XYZ and its inverse (`DEFAULT_ILLUMINANT`,
/// `INV_DEFAULT_ILLUMINANT` in FLIP.h), as the reference writes them.
#[expect(
    clippy::excessive_precision,
    reason = "the digits as FLIP.h writes them; they round to the same f32"
)]
const WHITE: [f32; 3] = [0.950_428_545, 1.0, 1.088_900_371];
#[expect(
    clippy::excessive_precision,
    reason = "the digits as FLIP.h writes them; they round to the same f32"
)]
const INV_WHITE: [f32; 3] = [1.052_156_925, 1.0, 0.918_357_670];

/// Linear sRGB (D65) to XYZ (`color3::LinearRGBToXYZ`, after
/// image-engineering.de's technote 958), as fractions evaluated in `f32`
/// as the reference evaluates them.
#[rustfmt::skip]
const RGB_TO_XYZ: [[f32; 3]; 3] = [
    [10_135_552.0 / 24_577_794.0, 8_788_810.0 / 24_577_794.0, 4_435_075.0 / 24_577_794.0],
    [2_613_072.0 / 12_288_897.0, 8_788_810.0 / 12_288_897.0, 887_015.0 / 12_288_897.0],
    [1_425_312.0 / 73_733_382.0, 8_788_810.0 / 73_733_382.0, 70_074_185.0 / 73_733_382.0],
];
/// Its inverse, as the reference rounds it (`color3::XYZToLinearRGB`).
#[expect(
    clippy::excessive_precision,
    reason = "the digits as FLIP.h writes them; they round to the same f32"
)]
#[rustfmt::skip]
const XYZ_TO_RGB: [[f32; 3]; 3] = [
    [3.241_003_275, -1.537_398_934, -0.498_615_861],
    [-0.969_224_334, 1.875_930_071, 0.041_554_224],
    [0.055_639_423, -0.204_011_202, 1.057_148_933],
];

/// The largest pixels per degree [`flip`] accepts. The filters grow with
/// it (the colour filter's radius is ≈ 0.135 · ppd pixels), and 1000 is
/// already a 0.3 m wide 4K screen seen from 4.5 m.
pub const MAX_PPD: f64 = 1000.0;

/// The magma colour map of the reference's error pictures (`FLIP::MapMagma`,
/// the 256 entries of matplotlib's magma, by Nathaniel J. Smith and Stéfan
/// van der Walt, CC0), as the 8-bit sRGB codes the reference tool writes
/// (`255 · v + 0.5`, truncated).
#[rustfmt::skip]
const MAGMA: [[u8; 3]; 256] = [
    [0, 0, 4], [1, 0, 5], [1, 1, 6], [1, 1, 8],
    [2, 1, 9], [2, 2, 11], [2, 2, 13], [3, 3, 15],
    [3, 3, 18], [4, 4, 20], [5, 4, 22], [6, 5, 24],
    [6, 5, 26], [7, 6, 28], [8, 7, 30], [9, 7, 32],
    [10, 8, 34], [11, 9, 36], [12, 9, 38], [13, 10, 41],
    [14, 11, 43], [16, 11, 45], [17, 12, 47], [18, 13, 49],
    [19, 13, 52], [20, 14, 54], [21, 14, 56], [22, 15, 59],
    [24, 15, 61], [25, 16, 63], [26, 16, 66], [28, 16, 68],
    [29, 17, 71], [30, 17, 73], [32, 17, 75], [33, 17, 78],
    [34, 17, 80], [36, 18, 83], [37, 18, 85], [39, 18, 88],
    [41, 17, 90], [42, 17, 92], [44, 17, 95], [45, 17, 97],
    [47, 17, 99], [49, 17, 101], [51, 16, 103], [52, 16, 105],
    [54, 16, 107], [56, 16, 108], [57, 15, 110], [59, 15, 112],
    [61, 15, 113], [63, 15, 114], [64, 15, 116], [66, 15, 117],
    [68, 15, 118], [69, 16, 119], [71, 16, 120], [73, 16, 120],
    [74, 16, 121], [76, 17, 122], [78, 17, 123], [79, 18, 123],
    [81, 18, 124], [82, 19, 124], [84, 19, 125], [86, 20, 125],
    [87, 21, 126], [89, 21, 126], [90, 22, 126], [92, 22, 127],
    [93, 23, 127], [95, 24, 127], [96, 24, 128], [98, 25, 128],
    [100, 26, 128], [101, 26, 128], [103, 27, 128], [104, 28, 129],
    [106, 28, 129], [107, 29, 129], [109, 29, 129], [110, 30, 129],
    [112, 31, 129], [114, 31, 129], [115, 32, 129], [117, 33, 129],
    [118, 33, 129], [120, 34, 129], [121, 34, 130], [123, 35, 130],
    [124, 35, 130], [126, 36, 130], [128, 37, 130], [129, 37, 129],
    [131, 38, 129], [132, 38, 129], [134, 39, 129], [136, 39, 129],
    [137, 40, 129], [139, 41, 129], [140, 41, 129], [142, 42, 129],
    [144, 42, 129], [145, 43, 129], [147, 43, 128], [148, 44, 128],
    [150, 44, 128], [152, 45, 128], [153, 45, 128], [155, 46, 127],
    [156, 46, 127], [158, 47, 127], [160, 47, 127], [161, 48, 126],
    [163, 48, 126], [165, 49, 126], [166, 49, 125], [168, 50, 125],
    [170, 51, 125], [171, 51, 124], [173, 52, 124], [174, 52, 123],
    [176, 53, 123], [178, 53, 123], [179, 54, 122], [181, 54, 122],
    [183, 55, 121], [184, 55, 121], [186, 56, 120], [188, 57, 120],
    [189, 57, 119], [191, 58, 119], [192, 58, 118], [194, 59, 117],
    [196, 60, 117], [197, 60, 116], [199, 61, 115], [200, 62, 115],
    [202, 62, 114], [204, 63, 113], [205, 64, 113], [207, 64, 112],
    [208, 65, 111], [210, 66, 111], [211, 67, 110], [213, 68, 109],
    [214, 69, 108], [216, 69, 108], [217, 70, 107], [219, 71, 106],
    [220, 72, 105], [222, 73, 104], [223, 74, 104], [224, 76, 103],
    [226, 77, 102], [227, 78, 101], [228, 79, 100], [229, 80, 100],
    [231, 82, 99], [232, 83, 98], [233, 84, 98], [234, 86, 97],
    [235, 87, 96], [236, 88, 96], [237, 90, 95], [238, 91, 94],
    [239, 93, 94], [240, 95, 94], [241, 96, 93], [242, 98, 93],
    [242, 100, 92], [243, 101, 92], [244, 103, 92], [244, 105, 92],
    [245, 107, 92], [246, 108, 92], [246, 110, 92], [247, 112, 92],
    [247, 114, 92], [248, 116, 92], [248, 118, 92], [249, 120, 93],
    [249, 121, 93], [249, 123, 93], [250, 125, 94], [250, 127, 94],
    [250, 129, 95], [251, 131, 95], [251, 133, 96], [251, 135, 97],
    [252, 137, 97], [252, 138, 98], [252, 140, 99], [252, 142, 100],
    [252, 144, 101], [253, 146, 102], [253, 148, 103], [253, 150, 104],
    [253, 152, 105], [253, 154, 106], [253, 155, 107], [254, 157, 108],
    [254, 159, 109], [254, 161, 110], [254, 163, 111], [254, 165, 113],
    [254, 167, 114], [254, 169, 115], [254, 170, 116], [254, 172, 118],
    [254, 174, 119], [254, 176, 120], [254, 178, 122], [254, 180, 123],
    [254, 182, 124], [254, 183, 126], [254, 185, 127], [254, 187, 129],
    [254, 189, 130], [254, 191, 132], [254, 193, 133], [254, 194, 135],
    [254, 196, 136], [254, 198, 138], [254, 200, 140], [254, 202, 141],
    [254, 204, 143], [254, 205, 144], [254, 207, 146], [254, 209, 148],
    [254, 211, 149], [254, 213, 151], [254, 215, 153], [254, 216, 154],
    [253, 218, 156], [253, 220, 158], [253, 222, 160], [253, 224, 161],
    [253, 226, 163], [253, 227, 165], [253, 229, 167], [253, 231, 169],
    [253, 233, 170], [253, 235, 172], [252, 236, 174], [252, 238, 176],
    [252, 240, 178], [252, 242, 180], [252, 244, 182], [252, 246, 184],
    [252, 247, 185], [252, 249, 187], [252, 251, 189], [252, 253, 191],
];

/// The pooled values of a FLIP error map, as the reference tool reports
/// them (`flip` prints the mean, the weighted median, the weighted 1st and
/// 3rd quartiles, the minimum and the maximum), and two plain percentiles.
///
/// A weighted percentile `p` weights each pixel by its own error: it is the
/// smallest error at which the sorted running sum of errors exceeds `p` of
/// their total (FLIP's `pooling::getPercentile(p, true)`), so it tells
/// where the error mass lies, not where most pixels are. It is 0 for an
/// error-free map.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct FlipStats {
    /// Mean error.
    pub mean: f64,
    /// Weighted median.
    pub weighted_median: f64,
    /// Weighted 1st quartile.
    pub weighted_first_quartile: f64,
    /// Weighted 3rd quartile.
    pub weighted_third_quartile: f64,
    /// Smallest error.
    pub min: f64,
    /// Largest error.
    pub max: f64,
    /// Median of the errors (the sorted value at index ⌈n/2⌉, as the
    /// reference's unweighted `getPercentile` indexes).
    pub median: f64,
    /// 95th percentile (index ⌈0.95 n⌉, clamped to the last).
    pub p95: f64,
}

/// Why [`flip`] refused its input.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum FlipError {
    /// An image does not have `width × height` pixels.
    #[error("FLIP needs two {width}×{height} images, got {reference} and {test} pixels")]
    Size {
        /// The stated width.
        width: u32,
        /// The stated height.
        height: u32,
        /// Pixels in the reference.
        reference: usize,
        /// Pixels in the test image.
        test: usize,
    },
    /// The pixels per degree are not finite or not in (0, [`MAX_PPD`]].
    #[error("FLIP needs pixels per degree in (0, {MAX_PPD}], got {0}")]
    Ppd(f64),
}

/// LDR-FLIP between a reference and a test image of `width × height`
/// linear-RGB pixels (row-major), for a viewer at `pixels_per_degree`
/// ([`DEFAULT_PPD`] is the reference's default). Channels are clamped to
/// [0, 1] (NaN counts as 0, as in the reference). Returns the per-pixel
/// error map, in [0, 1] and row-major, and its pooled values.
///
/// The map is symmetric: each image is filtered on its own and the two are
/// compared by distances (HyAB, absolute differences of feature
/// magnitudes), so swapping `reference` and `test` gives the same map, bit
/// for bit.
///
/// # Errors
///
/// [`FlipError::Size`] when a slice is not `width × height` long,
/// [`FlipError::Ppd`] when `pixels_per_degree` is out of range.
pub fn flip(
    reference: &[Rgb],
    test: &[Rgb],
    width: u32,
    height: u32,
    pixels_per_degree: f64,
) -> Result<(Vec<f32>, FlipStats), FlipError> {
    let (w, h) = (width as usize, height as usize);
    let n = w.checked_mul(h);
    if n != Some(reference.len()) || n != Some(test.len()) {
        return Err(FlipError::Size {
            width,
            height,
            reference: reference.len(),
            test: test.len(),
        });
    }
    if !(pixels_per_degree > 0.0 && pixels_per_degree <= MAX_PPD) {
        return Err(FlipError::Ppd(pixels_per_degree));
    }
    if w == 0 || h == 0 {
        return Ok((Vec::new(), FlipStats::default()));
    }
    let filters = Filters::new(pixels_per_degree);
    let (ref_ycc, test_ycc) = (to_ycxcz(reference), to_ycxcz(test));
    let (ref_lab, test_lab) = rayon::join(
        || filters.perceived(&ref_ycc, w),
        || filters.perceived(&test_ycc, w),
    );
    let (ref_feat, test_feat) = rayon::join(
        || filters.features(&ref_ycc[0], w),
        || filters.features(&test_ycc[0], w),
    );
    let cmax = hyab(
        hunt(xyz_to_lab(rgb_to_xyz([0.0, 1.0, 0.0]))),
        hunt(xyz_to_lab(rgb_to_xyz([0.0, 0.0, 1.0]))),
    )
    .powf(QC);
    let pccmax = PC * cmax;
    let errors: Vec<f32> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let c = hyab(ref_lab[i], test_lab[i]).powf(QC);
            let colour = if c < pccmax {
                c * (PT / pccmax)
            } else {
                PT + (c - pccmax) / (cmax - pccmax) * (1.0 - PT)
            };
            let edge = (ref_feat.0[i] - test_feat.0[i]).abs();
            let point = (ref_feat.1[i] - test_feat.1[i]).abs();
            let feature = (std::f32::consts::FRAC_1_SQRT_2 * edge.max(point)).powf(QF);
            colour.powf(1.0 - feature)
        })
        .collect();
    let stats = pool(&errors);
    Ok((errors, stats))
}

/// The pooled values of an error map (see [`FlipStats`]); all 0 when it is
/// empty.
#[must_use]
pub fn pool(errors: &[f32]) -> FlipStats {
    if errors.is_empty() {
        return FlipStats::default();
    }
    let mut sorted: Vec<f64> = errors.iter().map(|&e| f64::from(e)).collect();
    sorted.sort_by(f64::total_cmp);
    let total: f64 = sorted.iter().sum();
    let weighted = |p: f64| {
        let mut running = 0.0;
        for &v in &sorted {
            running += v;
            if running > p * total {
                return v;
            }
        }
        0.0
    };
    let ranked = |p: f64| {
        #[expect(
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss,
            clippy::cast_precision_loss,
            reason = "an index at most the length, of a map below 2^32 pixels"
        )]
        let i = ((p * sorted.len() as f64).ceil() as usize).min(sorted.len() - 1);
        sorted[i]
    };
    #[expect(clippy::cast_precision_loss, reason = "a pixel count below 2^32")]
    let n = sorted.len() as f64;
    FlipStats {
        mean: total / n,
        weighted_median: weighted(0.5),
        weighted_first_quartile: weighted(0.25),
        weighted_third_quartile: weighted(0.75),
        min: sorted[0],
        max: sorted[sorted.len() - 1],
        median: ranked(0.5),
        p95: ranked(0.95),
    }
}

/// The error map as the reference tool pictures it: each error `e`
/// (clamped to [0, 1]) coloured by entry `⌊255 e + 0.5⌋` of the magma map.
/// `None` when `errors` is not `width × height` long.
#[must_use]
pub fn magma_picture(width: u32, height: u32, errors: &[f32]) -> Option<Picture> {
    if (width as usize).checked_mul(height as usize) != Some(errors.len()) {
        return None;
    }
    let rgba = errors
        .iter()
        .flat_map(|&e| {
            let e = if e > 0.0 { e.min(1.0) } else { 0.0 };
            #[expect(
                clippy::cast_possible_truncation,
                clippy::cast_sign_loss,
                reason = "e is in [0, 1], so the index is in 0..=255"
            )]
            let c = MAGMA[(e * 255.0 + 0.5) as usize];
            [c[0], c[1], c[2], 255]
        })
        .collect();
    Some(Picture {
        width,
        height,
        rgba,
    })
}

/// The separable filters for one pixels-per-degree.
struct Filters {
    /// The achromatic (Y) and red–green (Cx) contrast sensitivity
    /// filters, each summing to 1.
    y: Vec<f32>,
    cx: Vec<f32>,
    /// The blue–yellow filter's two Gaussians, each the square root of its
    /// 2D Gaussian's separable factor, scaled together so the 2D sum
    /// `Σ cz1 ⊗ cz1 + Σ cz2 ⊗ cz2` is 1.
    cz1: Vec<f32>,
    cz2: Vec<f32>,
    /// The feature detector: a Gaussian summing to 1, and its first and
    /// second derivatives with positive weights summing to 1 and negative
    /// ones to −1 (`setFeatureFilter`).
    g: Vec<f32>,
    dg: Vec<f32>,
    ddg: Vec<f32>,
}

impl Filters {
    /// The filters for `ppd` pixels per degree, evaluated in `f32` in the
    /// reference's order of operations (`setSpatialFilters`,
    /// `setFeatureFilter`), so the weights agree with its to the last bit
    /// or two: the colour difference of two nearly equal blurred colours
    /// is a cancellation, and `x^0.7` amplifies it near 0.
    fn new(ppd: f64) -> Filters {
        #[expect(
            clippy::cast_possible_truncation,
            reason = "the reference takes the pixels per degree as f32"
        )]
        let ppd = ppd as f32;
        let pi = std::f32::consts::PI;
        let pi2 = pi * pi;
        // Three standard deviations of the widest CSF Gaussian: the one with
        // b = CSF_B_MAX has σ = √(b / 2π²) degrees.
        let spatial_r = radius(3.0 * (CSF_B_MAX / (2.0 * pi2)).sqrt() * ppd);
        let dx = 1.0 / ppd;
        let x2s: Vec<f32> = offsets(spatial_r)
            .map(|i| {
                let x = int_f32(i) * dx;
                x * x
            })
            .collect();
        // `a · √(π/b) · exp(−π² x² / b)`; the blue–yellow one as the
        // separable factor of its 2D form, a·√(π/b)·exp(−π²(x²+y²)/b) =
        // f(x)·f(y) with f = √(a·√(π/b))·exp(−π²x²/b).
        let csf = |a: f32, b: f32, root: bool| -> Vec<f32> {
            let scale = a * (pi / b).sqrt();
            let scale = if root { scale.sqrt() } else { scale };
            x2s.iter().map(|x2| scale * (-pi2 * x2 / b).exp()).collect()
        };
        let unit = |v: Vec<f32>| {
            let norm = 1.0 / v.iter().sum::<f32>();
            v.iter().map(|x| x * norm).collect::<Vec<f32>>()
        };
        let (c1, c2) = (csf(CSF_A1[2], CSF_B1[2], true), csf(CSF_A2, CSF_B2, true));
        let (s1, s2): (f32, f32) = (c1.iter().sum(), c2.iter().sum());
        let norm = 1.0 / (s1 * s1 + s2 * s2).sqrt();

        // The edge detector's Gaussian: σ = w/2 degrees, in pixels.
        let sd = 0.5 * GW * ppd;
        let feature_r = radius(3.0 * sd);
        let g: Vec<f32> = offsets(feature_r)
            .map(|i| (-(int_f32(i) * int_f32(i)) / (2.0 * sd * sd)).exp())
            .collect();
        let dg: Vec<f32> = offsets(feature_r)
            .zip(&g)
            .map(|(i, g)| -int_f32(i) * g)
            .collect();
        let ddg: Vec<f32> = offsets(feature_r)
            .zip(&g)
            .map(|(i, g)| (int_f32(i) * int_f32(i) / (sd * sd) - 1.0) * g)
            .collect();
        let signed_unit = |v: &[f32]| {
            let pos: f32 = v.iter().filter(|x| **x > 0.0).sum();
            let neg: f32 = v.iter().filter(|x| **x <= 0.0).map(|x| -x).sum();
            v.iter()
                .map(|&x| if x > 0.0 { x / pos } else { x / neg })
                .collect()
        };
        let gs: f32 = g.iter().sum();
        Filters {
            y: unit(csf(CSF_A1[0], CSF_B1[0], false)),
            cx: unit(csf(CSF_A1[1], CSF_B1[1], false)),
            cz1: c1.iter().map(|v| v * norm).collect(),
            cz2: c2.iter().map(|v| v * norm).collect(),
            g: g.iter().map(|x| x / gs).collect(),
            dg: signed_unit(&dg),
            ddg: signed_unit(&ddg),
        }
    }

    /// The image as the eye resolves it: each YCxCz channel blurred by its
    /// contrast sensitivity filter, back to linear RGB clamped to the unit
    /// cube, then in Hunt-adjusted CIELAB.
    fn perceived(&self, ycc: &[Vec<f32>; 3], w: usize) -> Vec<[f32; 3]> {
        let both = |plane: &[f32], f: &[f32]| rows_then_cols(plane, w, f, f);
        let (y, (cx, (cz1, cz2))) = rayon::join(
            || both(&ycc[0], &self.y),
            || {
                rayon::join(
                    || both(&ycc[1], &self.cx),
                    || rayon::join(|| both(&ycc[2], &self.cz1), || both(&ycc[2], &self.cz2)),
                )
            },
        );
        (0..y.len())
            .into_par_iter()
            .map(|i| {
                let rgb = xyz_to_rgb(ycxcz_to_xyz([y[i], cx[i], cz1[i] + cz2[i]]))
                    .map(|c| if c > 0.0 { c.min(1.0) } else { 0.0 });
                hunt(xyz_to_lab(rgb_to_xyz(rgb)))
            })
            .collect()
    }

    /// The edge and point magnitudes of the luminance (Y of YCxCz, scaled
    /// to [0, 1]): the gradient of the Gaussian-smoothed image and its
    /// second derivatives along x and y.
    fn features(&self, y: &[f32], w: usize) -> (Vec<f32>, Vec<f32>) {
        let yn: Vec<f32> = y.iter().map(|v| v * (1.0 / 116.0) + 16.0 / 116.0).collect();
        let (((dx, ddx), dy), ddy) = rayon::join(
            || {
                rayon::join(
                    || {
                        rayon::join(
                            || rows_then_cols(&yn, w, &self.dg, &self.g),
                            || rows_then_cols(&yn, w, &self.ddg, &self.g),
                        )
                    },
                    || rows_then_cols(&yn, w, &self.g, &self.dg),
                )
            },
            || rows_then_cols(&yn, w, &self.g, &self.ddg),
        );
        let edge = dx
            .iter()
            .zip(&dy)
            .map(|(a, b)| (a * a + b * b).sqrt())
            .collect();
        let point = ddx
            .iter()
            .zip(&ddy)
            .map(|(a, b)| (a * a + b * b).sqrt())
            .collect();
        (edge, point)
    }
}

/// Kernel offsets `−r..=r`.
fn offsets(r: i32) -> std::ops::RangeInclusive<i32> {
    -r..=r
}

/// A filter radius: `⌈v⌉` pixels (v is at most ≈ 0.135 · [`MAX_PPD`]).
#[expect(
    clippy::cast_possible_truncation,
    reason = "v is positive and below 1000 for ppd ≤ MAX_PPD"
)]
fn radius(v: f32) -> i32 {
    v.ceil() as i32
}

/// A kernel offset as `f32` (exact: offsets are below 2^24).
#[expect(clippy::cast_precision_loss, reason = "|i| ≤ 1000")]
fn int_f32(i: i32) -> f32 {
    i as f32
}

/// A `w`-wide plane convolved along rows with `fx`, then along columns
/// with `fy` (both of odd length, centred), repeating the edge pixels.
/// Each output sums its taps in the kernel's order, as the reference does.
fn rows_then_cols(src: &[f32], w: usize, fx: &[f32], fy: &[f32]) -> Vec<f32> {
    let h = src.len() / w;
    let rx = fx.len() / 2;
    let mut tmp = vec![0.0f32; src.len()];
    tmp.par_chunks_mut(w)
        .zip(src.par_chunks(w))
        .for_each(|(out, row)| {
            // The row with `rx` copies of its end pixels on each side.
            let mut pad = Vec::with_capacity(w + 2 * rx);
            pad.extend(std::iter::repeat_n(row[0], rx));
            pad.extend_from_slice(row);
            pad.extend(std::iter::repeat_n(row[w - 1], rx));
            // Tap by tap across the row (vectorisable), which keeps each
            // pixel's sum in the kernel's order.
            for (k, &kv) in fx.iter().enumerate() {
                for (o, v) in out.iter_mut().zip(&pad[k..]) {
                    *o += kv * v;
                }
            }
        });
    let ry = fy.len() / 2;
    let mut out = vec![0.0f32; src.len()];
    out.par_chunks_mut(w).enumerate().for_each(|(y, o)| {
        for (k, &kv) in fy.iter().enumerate() {
            let yy = (y + k).saturating_sub(ry).min(h - 1);
            for (a, b) in o.iter_mut().zip(&tmp[yy * w..(yy + 1) * w]) {
                *a += kv * b;
            }
        }
    });
    out
}

/// Linear RGB, clamped to [0, 1], as three YCxCz planes.
fn to_ycxcz(px: &[Rgb]) -> [Vec<f32>; 3] {
    let mut planes = [
        vec![0.0; px.len()],
        vec![0.0; px.len()],
        vec![0.0; px.len()],
    ];
    for (i, c) in px.iter().enumerate() {
        let rgb = c.to_array().map(|v| if v > 0.0 { v.min(1.0) } else { 0.0 });
        let [x, y, z] = rgb_to_xyz(rgb);
        let (x, y, z) = (x * INV_WHITE[0], y * INV_WHITE[1], z * INV_WHITE[2]);
        planes[0][i] = 116.0 * y - 16.0;
        planes[1][i] = 500.0 * (x - y);
        planes[2][i] = 200.0 * (y - z);
    }
    planes
}

fn rgb_to_xyz(c: [f32; 3]) -> [f32; 3] {
    RGB_TO_XYZ.map(|row| row[0] * c[0] + row[1] * c[1] + row[2] * c[2])
}

fn xyz_to_rgb(c: [f32; 3]) -> [f32; 3] {
    XYZ_TO_RGB.map(|row| row[0] * c[0] + row[1] * c[1] + row[2] * c[2])
}

/// YCxCz (Y = 116·y − 16, Cx = 500·(x − y), Cz = 200·(y − z) on
/// white-normalised XYZ: CIELAB without its cube root) back to XYZ.
fn ycxcz_to_xyz(c: [f32; 3]) -> [f32; 3] {
    let y = (c[0] + 16.0) / 116.0;
    let x = y + c[1] / 500.0;
    let z = y - c[2] / 200.0;
    [x * WHITE[0], y * WHITE[1], z * WHITE[2]]
}

/// CIE 1976 L*a*b* (D65), with its linear segment below (6/29)³.
fn xyz_to_lab(c: [f32; 3]) -> [f32; 3] {
    const D: f32 = 6.0 / 29.0;
    let f = |t: f32| {
        if t > D * D * D {
            t.powf(1.0 / 3.0)
        } else {
            t * (1.0 / (3.0 * D * D)) + 4.0 / 29.0
        }
    };
    let (fx, fy, fz) = (f(c[0] * INV_WHITE[0]), f(c[1]), f(c[2] * INV_WHITE[2]));
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

/// The Hunt adjustment: chroma scaled by lightness (a, b ← 0.01·L·a, 0.01·L·b).
fn hunt(lab: [f32; 3]) -> [f32; 3] {
    [lab[0], 0.01 * lab[0] * lab[1], 0.01 * lab[0] * lab[2]]
}

/// HyAB: city-block in lightness, Euclidean in the chroma plane.
fn hyab(p: [f32; 3], q: [f32; 3]) -> f32 {
    let (da, db) = (p[1] - q[1], p[2] - q[2]);
    (p[0] - q[0]).abs() + (da * da + db * db).sqrt()
}

#[cfg(test)]
#[allow(
    clippy::cast_possible_truncation,
    clippy::cast_precision_loss,
    clippy::cast_sign_loss,
    reason = "test fixtures: small generated counts and indices, where a wrong cast fails the test"
)]
mod tests {
    use std::path::{Path, PathBuf};

    use super::*;

    fn data_dir() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/flip")
    }

    /// An 8-bit sRGB PNG as linear RGB, decoded as the reference tool
    /// decodes it (`v / 255`, then `color3::sRGBToLinearRGB` in `f32`).
    fn read_png(path: &Path) -> (u32, u32, Vec<Rgb>) {
        let bytes = std::fs::read(path).expect("test image");
        let mut dec = png::Decoder::new(std::io::Cursor::new(bytes));
        dec.set_transformations(png::Transformations::EXPAND);
        let mut reader = dec.read_info().expect("png header");
        let mut buf = vec![0; reader.output_buffer_size().expect("size")];
        let info = reader.next_frame(&mut buf).expect("png data");
        assert_eq!(info.bit_depth, png::BitDepth::Eight);
        let channels = info.color_type.samples();
        let decode = |c: u8| {
            let s = f32::from(c) / 255.0;
            if s <= 0.040_45 {
                s / 12.92
            } else {
                ((s + 0.055) / 1.055).powf(2.4)
            }
        };
        let px = buf[..info.buffer_size()]
            .chunks(channels)
            .map(|p| Rgb::new(decode(p[0]), decode(p[1]), decode(p[2])))
            .collect();
        (info.width, info.height, px)
    }

    fn read_f32(path: &Path) -> Vec<f32> {
        std::fs::read(path)
            .expect("expected map")
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect()
    }

    /// The largest per-pixel difference allowed from the reference's map.
    /// Both sides compute in `f32` with the same constants, filter weights
    /// (evaluated in the same order), radii and order of each sum, and on
    /// the machine that made the data the maps agree bit for bit. What may
    /// still differ elsewhere is libm's last bit of `expf` and `powf`. How
    /// far one ulp in the weights moves the map was measured: weights
    /// computed in `f64` and rounded once (each within an ulp or two of the
    /// reference's) moved pixels by up to 5.2e-5 — at pixels of error
    /// ~1e-4, far from any change, where the colour difference is HyAB of
    /// two nearly equal blurred colours (a cancellation, ~1e-6 absolute in
    /// L*a*b*) raised to 0.7, whose slope grows without bound near 0.
    /// Hence 1e-4 absolute; a wrong formula or constant shows as 1e-3 or
    /// more on these pairs.
    const MAP_TOL: f32 = 1e-4;

    #[test]
    fn flip_matches_the_reference_implementation() {
        let dir = data_dir();
        let expected = std::fs::read_to_string(dir.join("expected.txt")).expect("expected.txt");
        let mut cases = 0;
        for line in expected.lines().filter(|l| !l.starts_with('#')) {
            let f: Vec<&str> = line.split_whitespace().collect();
            let (name, tag) = (f[0], f[1]);
            let vals: Vec<f64> = f[2..].iter().map(|v| v.parse().expect("number")).collect();
            let ppd = if tag == "default" {
                DEFAULT_PPD
            } else {
                tag.parse().expect("ppd")
            };
            let (w, h, a) = read_png(&dir.join(format!("{name}.ref.png")));
            let (_, _, b) = read_png(&dir.join(format!("{name}.test.png")));
            let want = read_f32(&dir.join(format!("{name}.{tag}.f32")));
            let (map, stats) = flip(&a, &b, w, h, ppd).expect("same sizes");
            assert_eq!(map.len(), want.len());
            let worst = map
                .iter()
                .zip(&want)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0f32, f32::max);
            eprintln!(
                "{name} at {tag} ppd: largest |Δ| {worst:e}, mean {} vs {}",
                stats.mean, vals[6]
            );
            assert!(worst <= MAP_TOL, "{name}/{tag}: a pixel differs by {worst}");
            // The mean: the maps agree bit for bit here, and the means to
            // ~1e-7, the reference summing in f32 and this in f64. 1e-6
            // allows an ulp-level libm difference (averaged over pixels, most
            // far below MAP_TOL).
            assert!(
                (stats.mean - vals[6]).abs() <= 1e-6,
                "{name}/{tag} mean {}",
                stats.mean
            );
            // The tool prints six decimals (±5e-7); a weighted percentile is
            // one pixel's value, so within MAP_TOL of the reference's when
            // both pick the same pixel.
            let tool = [
                stats.mean,
                stats.weighted_median,
                stats.weighted_first_quartile,
                stats.weighted_third_quartile,
                stats.min,
                stats.max,
            ];
            for (k, (got, want)) in tool.iter().zip(&vals[..6]).enumerate() {
                assert!(
                    (got - want).abs() <= 5e-7 + f64::from(MAP_TOL),
                    "{name}/{tag}: pooled value {k} is {got}, the tool says {want}"
                );
            }
            cases += 1;
        }
        assert_eq!(cases, 4);
    }

    fn scene(w: u32, h: u32) -> Vec<Rgb> {
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                Rgb::new(
                    0.5 + 0.4 * (x / 7.0).sin(),
                    (y / h as f32).powi(2),
                    if (x as u32 / 8 + y as u32 / 8).is_multiple_of(2) {
                        0.8
                    } else {
                        0.1
                    },
                )
            })
            .collect()
    }

    #[test]
    fn flip_of_identical_images_is_zero() {
        let a = scene(40, 30);
        let (map, stats) = flip(&a, &a, 40, 30, DEFAULT_PPD).expect("sizes");
        assert!(map.iter().all(|&e| e == 0.0));
        assert_eq!(stats, FlipStats::default());
    }

    #[test]
    fn flip_peaks_at_a_single_changed_pixel() {
        let (w, h) = (48u32, 40u32);
        for (x, y) in [(20usize, 15usize), (0, 0), (47, 39), (3, 30)] {
            let a = vec![Rgb::splat(0.4); (w * h) as usize];
            let mut b = a.clone();
            b[y * w as usize + x] = Rgb::new(0.9, 0.2, 0.4);
            let (map, stats) = flip(&a, &b, w, h, DEFAULT_PPD).expect("sizes");
            let argmax = (0..map.len())
                .max_by(|&i, &j| map[i].total_cmp(&map[j]))
                .expect("pixels");
            assert_eq!(argmax, y * w as usize + x, "peak at pixel ({x}, {y})");
            assert!(stats.max > 0.0 && stats.max <= 1.0);
            // The CSF blur spreads the error, but it stays local.
            assert!(map[(y + 15).min(39) * w as usize + (x + 15) % 48] < 0.01);
        }
    }

    #[test]
    fn flip_is_symmetric() {
        let (w, h) = (37u32, 29u32);
        let a = scene(w, h);
        let b: Vec<Rgb> = a
            .iter()
            .enumerate()
            .map(|(i, c)| {
                if i.is_multiple_of(5) {
                    Rgb::new(c.b, c.r, 1.2)
                } else {
                    *c
                }
            })
            .collect();
        for ppd in [DEFAULT_PPD, 12.5] {
            let (ab, _) = flip(&a, &b, w, h, ppd).expect("sizes");
            let (ba, _) = flip(&b, &a, w, h, ppd).expect("sizes");
            assert_eq!(ab, ba);
        }
    }

    #[test]
    fn flip_stays_within_its_range_on_extreme_pairs() {
        let (w, h) = (24u32, 24u32);
        let checker = |p: Rgb, q: Rgb| -> Vec<Rgb> {
            (0..w * h)
                .map(|i| {
                    if (i % w + i / w).is_multiple_of(2) {
                        p
                    } else {
                        q
                    }
                })
                .collect()
        };
        let green = Rgb::new(0.0, 1.0, 0.0);
        let blue = Rgb::new(0.0, 0.0, 1.0);
        let pairs = [
            (vec![Rgb::BLACK; 576], vec![Rgb::WHITE; 576]),
            (vec![green; 576], vec![blue; 576]),
            (checker(Rgb::BLACK, Rgb::WHITE), vec![Rgb::splat(0.5); 576]),
            (checker(green, blue), checker(blue, green)),
            (vec![Rgb::splat(f32::NAN); 576], vec![Rgb::splat(7.0); 576]),
        ];
        for (a, b) in &pairs {
            let (map, s) = flip(a, b, w, h, DEFAULT_PPD).expect("sizes");
            assert!(map.iter().all(|e| (0.0..=1.0).contains(e)), "{s:?}");
        }
        // Uniform green against uniform blue is c_max itself: FLIP 1.
        let (map, _) = flip(&pairs[1].0, &pairs[1].1, w, h, DEFAULT_PPD).expect("sizes");
        assert!(map.iter().all(|e| (e - 1.0).abs() < 1e-5), "{}", map[0]);
    }

    #[test]
    fn flip_refuses_bad_input() {
        let a = vec![Rgb::BLACK; 12];
        assert!(matches!(
            flip(&a, &a[..11], 4, 3, DEFAULT_PPD),
            Err(FlipError::Size { test: 11, .. })
        ));
        assert!(flip(&a, &a, 5, 3, DEFAULT_PPD).is_err());
        assert!(flip(&a, &a, u32::MAX, u32::MAX, DEFAULT_PPD).is_err());
        for ppd in [0.0, -1.0, f64::NAN, f64::INFINITY, MAX_PPD * 2.0] {
            assert!(
                matches!(flip(&a, &a, 4, 3, ppd), Err(FlipError::Ppd(p)) if p.to_bits() == ppd.to_bits())
            );
        }
        assert_eq!(
            flip(&[], &[], 0, 7, DEFAULT_PPD),
            Ok((Vec::new(), FlipStats::default()))
        );
        // A one-pixel image and the largest ppd are valid.
        let (map, _) = flip(&a[..1], &[Rgb::WHITE], 1, 1, MAX_PPD).expect("valid");
        assert!(map[0] > 0.5);
    }

    #[test]
    fn flip_default_ppd_is_the_references() {
        // FLIP::Parameters::PPD is calculatePPD(0.7, 3840, 0.7) in f32.
        assert!((DEFAULT_PPD - 67.020_645).abs() < 1e-5);
    }

    #[test]
    fn flip_pooling_weights_by_error() {
        // Eight pixels at 0.1 and one at 0.9: more than half the error mass
        // is the 0.9 pixel, so the weighted median is 0.9 while the median is 0.1.
        let mut e = vec![0.1f32; 8];
        e.push(0.9);
        let s = pool(&e);
        assert!((s.mean - 1.7 / 9.0).abs() < 1e-7);
        assert!((s.weighted_median - 0.9).abs() < 1e-7);
        assert!((s.weighted_first_quartile - 0.1).abs() < 1e-7);
        assert!((s.median - 0.1).abs() < 1e-7);
        assert!((s.p95 - 0.9).abs() < 1e-7);
        assert!((s.min - 0.1).abs() < 1e-7 && (s.max - 0.9).abs() < 1e-7);
    }

    #[test]
    fn flip_magma_picture_matches_the_map() {
        let p = magma_picture(3, 1, &[0.0, 1.0, f32::NAN]).expect("sizes");
        // The first and last entries of FLIP's MapMagma, and NaN as 0.
        assert_eq!(p.rgba, [0, 0, 4, 255, 252, 253, 191, 255, 0, 0, 4, 255]);
        assert!(magma_picture(2, 2, &[0.0; 3]).is_none());
    }

    #[test]
    fn flip_magma_picture_is_the_reference_tools() {
        let dir = data_dir();
        let (w, h, a) = read_png(&dir.join("shapes.ref.png"));
        let (_, _, b) = read_png(&dir.join("shapes.test.png"));
        let (map, _) = flip(&a, &b, w, h, DEFAULT_PPD).expect("sizes");
        let ours = magma_picture(w, h, &map).expect("sizes");
        let bytes = std::fs::read(dir.join("shapes.default.magma.png")).expect("picture");
        let mut reader = png::Decoder::new(std::io::Cursor::new(bytes))
            .read_info()
            .expect("png header");
        let mut buf = vec![0; reader.output_buffer_size().expect("size")];
        let info = reader.next_frame(&mut buf).expect("png data");
        assert_eq!(
            (info.width, info.height, info.color_type),
            (w, h, png::ColorType::Rgb)
        );
        let theirs: Vec<u8> = buf[..info.buffer_size()]
            .chunks(3)
            .flat_map(|p| [p[0], p[1], p[2], 255])
            .collect();
        assert_eq!(ours.rgba, theirs);
    }
}
