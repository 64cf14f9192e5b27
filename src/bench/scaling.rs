//! `rendiff bench --scaling`: time against triangle count and against
//! resolution, for both backends, with the fitted growth.
//!
//! * Triangles: one sphere tessellated with `tessellation = N` segments
//!   (N²−N triangles, 10³ … 4·10⁶), filling the middle of a fixed-size
//!   image and lit by a shadowless light, so the covered pixels and the
//!   rays stay the same and only the triangle count changes. The ray
//!   tracer is timed in two parts: the BVH build (expected n log n) and
//!   the tracing (expected log n per ray).
//! * Pixels: a scene (by default `scenes/bunny.toml`) rendered at sizes
//!   from 160×120 to 1920×1080 (expected: linear in the pixels for both,
//!   plus the rasterizer's per-triangle setup and the ray tracer's build,
//!   which do not grow).

#![expect(
    clippy::cast_precision_loss,
    reason = "statistics over counts and sizes below 2^53, exact in f64"
)]

use std::path::PathBuf;
use std::time::Instant;

use rendiff::accel::{Accel, AccelOptions};
use rendiff::image_io::{self, ImageIoError};
use rendiff::scene::Scene;
use rendiff::{Backend, Error, GATE_EPS, Overrides, Prepared, ray};

/// What to measure.
#[derive(Clone, Debug)]
pub struct ScalingOptions {
    /// Timed runs per point (median).
    pub repeats: usize,
    /// Segment counts of the sphere (triangles ≈ N²).
    pub segments: Vec<u32>,
    /// Image size of the triangle series.
    pub size: (u32, u32),
    /// The scene of the resolution series.
    pub scene: PathBuf,
    /// Sizes of the resolution series.
    pub sizes: Vec<(u32, u32)>,
}

impl Default for ScalingOptions {
    fn default() -> Self {
        ScalingOptions {
            repeats: 5,
            segments: vec![32, 64, 128, 256, 512, 1024, 2048],
            size: (640, 480),
            scene: PathBuf::from("scenes/bunny.toml"),
            sizes: vec![
                (160, 120),
                (320, 240),
                (640, 480),
                (1280, 720),
                (1920, 1080),
            ],
        }
    }
}

/// One measured point.
#[derive(Clone, Debug, PartialEq)]
pub struct ScalingRow {
    /// `triangles` or `pixels`.
    pub series: &'static str,
    /// `raster`, `ray` (whole frame), `ray build` or `ray trace`.
    pub what: &'static str,
    /// Triangles.
    pub triangles: usize,
    /// Pixels (width × height).
    pub pixels: u64,
    /// Median wall time, milliseconds.
    pub median_ms: f64,
    /// Rays traced (ray tracer) or 0.
    pub rays: u64,
}

/// The CSV header of [`ScalingRow`]s.
pub const SCALING_HEADER: &str = "series,what,triangles,pixels,median_ms,rays";

/// A fitted power law `t = c·x^k`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PowerFit {
    /// The exponent k.
    pub exponent: f64,
    /// The coefficient of determination of the log-log line.
    pub r2: f64,
}

/// Least-squares line through `(ln x, ln y)`.
#[must_use]
pub fn fit_power(points: &[(f64, f64)]) -> PowerFit {
    let pts: Vec<(f64, f64)> = points
        .iter()
        .filter(|(x, y)| *x > 0.0 && *y > 0.0)
        .map(|(x, y)| (x.ln(), y.ln()))
        .collect();
    let (k, _, r2) = least_squares(&pts);
    PowerFit { exponent: k, r2 }
}

/// Least-squares `y = a + b·log2 x`; returns `(a, b, r²)`.
#[must_use]
pub fn fit_log2(points: &[(f64, f64)]) -> (f64, f64, f64) {
    let pts: Vec<(f64, f64)> = points
        .iter()
        .filter(|(x, _)| *x > 0.0)
        .map(|(x, y)| (x.log2(), *y))
        .collect();
    let (b, a, r2) = least_squares(&pts);
    (a, b, r2)
}

/// Slope, intercept and r² of the least-squares line.
fn least_squares(p: &[(f64, f64)]) -> (f64, f64, f64) {
    let n = p.len() as f64;
    if p.len() < 2 {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    let mx = p.iter().map(|q| q.0).sum::<f64>() / n;
    let my = p.iter().map(|q| q.1).sum::<f64>() / n;
    let sxx: f64 = p.iter().map(|q| (q.0 - mx).powi(2)).sum();
    let sxy: f64 = p.iter().map(|q| (q.0 - mx) * (q.1 - my)).sum();
    let syy: f64 = p.iter().map(|q| (q.1 - my).powi(2)).sum();
    let slope = sxy / sxx;
    let r2 = if syy > 0.0 {
        sxy * sxy / (sxx * syy)
    } else {
        1.0
    };
    (slope, my - slope * mx, r2)
}

/// The sphere scene of the triangle series.
fn sphere_scene(segments: u32, size: (u32, u32)) -> Result<Scene, Error> {
    let text = format!(
        r#"
[image]
width = {w}
height = {h}
background = [0.1, 0.1, 0.12]

[camera]
eye = [0.0, 0.0, 4.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov_y = 40.0

[[lights]]
kind = "point"
position = [3.0, 4.0, 5.0]
color = [1.0, 1.0, 1.0]
shadowless = true

[materials.clay]
pigment = [0.8, 0.7, 0.6]
phong = 0.4

[[objects]]
kind = "sphere"
material = "clay"
center = [0.0, 0.0, 0.0]
radius = 1.0
tessellation = {segments}
"#,
        w = size.0,
        h = size.1
    );
    Ok(Scene::from_str(
        &PathBuf::from(format!("scaling-sphere-{segments}.toml")),
        &text,
    )?)
}

fn median_of(mut t: Vec<f64>) -> f64 {
    t.sort_by(f64::total_cmp);
    let n = t.len();
    if n == 0 {
        return f64::NAN;
    }
    if n % 2 == 1 {
        t[n / 2]
    } else {
        0.5 * (t[n / 2 - 1] + t[n / 2])
    }
}

fn ms(start: Instant) -> f64 {
    start.elapsed().as_secs_f64() * 1e3
}

/// Runs both series; `progress(label)` after each point.
///
/// # Errors
///
/// [`Error::Load`] when the resolution scene cannot be loaded,
/// [`Error::Usage`] for bad options.
pub fn run(opts: &ScalingOptions, progress: &dyn Fn(&str)) -> Result<Vec<ScalingRow>, Error> {
    if opts.repeats == 0 {
        return Err(Error::Usage("--repeats: expected at least 1".into()));
    }
    let mut rows = Vec::new();
    let pixels = u64::from(opts.size.0) * u64::from(opts.size.1);
    for &n in &opts.segments {
        let job = Prepared::from_scene(sphere_scene(n, opts.size)?, &Overrides::default())?;
        let tris = job.tri.len();
        let raster = (0..=opts.repeats)
            .map(|_| job.render(Backend::Raster).map(|r| r.time_ms))
            .skip(1)
            .collect::<Result<_, _>>()?;
        rows.push(ScalingRow {
            series: "triangles",
            what: "raster",
            triangles: tris,
            pixels,
            median_ms: median_of(raster),
            rays: 0,
        });
        let (mut build, mut trace, mut rays) = (Vec::new(), Vec::new(), 0);
        for k in 0..=opts.repeats {
            let t0 = Instant::now();
            let accel = Accel::new(
                &job.tri,
                AccelOptions {
                    bvh: job.plan.bvh,
                    ..AccelOptions::default()
                },
            );
            let b = ms(t0);
            let t1 = Instant::now();
            let (_, stats) = ray::render_counted(
                &accel,
                &ray::RayOptions {
                    max_depth: 1,
                    shadows: job.plan.shadows,
                    gate_eps: GATE_EPS,
                },
            );
            let t = ms(t1);
            if k > 0 {
                build.push(b);
                trace.push(t);
            }
            rays = stats.primary + stats.shadow + stats.secondary;
        }
        let (build, trace) = (median_of(build), median_of(trace));
        for (what, t) in [
            ("ray build", build),
            ("ray trace", trace),
            ("ray", build + trace),
        ] {
            rows.push(ScalingRow {
                series: "triangles",
                what,
                triangles: tris,
                pixels,
                median_ms: t,
                rays,
            });
        }
        progress(&format!("{tris} triangles"));
    }
    for &(w, h) in &opts.sizes {
        let job = Prepared::load(
            &opts.scene,
            &Overrides {
                size: Some((w, h)),
                ..Overrides::default()
            },
        )?;
        for backend in [Backend::Raster, Backend::Ray] {
            let mut times = Vec::new();
            let mut rays = 0;
            for k in 0..=opts.repeats {
                let r = job.render(backend)?;
                if k > 0 {
                    times.push(r.time_ms);
                }
                if let rendiff::Work::Ray { rays: s, .. } = r.work {
                    rays = s.primary + s.shadow + s.secondary;
                }
            }
            rows.push(ScalingRow {
                series: "pixels",
                what: if backend == Backend::Raster {
                    "raster"
                } else {
                    "ray"
                },
                triangles: job.tri.len(),
                pixels: u64::from(w) * u64::from(h),
                median_ms: median_of(times),
                rays,
            });
        }
        progress(&format!("{w}x{h}"));
    }
    Ok(rows)
}

/// Least-squares `y = a + b·x`; returns `(a, b, r²)`.
#[must_use]
pub fn fit_affine(points: &[(f64, f64)]) -> (f64, f64, f64) {
    let (b, a, r2) = least_squares(points);
    (a, b, r2)
}

/// The fitted growth of each curve, as text lines: each backend's model
/// (the rasterizer affine in the triangles, the build in n·log2 n, the
/// tracing per ray in log2 n, both affine in the pixels) and the power-law
/// exponent over the upper half of the range, where fixed costs matter
/// least.
#[must_use]
pub fn fits(rows: &[ScalingRow]) -> Vec<String> {
    let mut out = Vec::new();
    let series = |series: &str, what: &str, x: fn(&ScalingRow) -> f64| -> Vec<(f64, f64)> {
        rows.iter()
            .filter(|r| r.series == series && r.what == what)
            .map(|r| (x(r), r.median_ms))
            .collect()
    };
    let upper = |pts: &[(f64, f64)]| fit_power(&pts[pts.len() / 2..]);
    let tris = |r: &ScalingRow| r.triangles as f64;
    let raster = series("triangles", "raster", tris);
    if raster.len() >= 2 {
        let (a, b, r2) = fit_affine(&raster);
        out.push(format!(
            "triangles: raster     {a:.2} ms + {:.1} ns/triangle (r² {r2:.3}); upper half ∝ n^{:.2}",
            b * 1e6,
            upper(&raster).exponent
        ));
    }
    let build = series("triangles", "ray build", tris);
    if build.len() >= 2 {
        let nlogn: Vec<(f64, f64)> = build.iter().map(|&(n, t)| (n * n.log2(), t)).collect();
        let (a, b, r2) = fit_affine(&nlogn);
        out.push(format!(
            "triangles: ray build  {a:.2} ms + {:.2} ns · n·log2 n (r² {r2:.3}); upper half ∝ n^{:.2}",
            b * 1e6,
            upper(&build).exponent
        ));
    }
    let per_ray: Vec<(f64, f64)> = rows
        .iter()
        .filter(|r| r.series == "triangles" && r.what == "ray trace" && r.rays > 0)
        .map(|r| (r.triangles as f64, r.median_ms * 1e6 / r.rays as f64))
        .collect();
    if per_ray.len() >= 2 {
        let (a, b, r2) = fit_log2(&per_ray);
        out.push(format!(
            "triangles: ray trace  {a:.1} ns + {b:.2} ns · log2 n per ray (r² {r2:.3}); {:.0} ns/ray at {:.0} triangles, {:.0} ns/ray at {:.0}",
            per_ray[0].1,
            per_ray[0].0,
            per_ray[per_ray.len() - 1].1,
            per_ray[per_ray.len() - 1].0
        ));
    }
    for what in ["raster", "ray"] {
        let pts = series("pixels", what, |r| r.pixels as f64);
        if pts.len() >= 2 {
            let (a, b, r2) = fit_affine(&pts);
            out.push(format!(
                "pixels:    {what:10} {a:.2} ms + {:.1} ns/pixel (r² {r2:.3}); upper half ∝ p^{:.2}",
                b * 1e6,
                upper(&pts).exponent
            ));
        }
    }
    out
}

/// Writes `scaling.csv` (atomically).
///
/// # Errors
///
/// [`ImageIoError::Io`] when the file cannot be written.
pub fn write_csv(rows: &[ScalingRow], path: &std::path::Path) -> Result<(), ImageIoError> {
    let mut text = String::from(SCALING_HEADER);
    text.push('\n');
    for r in rows {
        text.push_str(&format!(
            "{},{},{},{},{:.3},{}\n",
            r.series, r.what, r.triangles, r.pixels, r.median_ms, r.rays
        ));
    }
    image_io::write_atomic(path, |f| std::io::Write::write_all(f, text.as_bytes()))
}
