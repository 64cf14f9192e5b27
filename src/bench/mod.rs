//! `rendiff bench`: run time against error.
//!
//! For each scene, one setting at a time is swept away from the scene's
//! own — tessellation error, samples, depth format, shadow rays against
//! shadow-map resolutions, `max_depth`, the plan, the thread count — and
//! each setting is rendered once for its error and `repeats` times for its
//! median wall time. The error is measured against the best reference
//! available for what the sweep changes:
//!
//! * settings that keep the sample points and the triangles (depth format,
//!   shadows, `max_depth`, plan, threads): the scene's POV-Ray reference in
//!   `golden/pov` (`NAME.d1.png` for the rasterizer where the scene has a
//!   ray tree, since it shades locally), when it exists, is current and has
//!   the size being rendered;
//! * tessellation: POV-Ray's analytic reference (the true curved
//!   surfaces), where it exists and the backend traces the same ray tree;
//! * samples: a converged render, since more samples estimate a different
//!   quantity (the pixel's mean) than one sample does;
//!
//! and otherwise a high-quality ray-traced render: 8×8 samples for the
//! samples sweep, a tessellation error of 0.05 px (analytic spheres) for
//! the tessellation sweep, the scene's own settings for the rest. Each row
//! of `results.csv` names its reference.
//!
//! The error is the mean over pixels of the largest 8-bit sRGB channel
//! difference (`mae8`, in 1/255), with the share of pixels beyond 2/255
//! and the largest difference.

pub mod plot;
pub mod scaling;

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use rendiff::color::{Rgb, to_srgb8};
use rendiff::image_io::{self, ImageIoError};
use rendiff::options::{DepthFormat, Geometry, ShadowMode};
use rendiff::pov::golden::{self, Variant};
use rendiff::scene::{Scene, Shape};
use rendiff::{Backend, Error, Overrides, Prepared, Work};

/// A setting that trades time for error.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Sweep {
    /// `tessellation_error` in pixels (scenes with curved shapes).
    Tessellation,
    /// Samples per pixel side.
    Samples,
    /// The rasterizer's depth format.
    Depth,
    /// The rasterizer's shadow rays against shadow maps.
    Shadows,
    /// The ray tracer's `max_depth` (scenes with a ray tree).
    MaxDepth,
    /// The render plan on and off.
    Plan,
    /// Worker threads.
    Threads,
}

impl Sweep {
    /// Every sweep, in report order.
    pub const ALL: [Sweep; 7] = [
        Sweep::Tessellation,
        Sweep::Samples,
        Sweep::Depth,
        Sweep::Shadows,
        Sweep::MaxDepth,
        Sweep::Plan,
        Sweep::Threads,
    ];

    /// The name used on the command line and in `results.csv`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Sweep::Tessellation => "tessellation",
            Sweep::Samples => "samples",
            Sweep::Depth => "depth",
            Sweep::Shadows => "shadows",
            Sweep::MaxDepth => "max_depth",
            Sweep::Plan => "plan",
            Sweep::Threads => "threads",
        }
    }
}

impl FromStr for Sweep {
    type Err = String;
    fn from_str(s: &str) -> Result<Sweep, String> {
        Sweep::ALL
            .into_iter()
            .find(|w| w.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = Sweep::ALL.iter().map(|w| w.name()).collect();
                format!(
                    "unknown sweep \"{s}\"; expected one of {}",
                    names.join(", ")
                )
            })
    }
}

/// What to run.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// Timed runs per setting (the median is reported); one more untimed
    /// run gives the error and warms the caches.
    pub repeats: usize,
    /// The sweeps to run.
    pub sweeps: Vec<Sweep>,
    /// `--size`: render at this size instead of the scene's.
    pub size: Option<(u32, u32)>,
    /// Thread counts of the thread sweep.
    pub threads: Vec<usize>,
    /// Fewer settings per sweep (for tests and a first look).
    pub quick: bool,
    /// Where the POV-Ray references are.
    pub golden_dir: PathBuf,
}

impl Default for BenchOptions {
    fn default() -> Self {
        let max = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
        let mut threads: Vec<usize> = std::iter::successors(Some(1usize), |t| Some(t * 2))
            .take_while(|&t| t < max)
            .collect();
        threads.push(max);
        BenchOptions {
            repeats: 5,
            sweeps: Sweep::ALL.to_vec(),
            size: None,
            threads,
            quick: false,
            golden_dir: PathBuf::from("golden/pov"),
        }
    }
}

/// One measured setting: a row of `results.csv`.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// Scene name.
    pub scene: String,
    /// Backend.
    pub backend: Backend,
    /// The sweep this row belongs to.
    pub sweep: Sweep,
    /// The swept value.
    pub setting: String,
    /// Worker threads.
    pub threads: usize,
    /// Triangles rendered.
    pub triangles: usize,
    /// Image size.
    pub size: (u32, u32),
    /// Samples per pixel side.
    pub samples: u32,
    /// Timed runs.
    pub runs: usize,
    /// Median wall time of the render (acceleration structures included),
    /// milliseconds.
    pub median_ms: f64,
    /// Fastest run.
    pub min_ms: f64,
    /// Slowest run.
    pub max_ms: f64,
    /// The reference of the error columns.
    pub reference: String,
    /// Mean over pixels of the largest 8-bit sRGB channel difference.
    pub mae8: f64,
    /// Share of pixels more than 2/255 off, in percent.
    pub beyond2_pct: f64,
    /// Largest 8-bit difference.
    pub max8: u8,
    /// Rays cast (ray tracer: primary + shadow + secondary; rasterizer:
    /// shadow rays).
    pub rays: u64,
}

/// The CSV header of [`Row`]s.
pub const CSV_HEADER: &str = "scene,backend,sweep,setting,threads,triangles,width,height,samples,runs,median_ms,min_ms,max_ms,reference,mae8,beyond2_pct,max8,rays";

impl Row {
    /// The row as a CSV line (no field needs quoting: names are file stems
    /// and settings have no commas).
    #[must_use]
    pub fn csv(&self) -> String {
        format!(
            "{},{},{},{},{},{},{},{},{},{},{:.3},{:.3},{:.3},{},{:.5},{:.4},{},{}",
            csv_field(&self.scene),
            self.backend,
            self.sweep.name(),
            csv_field(&self.setting),
            self.threads,
            self.triangles,
            self.size.0,
            self.size.1,
            self.samples,
            self.runs,
            self.median_ms,
            self.min_ms,
            self.max_ms,
            csv_field(&self.reference),
            self.mae8,
            self.beyond2_pct,
            self.max8,
            self.rays
        )
    }
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// The error of an image against a reference of the same size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImageError {
    /// Mean over pixels of the largest 8-bit channel difference.
    pub mae8: f64,
    /// Share of pixels more than 2/255 off, in percent.
    pub beyond2_pct: f64,
    /// Largest 8-bit difference.
    pub max8: u8,
}

/// Measures `image` against `reference` in 8-bit sRGB.
#[must_use]
#[expect(
    clippy::cast_precision_loss,
    reason = "statistics over counts and sizes below 2^53, exact in f64"
)]
pub fn image_error(image: &[Rgb], reference: &[Rgb]) -> ImageError {
    let mut sum = 0u64;
    let mut beyond = 0usize;
    let mut max8 = 0u8;
    for (p, q) in image.iter().zip(reference) {
        let d = [(p.r, q.r), (p.g, q.g), (p.b, q.b)]
            .iter()
            .map(|(x, y)| to_srgb8(*x).abs_diff(to_srgb8(*y)))
            .max()
            .unwrap_or(0);
        sum += u64::from(d);
        beyond += usize::from(d > 2);
        max8 = max8.max(d);
    }
    let n = image.len().max(1) as f64;
    ImageError {
        mae8: sum as f64 / n,
        beyond2_pct: beyond as f64 / n * 100.0,
        max8,
    }
}

/// One setting of one scene to measure.
#[derive(Clone, Debug)]
struct Case {
    backend: Backend,
    sweep: Sweep,
    setting: String,
    ov: Overrides,
    tessellation_error: Option<f64>,
    threads: Option<usize>,
    reference: RefKind,
}

impl Case {
    /// What determines the measurement (equal keys are measured once).
    fn key(&self) -> String {
        format!(
            "{} {:?} {:?} {:?}",
            self.backend, self.ov, self.tessellation_error, self.threads
        )
    }
}

/// Which reference a case is measured against.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum RefKind {
    /// The scene's own sample points and triangles.
    Main,
    /// The true curved surfaces.
    Surface,
    /// The pixel means.
    Converged,
}

/// A bench run over several scenes: the cases are known before anything
/// renders, so a progress bar can show the total.
#[derive(Debug)]
pub struct Bench {
    scenes: Vec<(Scene, Vec<Case>)>,
    opts: BenchOptions,
}

/// Tessellation errors of the tessellation sweep, in pixels.
const TESSELLATION: [f64; 6] = [4.0, 2.0, 1.0, 0.5, 0.25, 0.1];
/// Tessellation error of the high-quality reference render, in pixels.
const FINE_TESSELLATION: f64 = 0.05;
/// Samples per pixel side of the converged reference.
const CONVERGED_SAMPLES: u32 = 8;

impl Bench {
    /// Loads the scenes and lists every case.
    ///
    /// # Errors
    ///
    /// [`Error::Load`] for a bad scene, [`Error::Usage`] for bad options.
    pub fn new(paths: &[PathBuf], opts: BenchOptions) -> Result<Bench, Error> {
        if opts.repeats == 0 {
            return Err(Error::Usage("--repeats: expected at least 1".into()));
        }
        if opts.threads.contains(&0) {
            return Err(Error::Usage(
                "--threads: expected counts of at least 1".into(),
            ));
        }
        let mut scenes = Vec::new();
        for p in paths {
            let scene = Scene::load(p)?;
            let base = Prepared::from_scene(scene.clone(), &base_overrides(&opts))?;
            let cases = cases(&scene, &base, &opts);
            scenes.push((scene, cases));
        }
        Ok(Bench { scenes, opts })
    }

    /// How many settings will be measured.
    #[must_use]
    pub fn len(&self) -> usize {
        self.scenes.iter().map(|(_, c)| c.len()).sum()
    }

    /// `true` when there is nothing to measure.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Runs every case; `progress(label)` is called after each.
    ///
    /// The settings of one sweep are timed in rounds — each round renders
    /// every setting once, after an untimed render of the same setting —
    /// so a slow drift of the machine (other load, clock changes) affects
    /// them alike instead of whichever came last.
    ///
    /// # Errors
    ///
    /// [`Error::Usage`] when a thread pool cannot be made; scene errors.
    pub fn run(&self, progress: &(dyn Fn(&str) + Sync)) -> Result<Vec<Row>, Error> {
        let mut rows = Vec::new();
        for (scene, cases) in &self.scenes {
            let mut refs: HashMap<(Backend, RefKind), (String, Vec<Rgb>)> = HashMap::new();
            let mut measured: HashMap<String, Row> = HashMap::new();
            let mut sweeps: Vec<Sweep> = cases.iter().map(|c| c.sweep).collect();
            sweeps.dedup();
            for sweep in sweeps {
                let group: Vec<&Case> = cases.iter().filter(|c| c.sweep == sweep).collect();
                // Settings not measured before (the scene's own settings
                // recur across sweeps).
                let mut fresh: Vec<&Case> = Vec::new();
                for c in &group {
                    if !measured.contains_key(&c.key()) && !fresh.iter().any(|f| f.key() == c.key())
                    {
                        fresh.push(c);
                    }
                }
                for c in &fresh {
                    let key = (c.backend, c.reference);
                    if let std::collections::hash_map::Entry::Vacant(e) = refs.entry(key) {
                        e.insert(self.reference(scene, c.backend, c.reference)?);
                    }
                }
                let runs: Vec<Runner> = fresh
                    .iter()
                    .map(|c| Runner::new(scene, c))
                    .collect::<Result<_, _>>()?;
                // One untimed render each: the error, and warm caches.
                let mut partial: Vec<Row> = Vec::new();
                for (c, r) in fresh.iter().zip(&runs) {
                    let (ref_label, ref_pixels) = &refs[&(c.backend, c.reference)];
                    partial.push(r.first_row(scene, c, ref_label, ref_pixels)?);
                }
                // Each timed render follows an untimed one of the same
                // setting, so what the previous setting left in the caches
                // and the allocator (a 4096² shadow map frees 400 MB) is
                // not charged to this one.
                let mut times = vec![Vec::with_capacity(self.opts.repeats); runs.len()];
                for _ in 0..self.opts.repeats {
                    for (k, r) in runs.iter().enumerate() {
                        if runs.len() > 1 {
                            r.render()?;
                        }
                        times[k].push(r.render()?.time_ms);
                    }
                }
                for ((c, mut row), mut t) in fresh.iter().zip(partial).zip(times) {
                    t.sort_by(f64::total_cmp);
                    row.runs = t.len();
                    row.median_ms = median(&t);
                    row.min_ms = t[0];
                    row.max_ms = t[t.len() - 1];
                    measured.insert(c.key(), row);
                }
                for c in group {
                    let row = Row {
                        sweep: c.sweep,
                        setting: c.setting.clone(),
                        ..measured[&c.key()].clone()
                    };
                    progress(&format!(
                        "{} {} {}={}",
                        scene.name(),
                        c.backend,
                        c.sweep.name(),
                        c.setting
                    ));
                    rows.push(row);
                }
            }
        }
        Ok(rows)
    }

    /// The reference image for a backend and a kind (see the module docs).
    fn reference(
        &self,
        scene: &Scene,
        backend: Backend,
        kind: RefKind,
    ) -> Result<(String, Vec<Rgb>), Error> {
        let base = Prepared::from_scene(scene.clone(), &base_overrides(&self.opts))?;
        let has_d1 = golden::has_ray_tree(&base.tri);
        let local = backend.shades_locally() && has_d1;
        let variant = match kind {
            RefKind::Main if local => Some(Variant::Depth1),
            RefKind::Main => Some(Variant::Main),
            RefKind::Surface if !local => Some(Variant::Analytic),
            RefKind::Surface | RefKind::Converged => None,
        };
        if let Some(v) = variant
            && let Some(pixels) = self.stored(&base, v)
        {
            return Ok((format!("pov{}", v.suffix()), pixels));
        }
        // The ray tracer's best: analytic spheres, fine tessellation,
        // the backend's ray-tree depth.
        let mut s = scene.clone();
        let mut ov = base_overrides(&self.opts);
        if local {
            ov.max_depth = Some(1);
        }
        let mut label = String::from("ray");
        if kind != RefKind::Main {
            s.render.tessellation_error = FINE_TESSELLATION;
            if s.objects
                .iter()
                .any(|o| matches!(o.shape, Shape::Sphere { .. }))
            {
                ov.geometry = Some(Geometry::Analytic);
            }
            label.push_str(" fine");
        }
        if kind == RefKind::Converged {
            ov.samples = Some(CONVERGED_SAMPLES);
            let _ = write!(label, " {CONVERGED_SAMPLES}x{CONVERGED_SAMPLES}");
        }
        if local {
            label.push_str(" d1");
        }
        let job = Prepared::from_scene(s, &ov)?;
        Ok((label, job.render(Backend::Ray)?.frame.color.to_vec()))
    }

    /// A stored POV-Ray reference, if it is current and of the right size.
    fn stored(&self, base: &Prepared, variant: Variant) -> Option<Vec<Rgb>> {
        let fresh = golden::stale(&base.scene, &base.tri, &self.opts.golden_dir)
            .is_ok_and(|p| p.is_empty());
        if !fresh {
            return None;
        }
        let path = golden::reference_path(&self.opts.golden_dir, &base.scene, variant);
        let img = image_io::read_png_linear(&path).ok()?;
        let cam = &base.tri.camera;
        (img.width == cam.width() && img.height == cam.height()).then_some(img.pixels)
    }
}

/// A prepared case: the scene tessellated for it, and its thread pool.
struct Runner {
    job: Prepared,
    backend: Backend,
    pool: Option<rayon::ThreadPool>,
}

impl Runner {
    fn new(scene: &Scene, case: &Case) -> Result<Runner, Error> {
        let mut s = scene.clone();
        if let Some(e) = case.tessellation_error {
            s.render.tessellation_error = e;
        }
        let job = Prepared::from_scene(s, &case.ov)?;
        let pool = match case.threads {
            Some(n) => Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .build()
                    .map_err(|e| Error::Usage(format!("could not start {n} threads: {e}")))?,
            ),
            None => None,
        };
        Ok(Runner {
            job,
            backend: case.backend,
            pool,
        })
    }

    fn render(&self) -> Result<rendiff::Rendered, Error> {
        match &self.pool {
            Some(p) => p.install(|| self.job.render(self.backend)),
            None => self.job.render(self.backend),
        }
    }

    /// The untimed first render: everything but the times.
    fn first_row(
        &self,
        scene: &Scene,
        case: &Case,
        ref_label: &str,
        reference: &[Rgb],
    ) -> Result<Row, Error> {
        let first = self.render()?;
        let err = image_error(&first.frame.color, reference);
        let rays = match first.work {
            Work::Ray { rays, .. } => rays.primary + rays.shadow + rays.secondary,
            Work::Raster(s) | Work::Painter { raster: s, .. } | Work::Bsp { raster: s, .. } => {
                s.shadow_rays
            }
        };
        let cam = &self.job.tri.camera;
        Ok(Row {
            scene: scene.name(),
            backend: case.backend,
            sweep: case.sweep,
            setting: case.setting.clone(),
            threads: self.pool.as_ref().map_or_else(
                rayon::current_num_threads,
                rayon::ThreadPool::current_num_threads,
            ),
            triangles: self.job.tri.len(),
            size: (cam.width(), cam.height()),
            samples: cam.samples(),
            runs: 0,
            median_ms: 0.0,
            min_ms: 0.0,
            max_ms: 0.0,
            reference: ref_label.to_string(),
            mae8: err.mae8,
            beyond2_pct: err.beyond2_pct,
            max8: err.max8,
            rays,
        })
    }
}

fn median(sorted: &[f64]) -> f64 {
    let n = sorted.len();
    if n % 2 == 1 {
        sorted[n / 2]
    } else {
        0.5 * (sorted[n / 2 - 1] + sorted[n / 2])
    }
}

fn base_overrides(opts: &BenchOptions) -> Overrides {
    Overrides {
        size: opts.size,
        ..Overrides::default()
    }
}

/// One setting a sweep varies, applied to a case.
#[derive(Clone, Copy, Debug)]
enum Knob {
    Tessellation(f64),
    Analytic,
    Samples(u32),
    Depth(DepthFormat),
    Shadows(ShadowMode),
    MaxDepth(u32),
    Plan(bool),
    Threads(usize),
}

impl Knob {
    /// The setting's column in the CSV.
    fn label(self) -> String {
        match self {
            Knob::Tessellation(e) => format!("{e}"),
            Knob::Analytic => "analytic".into(),
            Knob::Samples(n) => format!("{n}x{n}"),
            Knob::Depth(d) => d.to_string(),
            Knob::Shadows(m) => m.to_string(),
            Knob::MaxDepth(d) => d.to_string(),
            Knob::Plan(on) => if on { "on" } else { "off" }.into(),
            Knob::Threads(n) => n.to_string(),
        }
    }

    fn apply(self, c: &mut Case) {
        match self {
            Knob::Tessellation(e) => c.tessellation_error = Some(e),
            Knob::Analytic => c.ov.geometry = Some(Geometry::Analytic),
            Knob::Samples(n) => c.ov.samples = Some(n),
            Knob::Depth(d) => c.ov.depth = Some(d),
            Knob::Shadows(m) => c.ov.shadows = Some(m),
            Knob::MaxDepth(d) => c.ov.max_depth = Some(d),
            Knob::Plan(on) => c.ov.no_plan = !on,
            Knob::Threads(n) => c.threads = Some(n),
        }
    }
}

/// Every case of a scene, sweep by sweep.
fn cases(scene: &Scene, base: &Prepared, opts: &BenchOptions) -> Vec<Case> {
    let mut out = Vec::new();
    for &sweep in &opts.sweeps {
        for (backend, knob, reference) in sweep_knobs(sweep, scene, base, opts) {
            let mut c = Case {
                backend,
                sweep,
                setting: knob.label(),
                ov: base_overrides(opts),
                tessellation_error: None,
                threads: None,
                reference,
            };
            knob.apply(&mut c);
            out.push(c);
        }
    }
    out
}

/// The (backend, setting, reference) triples of one sweep; none where the
/// scene has nothing for it to vary (no curved surface to tessellate, no
/// shadow, no ray tree).
fn sweep_knobs(
    sweep: Sweep,
    scene: &Scene,
    base: &Prepared,
    opts: &BenchOptions,
) -> Vec<(Backend, Knob, RefKind)> {
    const BOTH: [Backend; 2] = [Backend::Raster, Backend::Ray];
    let each = |knobs: Vec<Knob>, backends: &[Backend], r: RefKind| {
        knobs
            .into_iter()
            .flat_map(|k| backends.iter().map(move |&b| (b, k, r)))
            .collect::<Vec<_>>()
    };
    let quick = opts.quick;
    let curved = scene.objects.iter().any(|o| {
        o.tessellation.is_none()
            && matches!(o.shape, Shape::Sphere { .. } | Shape::Superellipsoid { .. })
    });
    match sweep {
        Sweep::Tessellation if curved => {
            let errors: &[f64] = if quick { &[2.0, 0.25] } else { &TESSELLATION };
            let mut out = each(
                errors.iter().map(|&e| Knob::Tessellation(e)).collect(),
                &BOTH,
                RefKind::Surface,
            );
            // The ray tracer can skip tessellation altogether.
            out.push((Backend::Ray, Knob::Analytic, RefKind::Surface));
            out
        }
        Sweep::Samples => {
            let ns: &[u32] = if quick { &[1, 2] } else { &[1, 2, 4] };
            each(
                ns.iter().map(|&n| Knob::Samples(n)).collect(),
                &BOTH,
                RefKind::Converged,
            )
        }
        Sweep::Depth => {
            let formats: &[DepthFormat] = if quick {
                &[DepthFormat::F32, DepthFormat::U16]
            } else {
                &[DepthFormat::F32, DepthFormat::U24, DepthFormat::U16]
            };
            each(
                formats.iter().map(|&d| Knob::Depth(d)).collect(),
                &[Backend::Raster],
                RefKind::Main,
            )
        }
        Sweep::Shadows if base.plan.shadows => {
            let modes: &[ShadowMode] = if quick {
                &[ShadowMode::Rays, ShadowMode::Map(256)]
            } else {
                &[
                    ShadowMode::Rays,
                    ShadowMode::Map(256),
                    ShadowMode::Map(1024),
                    ShadowMode::Map(4096),
                ]
            };
            each(
                modes.iter().map(|&m| Knob::Shadows(m)).collect(),
                &[Backend::Raster],
                RefKind::Main,
            )
        }
        Sweep::MaxDepth if base.plan.ray_tree => {
            let top = base.settings.max_depth;
            let depths: Vec<u32> = if quick {
                vec![1, top]
            } else {
                let mut d: Vec<u32> = [1, 2, 3, 5, 8].into_iter().filter(|&d| d < top).collect();
                d.push(top);
                d
            };
            each(
                depths.into_iter().map(Knob::MaxDepth).collect(),
                &[Backend::Ray],
                RefKind::Main,
            )
        }
        Sweep::Plan => BOTH
            .iter()
            .flat_map(|&b| {
                [
                    (b, Knob::Plan(true), RefKind::Main),
                    (b, Knob::Plan(false), RefKind::Main),
                ]
            })
            .collect(),
        Sweep::Threads => each(
            opts.threads.iter().map(|&n| Knob::Threads(n)).collect(),
            &BOTH,
            RefKind::Main,
        ),
        Sweep::Tessellation | Sweep::Shadows | Sweep::MaxDepth => Vec::new(),
    }
}

/// Writes `results.csv` (atomically).
///
/// # Errors
///
/// [`ImageIoError::Io`] when the file cannot be written.
pub fn write_csv(rows: &[Row], path: &Path) -> Result<(), ImageIoError> {
    let mut text = String::from(CSV_HEADER);
    text.push('\n');
    for r in rows {
        text.push_str(&r.csv());
        text.push('\n');
    }
    image_io::write_atomic(path, |f| std::io::Write::write_all(f, text.as_bytes()))
}

/// Indices of the points on the Pareto front of `(time, error)` pairs:
/// no other point is at least as fast and at least as accurate while
/// strictly better in one; sorted by time.
#[must_use]
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..points.len()).collect();
    idx.sort_by(|&a, &b| {
        points[a]
            .0
            .total_cmp(&points[b].0)
            .then(points[a].1.total_cmp(&points[b].1))
    });
    let mut front = Vec::new();
    let mut best = f64::INFINITY;
    for i in idx {
        if points[i].1 < best {
            best = points[i].1;
            front.push(i);
        }
    }
    front
}

/// What the plan saved per scene and backend: (scene, backend, time with
/// the plan, time without), from the plan sweep's rows. The times are the
/// medians, the figure results.csv reports and the plots show, so the
/// saving printed is the one a reader of the CSV computes (the fastest
/// runs, `min_ms`, are in the CSV beside them: on a loaded machine they
/// move less between benches).
#[must_use]
pub fn plan_savings(rows: &[Row]) -> Vec<(String, Backend, f64, f64)> {
    let mut out = Vec::new();
    for r in rows
        .iter()
        .filter(|r| r.sweep == Sweep::Plan && r.setting == "on")
    {
        if let Some(off) = rows.iter().find(|o| {
            o.sweep == Sweep::Plan
                && o.setting == "off"
                && o.scene == r.scene
                && o.backend == r.backend
        }) {
            out.push((r.scene.clone(), r.backend, r.median_ms, off.median_ms));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pareto_front_keeps_exactly_the_undominated_points() {
        // (time, error)
        let pts = [
            (1.0, 5.0),
            (2.0, 3.0),
            (2.5, 4.0),
            (3.0, 1.0),
            (4.0, 1.0),
            (0.5, 9.0),
        ];
        // (2.5, 4) is beaten by (2, 3); (4, 1) by (3, 1).
        assert_eq!(pareto_front(&pts), vec![5, 0, 1, 3]);
        assert!(pareto_front(&[]).is_empty());
    }

    #[test]
    fn image_error_counts_8bit_differences() {
        let a = vec![Rgb::splat(0.5); 4];
        let mut b = a.clone();
        b[0] = Rgb::new(0.6, 0.5, 0.5);
        let e = image_error(&a, &b);
        assert_eq!(e.max8, to_srgb8(0.6) - to_srgb8(0.5));
        assert!((e.beyond2_pct - 25.0).abs() < 1e-9);
        assert!((e.mae8 - f64::from(e.max8) / 4.0).abs() < 1e-12);
        assert_eq!(image_error(&a, &a).mae8, 0.0);
    }

    #[test]
    fn fits_recover_known_growth() {
        use scaling::{fit_affine, fit_log2, fit_power};
        let pts: Vec<(f64, f64)> = (1..8)
            .map(|k| (10f64.powi(k), 3.0 * 10f64.powi(k).powf(0.75)))
            .collect();
        let f = fit_power(&pts);
        assert!((f.exponent - 0.75).abs() < 1e-9 && f.r2 > 0.999_999);
        let (a, b, r2) = fit_affine(&[(1.0, 5.0), (2.0, 7.0), (4.0, 11.0)]);
        assert!((a - 3.0).abs() < 1e-12 && (b - 2.0).abs() < 1e-12 && (r2 - 1.0).abs() < 1e-12);
        let (a, b, _) = fit_log2(&[(2.0, 11.0), (8.0, 15.0), (1024.0, 29.0)]);
        assert!((a - 9.0).abs() < 1e-9 && (b - 2.0).abs() < 1e-9);
    }

    #[test]
    fn sweeps_parse_and_reject_unknown_names() {
        for s in Sweep::ALL {
            assert_eq!(s.name().parse::<Sweep>(), Ok(s));
        }
        assert!(
            "nope"
                .parse::<Sweep>()
                .unwrap_err()
                .contains("tessellation")
        );
    }
}
