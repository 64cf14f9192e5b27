//! Shadow maps (`--shadows map:RES`): the rasterizer's own answer to the
//! visibility question, whose error against shadow rays is measured.
//!
//! A point light gets a cube map (six 90° perspective faces of RES×RES
//! texels), a parallel light one orthographic map covering the scene's
//! bounding sphere. Each texel keeps the nearest depth of an opaque,
//! shadow-casting triangle, rasterized with the shared coverage rule at
//! texel centres. A point is in shadow when its own depth exceeds the
//! stored one by more than a bias of (1.5 + 2·tan θ) texels (in world units
//! at that depth; θ between the surface's normal and the light, tan θ
//! capped at 10): a surface tilted by θ changes depth by tan θ per texel.
//! Transparent casters are ignored (a depth map cannot colour light) and
//! `no_shadow` objects cast nothing, so the map's error is: aliasing at
//! shadow edges, acne or light leaks where the bias is too small or too
//! large, and missing coloured shadows.

use rayon::prelude::*;

use super::clip::{HVert, clip_polygon, planes};
use rendiff_core::color::Rgb;
use rendiff_core::coverage::{SampleGrid, SnappedTri};
use rendiff_core::math::{DVec3, to_f64};
use rendiff_core::shade::{LightKind, ShadowQuery, Visibility};

/// Largest depth slope (tan θ) the bias follows: beyond ~84° from facing
/// the light, a wider bias would leak more light than it saves acne.
const MAX_SLOPE: f64 = 10.0;
use rendiff_core::tri_scene::TriScene;

/// One depth map with its projection.
#[derive(Debug)]
struct DepthMap {
    res: u32,
    /// Origin (light position, or the bounding sphere's centre).
    origin: DVec3,
    /// Orthonormal frame: right, up, forward.
    r: DVec3,
    u: DVec3,
    f: DVec3,
    /// Perspective (90°) or orthographic with half-size `half`.
    perspective: bool,
    half: f64,
    depth: Vec<f32>,
}

impl DepthMap {
    fn to_h(&self, p: DVec3) -> HVert {
        let rel = p - self.origin;
        let (xc, yc, zc) = (rel.dot(self.r), rel.dot(self.u), rel.dot(self.f));
        let res = f64::from(self.res);
        if self.perspective {
            HVert {
                xh: (xc + zc) * res / 2.0,
                yh: (zc - yc) * res / 2.0,
                w: zc,
                z: zc,
            }
        } else {
            HVert {
                xh: (xc / self.half + 1.0) * res / 2.0,
                yh: (1.0 - yc / self.half) * res / 2.0,
                w: 1.0,
                z: zc,
            }
        }
    }

    /// Rasterizes every caster (serially: the depth is a plain minimum,
    /// so the result does not depend on order; maps render in parallel).
    fn render(&mut self, scene: &TriScene, casters: &[u32], near: f64) {
        let res = self.res;
        let grid = SampleGrid::new(1);
        let clip = planes(near, f64::MAX, f64::from(res), f64::from(res), 65_536.0);
        let perspective = self.perspective;
        let mut poly = Vec::with_capacity(8);
        let mut tmp = Vec::with_capacity(8);
        for &t in casters {
            let v = scene.triangle(t).map(|p| self.to_h(to_f64(p)));
            poly.clear();
            poly.extend_from_slice(&v);
            for plane in &clip {
                clip_polygon(&poly, plane, &mut tmp);
                std::mem::swap(&mut poly, &mut tmp);
                if poly.len() < 3 {
                    break;
                }
            }
            if poly.len() < 3 {
                continue;
            }
            let Some(pl) = super::triangle_planes(&v, perspective, 0.0, 0.0) else {
                continue;
            };
            let screen: Vec<(f64, f64)> = poly.iter().map(HVert::screen).collect();
            for k in 1..screen.len() - 1 {
                let Some(st) = SnappedTri::new([screen[0], screen[k], screen[k + 1]]) else {
                    continue;
                };
                let depth = &mut self.depth;
                st.for_each_span(&grid, 0..res, 0..res, |row, cols| {
                    let y = f64::from(row) + 0.5;
                    for c in cols {
                        let x = f64::from(c) + 0.5;
                        let dv = super::Planes::eval(&pl.depth, x, y);
                        let z = if perspective { 1.0 / dv } else { dv };
                        #[expect(clippy::cast_possible_truncation, reason = "depth map is f32")]
                        let z = z as f32;
                        let slot = &mut depth[row as usize * res as usize + c as usize];
                        if z < *slot {
                            *slot = z;
                        }
                    }
                });
            }
        }
    }

    /// `true` when `p` is farther than the stored depth by more than the
    /// bias: 1.5 texels plus `slope` texels (in world units at that depth).
    fn shadowed(&self, p: DVec3, slope: f64) -> bool {
        let h = self.to_h(p);
        if h.w <= 0.0 {
            return false;
        }
        let (x, y) = h.screen();
        let res = f64::from(self.res);
        if !(0.0..res).contains(&x) || !(0.0..res).contains(&y) {
            return false;
        }
        #[expect(
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss,
            reason = "checked to be in [0, res)"
        )]
        let i = (y as usize) * self.res as usize + x as usize;
        let stored = f64::from(self.depth[i]);
        let texel = if self.perspective {
            2.0 * h.z / res
        } else {
            2.0 * self.half / res
        };
        h.z > stored + (1.5 + 2.0 * slope) * texel
    }
}

/// The shadow maps of every light of a scene.
#[derive(Debug)]
pub(crate) struct ShadowMaps {
    /// Per light: its maps (six cube faces, one orthographic, or none).
    maps: Vec<Vec<DepthMap>>,
    point: Vec<Option<DVec3>>,
}

impl ShadowMaps {
    /// How many maps were rendered.
    #[must_use]
    pub(crate) fn count(&self) -> usize {
        self.maps.iter().map(Vec::len).sum()
    }

    /// Renders the maps at `res`×`res` texels each.
    #[must_use]
    pub(crate) fn new(scene: &TriScene, res: u32) -> ShadowMaps {
        let casters: Vec<u32> = (0..u32::try_from(scene.len()).unwrap_or(0))
            .filter(|&t| {
                let o = &scene.objects[scene.tri_object[t as usize] as usize];
                !o.no_shadow
                    && !scene.materials[usize::from(scene.tri_material[t as usize])]
                        .is_transparent()
            })
            .collect();
        let (center, radius) = scene.bounds.bounding_sphere();
        let (center, radius) = (to_f64(center), f64::from(radius).max(1e-12));
        let near = radius * 1e-5;
        let mut maps = Vec::new();
        let mut point = Vec::new();
        for light in &scene.lights {
            if light.shadowless {
                maps.push(Vec::new());
                point.push(None);
                continue;
            }
            match light.kind {
                LightKind::Point { position } => {
                    let o = to_f64(position);
                    let faces = [
                        (DVec3::X, DVec3::Y),
                        (-DVec3::X, DVec3::Y),
                        (DVec3::Y, DVec3::Z),
                        (-DVec3::Y, -DVec3::Z),
                        (DVec3::Z, DVec3::Y),
                        (-DVec3::Z, DVec3::Y),
                    ];
                    let mut m: Vec<DepthMap> = faces
                        .iter()
                        .map(|&(f, up)| {
                            let r = f.cross(up).normalize();
                            DepthMap {
                                res,
                                origin: o,
                                r,
                                u: r.cross(f),
                                f,
                                perspective: true,
                                half: 1.0,
                                depth: vec![f32::INFINITY; (res as usize) * (res as usize)],
                            }
                        })
                        .collect();
                    m.par_iter_mut()
                        .for_each(|face| face.render(scene, &casters, near));
                    maps.push(m);
                    point.push(Some(o));
                }
                LightKind::Parallel { direction } => {
                    let f = to_f64(direction).normalize();
                    let r = f.any_orthonormal_vector();
                    let u = f.cross(r);
                    let mut m = DepthMap {
                        res,
                        origin: center - f * (radius * 1.01),
                        r,
                        u,
                        f,
                        perspective: false,
                        half: radius * 1.01,
                        depth: vec![f32::INFINITY; (res as usize) * (res as usize)],
                    };
                    m.render(scene, &casters, 0.0);
                    maps.push(vec![m]);
                    point.push(None);
                }
            }
        }
        ShadowMaps { maps, point }
    }
}

impl Visibility for ShadowMaps {
    fn transmittance(&self, q: &ShadowQuery) -> Rgb {
        let Some(maps) = self.maps.get(q.light) else {
            return Rgb::WHITE;
        };
        let p = to_f64(q.origin);
        // Slope-scaled bias: a surface at angle θ to the light spans
        // tan θ texels of depth per texel.
        let cos = f64::from(q.normal.dot(q.dir).abs()).max(1e-3);
        let slope = ((1.0 - cos * cos).sqrt() / cos).min(MAX_SLOPE);
        let light = q.light;
        let shadowed = match (self.point.get(light).copied().flatten(), maps.as_slice()) {
            (Some(o), faces) if faces.len() == 6 => {
                let q = p - o;
                let a = q.abs();
                let face = if a.x >= a.y && a.x >= a.z {
                    usize::from(q.x < 0.0)
                } else if a.y >= a.z {
                    2 + usize::from(q.y < 0.0)
                } else {
                    4 + usize::from(q.z < 0.0)
                };
                faces[face].shadowed(p, slope)
            }
            (None, [m]) => m.shadowed(p, slope),
            _ => false,
        };
        if shadowed { Rgb::BLACK } else { Rgb::WHITE }
    }
}
