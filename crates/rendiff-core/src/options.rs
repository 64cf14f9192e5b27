//! Render settings shared by the scene file, the command line and the
//! backends: the named conventions of DESIGN.md §4–§5 as enums, never as
//! booleans.

use std::fmt;
use std::str::FromStr;

/// A value of an option that does not parse (`--depth u12`,
/// `shadows = "map:x"`): the text given and what was expected.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct ParseOptionError {
    /// The text given.
    pub got: String,
    /// What was wrong with it, and what was expected.
    pub message: String,
}

impl ParseOptionError {
    /// The error for the text `got`, with `message`.
    #[must_use]
    pub fn new(got: &str, message: String) -> ParseOptionError {
        ParseOptionError {
            got: got.to_string(),
            message,
        }
    }
}

/// A [`ParseOptionError`] for the text `s`, with a formatted message.
macro_rules! parse_error {
    ($s:expr, $($t:tt)*) => {
        ParseOptionError::new($s, format!($($t)*))
    };
}

/// The largest side of every raster rendiff makes or reads: the image
/// (DESIGN.md §4), a texture, a shadow map. In the 1/256-pixel fixed
/// point of the coverage rule a coordinate stays below 2^22 (edge
/// products far inside i64), and a texel coordinate is exact in f32.
pub const MAX_SIDE: u32 = 16_384;

/// Format of the rasterizer's depth buffer (DESIGN.md §2).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum DepthFormat {
    /// `f32` reversed-Z (perspective stores near/z).
    #[default]
    F32,
    /// 24-bit unsigned normalised.
    U24,
    /// 16-bit unsigned normalised.
    U16,
}

impl DepthFormat {
    /// Bits of an integer format (`None` for f32).
    #[must_use]
    pub fn bits(self) -> Option<u32> {
        match self {
            DepthFormat::F32 => None,
            DepthFormat::U24 => Some(24),
            DepthFormat::U16 => Some(16),
        }
    }

    /// The largest key of an integer format, `2^bits − 1`: the normalised
    /// depth `q ∈ [0, 1]` is stored as `round(q · max_key)`, so one step of
    /// `q` is `1 / max_key` (the rasterizer quantises with it, the
    /// verdict's depth resolution is derived from it). `None` for f32.
    #[must_use]
    pub fn max_key(self) -> Option<f64> {
        self.bits().map(|b| f64::from((1u32 << b) - 1))
    }
}

impl fmt::Display for DepthFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            DepthFormat::F32 => "f32",
            DepthFormat::U24 => "u24",
            DepthFormat::U16 => "u16",
        })
    }
}

impl FromStr for DepthFormat {
    type Err = ParseOptionError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "f32" => Ok(DepthFormat::F32),
            "u24" => Ok(DepthFormat::U24),
            "u16" => Ok(DepthFormat::U16),
            _ => Err(parse_error!(
                s,
                "expected \"f32\", \"u24\" or \"u16\", got \"{s}\""
            )),
        }
    }
}

/// How the rasterizer answers shadow rays.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum ShadowMode {
    /// The same shadow rays as the ray tracer (hybrid).
    #[default]
    Rays,
    /// A shadow map of the given resolution per light.
    Map(u32),
}

impl ShadowMode {
    /// Smallest shadow-map resolution.
    pub const MIN_RES: u32 = 64;
    /// Largest shadow-map resolution.
    pub const MAX_RES: u32 = MAX_SIDE;
}

impl fmt::Display for ShadowMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ShadowMode::Rays => f.write_str("rays"),
            ShadowMode::Map(r) => write!(f, "map:{r}"),
        }
    }
}

impl FromStr for ShadowMode {
    type Err = ParseOptionError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s == "rays" {
            return Ok(ShadowMode::Rays);
        }
        if let Some(r) = s.strip_prefix("map:") {
            let res: u32 = r.parse().map_err(|_| {
                parse_error!(s, "expected \"map:RES\" with an integer RES, got \"{s}\"")
            })?;
            if !(Self::MIN_RES..=Self::MAX_RES).contains(&res) {
                return Err(parse_error!(
                    s,
                    "shadow map resolution {res} is outside {} … {}",
                    Self::MIN_RES,
                    Self::MAX_RES
                ));
            }
            return Ok(ShadowMode::Map(res));
        }
        Err(parse_error!(
            s,
            "expected \"rays\" or \"map:RES\", got \"{s}\""
        ))
    }
}

/// Whether the ray tracer uses a BVH.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum BvhMode {
    /// Decided by the render plan (a flat loop for tiny scenes).
    #[default]
    Auto,
    /// Always a BVH.
    On,
    /// Always a flat loop.
    Off,
}

impl fmt::Display for BvhMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            BvhMode::Auto => "auto",
            BvhMode::On => "on",
            BvhMode::Off => "off",
        })
    }
}

impl FromStr for BvhMode {
    type Err = ParseOptionError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "auto" => Ok(BvhMode::Auto),
            "on" => Ok(BvhMode::On),
            "off" => Ok(BvhMode::Off),
            _ => Err(parse_error!(
                s,
                "expected \"auto\", \"on\" or \"off\", got \"{s}\""
            )),
        }
    }
}

/// How a BVH is built. Every build gives the same hits, bit for bit (a
/// query's answer is the least (distance, id) over the triangles the ray
/// meets, or whether it meets one, whatever the grouping); the builds
/// differ in how long they take and how fast rays walk the tree.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum BvhBuild {
    /// Binned surface area heuristic: the slower build, the faster walk.
    #[default]
    Sah,
    /// Morton order (a linear BVH): about three times faster to build, its
    /// walks 0–21 % slower, for frames that cast few rays per triangle.
    Morton,
}

/// Shadow rays toward a light per triangle that casts a shadow from which
/// a light buffer (Haines and Greenberg's grid of the triangles seen from
/// the light) pays for its build (300 to 2 000 instructions per triangle
/// and light on the bundled scenes): measured on the bundled scenes
/// (ARCHITECTURE.md, "The light buffer").
pub const LIGHT_BUFFER_RAYS_PER_TRIANGLE: u64 = 8;

/// `true` when a light toward which about `rays` shadow rays will be asked
/// gets a light buffer over `casters` casting triangles (see
/// [`LIGHT_BUFFER_RAYS_PER_TRIANGLE`]).
#[must_use]
pub fn light_buffer_pays(rays: u64, casters: u64) -> bool {
    rays > 0 && casters.saturating_mul(LIGHT_BUFFER_RAYS_PER_TRIANGLE) <= rays
}

impl BvhBuild {
    /// Below this many rays per triangle a BVH is built in Morton order.
    ///
    /// Measured on the 940 k-triangle bunny, one thread (`rendiff-peers
    /// trees`, medians of 11 rounds alternating the two trees, two runs):
    /// the build 583–617 ms by the SAH against 186–197 ms in Morton order
    /// (0.44 µs a triangle saved), primary rays 389–410 against 391–394 ms
    /// for 2 073 600 rays (within noise), shadow rays 266–281 against
    /// 243–262 ms for 551 746 rays (0.03–0.04 µs a ray more). In two
    /// `make peers` runs the Morton tree's walks took 0.99–1.08× the SAH
    /// tree's time for primary rays and 1.14–1.21× for shadow rays (up to
    /// 0.1 µs a shadow ray): the build pays back below 4.6 rays per
    /// triangle where the rays are all shadow rays, below about 30 where
    /// they are primary rays. Four keeps on the safe side of both, and of
    /// scenes whose triangles sort less well (on the bundled
    /// `textured.toml` the Morton tree's walks take 14–23 % more
    /// instructions, but its few triangles make the build negligible).
    ///
    /// Measured again once the SAH build no longer ran on subnormal
    /// floats (ARCHITECTURE.md, "Subnormal lanes"; `make peers` run 10's
    /// `trees` row): the SAH build 311.8 ms against 171.7 ms in Morton
    /// order (0.15 µs a triangle saved, no longer 0.44), shadow rays
    /// 153.8 against 164.8 ms (0.02 µs a ray more), primary rays 203.4
    /// against 222.1 ms (0.01 µs). The break-even is now 7–15 rays per
    /// triangle at these walks (it was 11–15) and 1.5 at the worst case's
    /// 0.1 µs a shadow ray (it was 4.4); four lies between them and is
    /// kept.
    pub const MORTON_BELOW_RAYS_PER_TRIANGLE: u64 = 4;

    /// The build for a tree that will answer about `rays` rays over
    /// `triangles` triangles: Morton order below
    /// [`BvhBuild::MORTON_BELOW_RAYS_PER_TRIANGLE`] rays per triangle, else
    /// the SAH.
    #[must_use]
    pub fn for_rays(rays: u64, triangles: usize) -> BvhBuild {
        let triangles = u64::try_from(triangles).unwrap_or(u64::MAX);
        if rays < triangles.saturating_mul(Self::MORTON_BELOW_RAYS_PER_TRIANGLE) {
            BvhBuild::Morton
        } else {
            BvhBuild::Sah
        }
    }
}

impl fmt::Display for BvhBuild {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            BvhBuild::Sah => "SAH",
            BvhBuild::Morton => "Morton order",
        })
    }
}

/// What geometry the ray tracer intersects.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Geometry {
    /// The triangles every backend sees.
    #[default]
    Mesh,
    /// Analytic shapes where the ray tracer has them (spheres).
    Analytic,
}

impl fmt::Display for Geometry {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Geometry::Mesh => "mesh",
            Geometry::Analytic => "analytic",
        })
    }
}

impl FromStr for Geometry {
    type Err = ParseOptionError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "mesh" => Ok(Geometry::Mesh),
            "analytic" => Ok(Geometry::Analytic),
            _ => Err(parse_error!(
                s,
                "expected \"mesh\" or \"analytic\", got \"{s}\""
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_round_trip_through_text() {
        for s in ["f32", "u24", "u16"] {
            assert_eq!(s.parse::<DepthFormat>().unwrap().to_string(), s);
        }
        for s in ["rays", "map:64", "map:2048"] {
            assert_eq!(s.parse::<ShadowMode>().unwrap().to_string(), s);
        }
        assert!("map:63".parse::<ShadowMode>().is_err());
        assert!("map:x".parse::<ShadowMode>().is_err());
        assert!("f16".parse::<DepthFormat>().is_err());
    }
}

/// How the painter orders its triangles (`--sort`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum PainterSort {
    /// By the view depth of the centroid, farthest first: the plain
    /// list-priority sort, which misorders long triangles.
    Centroid,
    /// Newell, Newell and Sancha's tests on every pair whose projections
    /// overlap (depth ranges, then each triangle's plane against the
    /// other's vertices), then a topological sort, farthest first.
    #[default]
    Newell,
}

impl fmt::Display for PainterSort {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(match self {
            PainterSort::Centroid => "centroid",
            PainterSort::Newell => "newell",
        })
    }
}

impl FromStr for PainterSort {
    type Err = ParseOptionError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "centroid" => Ok(PainterSort::Centroid),
            "newell" => Ok(PainterSort::Newell),
            _ => Err(parse_error!(
                s,
                "expected \"centroid\" or \"newell\", got \"{s}\""
            )),
        }
    }
}
