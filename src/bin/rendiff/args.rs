//! Command-line grammar (DESIGN.md §5), parsed by clap.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};

/// One scene, two renderers, one verdict.
///
/// rendiff renders a scene with a scanline z-buffer rasterizer and a ray
/// tracer, and checks sample by sample that they agree; POV-Ray 3.7 renders
/// are the outside reference.
#[derive(Debug, Parser)]
#[command(name = "rendiff", version, about, long_about)]
pub struct Cli {
    /// The command.
    #[command(subcommand)]
    pub command: Command,
}

/// The commands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Render a scene to a PNG.
    Render(RenderArgs),
    /// Render scenes two ways (or against an image) and explain every difference.
    ///
    /// Exit status 0 when every scene is within tolerance, 1 when one is not.
    Diff(DiffArgs),
    /// Print what a scene contains and what the render plan decides.
    Plan(PlanArgs),
    /// Write the POV-Ray 3.7 scene that renders the same picture.
    Pov(PovArgs),
    /// Check the stored POV-Ray references (or re-render them with --update).
    ///
    /// Without --update, renders every reference again into a temporary
    /// folder and reports whether the stored ones are still what POV-Ray
    /// produces (exit 1 when one is stale or differs).
    Golden(GoldenArgs),
    /// Measure run time against error, sweeping the settings that trade one for the other.
    ///
    /// Writes results.csv, a time-against-error plot per scene (with the
    /// Pareto front marked), plan_savings.svg and index.html into --out.
    Bench(BenchArgs),
    /// Merge verdicts (the --json output of diff runs, e.g. one per shard) into one report.
    ///
    /// Reads JSON files (a report or an array of reports) and folders (every
    /// report.json under them); prints each scene's verdict and the totals,
    /// or the merged array with --json. Exit status 1 when a scene failed.
    Report(ReportArgs),
    /// Walk the pending snapshot images (NAME.new.png beside NAME.png) and accept or reject each.
    ///
    /// Shows each pending image's verdict against its golden; on a terminal
    /// asks for each: [a]ccept (the pending image becomes the golden),
    /// [r]eject (it is removed), [s]kip. Exit status 1 while images remain
    /// pending.
    Review(ReviewArgs),
    /// Draw the visible edges (silhouettes, creases, boundaries) as SVG or PNG.
    ///
    /// Hidden parts are removed by Appel's quantitative invisibility: the
    /// number of surfaces in front of an edge changes only where it passes
    /// behind a contour edge.
    Lines(LinesArgs),
    /// Print a shell completion script to standard output.
    ///
    /// For example `rendiff completions bash > ~/.local/share/bash-completion/completions/rendiff`,
    /// or `rendiff completions zsh > ~/.zfunc/_rendiff`.
    Completions(CompletionsArgs),
    /// Write the manual page (roff) to standard output or a file.
    ///
    /// For example `rendiff man | man -l -`, or `rendiff man -o rendiff.1`.
    Man(ManArgs),
}

/// `rendiff completions`.
#[derive(Debug, Args)]
pub struct CompletionsArgs {
    /// The shell to write the script for.
    #[arg(value_enum)]
    pub shell: clap_complete::Shell,
}

/// `rendiff man`.
#[derive(Debug, Args)]
pub struct ManArgs {
    /// Output file (default: standard output).
    #[arg(short = 'o', long = "output", value_name = "FILE")]
    pub output: Option<PathBuf>,
}

/// A renderer, as the command line names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum BackendArg {
    /// The scanline z-buffer rasterizer.
    Raster,
    /// The ray tracer.
    Ray,
    /// The painter's algorithm (depth-sorted triangles, no z-buffer).
    Painter,
    /// A BSP tree of the triangles, painted back to front (no z-buffer).
    Bsp,
}

impl From<BackendArg> for rendiff::Backend {
    fn from(b: BackendArg) -> Self {
        match b {
            BackendArg::Raster => rendiff::Backend::Raster,
            BackendArg::Ray => rendiff::Backend::Ray,
            BackendArg::Painter => rendiff::Backend::Painter,
            BackendArg::Bsp => rendiff::Backend::Bsp,
        }
    }
}

/// The ray tracer's geometry, as the command line names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum GeometryArg {
    /// The triangles every backend sees.
    Mesh,
    /// Exact shapes (spheres, boxes, …) where the scene has them.
    Analytic,
}

impl From<GeometryArg> for rendiff::options::Geometry {
    fn from(g: GeometryArg) -> Self {
        match g {
            GeometryArg::Mesh => rendiff::options::Geometry::Mesh,
            GeometryArg::Analytic => rendiff::options::Geometry::Analytic,
        }
    }
}

/// The rasterizer's depth buffer format, as the command line names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum DepthArg {
    /// 32-bit float.
    F32,
    /// 24-bit fixed point.
    U24,
    /// 16-bit fixed point.
    U16,
}

impl From<DepthArg> for rendiff::options::DepthFormat {
    fn from(d: DepthArg) -> Self {
        match d {
            DepthArg::F32 => rendiff::options::DepthFormat::F32,
            DepthArg::U24 => rendiff::options::DepthFormat::U24,
            DepthArg::U16 => rendiff::options::DepthFormat::U16,
        }
    }
}

/// The painter's order, as the command line names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SortArg {
    /// Newell's tests (splitting cycles).
    Newell,
    /// The plain depth sort by centroid.
    Centroid,
}

impl From<SortArg> for rendiff::options::PainterSort {
    fn from(s: SortArg) -> Self {
        match s {
            SortArg::Newell => rendiff::options::PainterSort::Newell,
            SortArg::Centroid => rendiff::options::PainterSort::Centroid,
        }
    }
}

/// `rendiff report`.
#[derive(Debug, Args)]
pub struct ReportArgs {
    /// JSON files and folders of diff results.
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// Print the merged reports as one JSON array.
    #[arg(long)]
    pub json: bool,
}

/// `rendiff review`.
#[derive(Debug, Args)]
pub struct ReviewArgs {
    /// The golden folder to walk.
    #[arg(default_value = "tests/golden", value_name = "DIR")]
    pub dir: PathBuf,
    /// Accept every pending image without asking.
    #[arg(long, conflicts_with = "reject_all")]
    pub accept_all: bool,
    /// Reject every pending image without asking.
    #[arg(long)]
    pub reject_all: bool,
    /// Also write each comparison's pictures and report (a.png golden,
    /// b.png pending, heat map, index.html) into DIR/NAME.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
}

/// `rendiff lines`.
#[derive(Debug, Args)]
pub struct LinesArgs {
    /// The scene file (.toml).
    pub scene: PathBuf,
    /// Output .svg or .png.
    #[arg(short = 'o', long = "output", value_name = "OUT.svg|OUT.png")]
    pub output: PathBuf,
    /// Edges whose faces meet at more than this angle (degrees) are drawn as creases.
    #[arg(long, default_value_t = 30.0, value_name = "DEG")]
    pub crease: f64,
    /// Also draw the hidden parts (dashed, grey).
    #[arg(long)]
    pub hidden: bool,
    /// Image size, overriding the scene's [image] (e.g. 640x480).
    #[arg(long, value_name = "WxH", value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
    /// The hidden-line method.
    #[arg(long, value_enum, default_value_t = MethodArg::Appel, value_name = "METHOD")]
    pub method: MethodArg,
}

/// A hidden-line method, as the command line names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MethodArg {
    /// Appel's quantitative invisibility (any scene).
    Appel,
    /// Roberts' algorithm (scenes of convex polyhedra only).
    Roberts,
}

/// `rendiff bench`.
#[derive(Debug, Args)]
pub struct BenchArgs {
    /// Scene files (default: every scenes/*.toml).
    pub scenes: Vec<PathBuf>,
    /// Output folder.
    #[arg(long, default_value = "rendiff-bench", value_name = "DIR")]
    pub out: PathBuf,
    /// Timed runs per setting (the median is reported).
    #[arg(long, default_value_t = 5, value_name = "N")]
    pub repeats: usize,
    /// Only these sweeps (repeatable): tessellation, samples, depth,
    /// shadows, max_depth, plan, threads.
    #[arg(long = "sweep", value_name = "NAME")]
    pub sweeps: Vec<String>,
    /// Fewer settings per sweep.
    #[arg(long)]
    pub quick: bool,
    /// Image size, overriding the scenes' (e.g. 640x480).
    #[arg(long, value_name = "WxH", value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
    /// Thread counts of the threads sweep, e.g. 1,2,4 (default: 1, 2, 4, … all cores).
    #[arg(long, value_name = "LIST", value_delimiter = ',')]
    pub threads: Vec<usize>,
    /// Folder of the stored POV-Ray references.
    #[arg(long = "golden", default_value = "golden/pov", value_name = "DIR")]
    pub golden_dir: PathBuf,
    /// Measure scaling instead: time against triangle count (a sphere
    /// tessellated from 10^3 to 4·10^6 triangles) and against resolution
    /// (the first scene given, default scenes/bunny.toml, 160x120 …
    /// 1920x1080); writes scaling.csv and scaling.svg.
    #[arg(long)]
    pub scaling: bool,
}

/// `rendiff pov`.
#[derive(Debug, Args)]
pub struct PovArgs {
    /// The scene file (.toml).
    pub scene: PathBuf,
    /// Output .pov (default: standard output, images named relative to
    /// the scene's folder). Images are named relative to the file's
    /// folder, and its first comment line is the command that renders it
    /// there.
    #[arg(short = 'o', long = "output", value_name = "OUT.pov")]
    pub output: Option<PathBuf>,
    /// mesh (the triangles the backends see) or analytic (POV-Ray primitives).
    #[arg(long, value_enum, default_value_t = GeometryArg::Mesh, value_name = "KIND")]
    pub geometry: GeometryArg,
    /// Image size, overriding the scene's [image] (e.g. 640x480).
    #[arg(long, value_name = "WxH", value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
    /// POV-Ray's max_trace_level (default: the scene's max_depth).
    #[arg(long, value_name = "N")]
    pub max_depth: Option<u32>,
    /// Name texture and bump images by absolute paths (default: relative to
    /// the output's folder, so the file renders where it is written).
    #[arg(long)]
    pub absolute_paths: bool,
}

/// `rendiff golden`.
#[derive(Debug, Args)]
pub struct GoldenArgs {
    /// Scene files (default: every scenes/*.toml).
    pub scenes: Vec<PathBuf>,
    /// Render the references and store them (only the scenes given).
    #[arg(long)]
    pub update: bool,
    /// Folder of the references.
    #[arg(long = "golden", default_value = "golden/pov", value_name = "DIR")]
    pub golden_dir: PathBuf,
    /// Work on shard K of N only (1-based): a scene belongs to the shard its
    /// path's hash names, the same on every machine and run.
    #[arg(long, value_name = "K/N", value_parser = parse_shard)]
    pub shard: Option<(u64, u64)>,
    /// Accept every pending snapshot image (NAME.new.png) under DIR (default
    /// tests/golden) instead: as `rendiff review DIR --accept-all`.
    #[arg(
        long,
        value_name = "DIR",
        num_args = 0..=1,
        default_missing_value = "tests/golden",
        conflicts_with_all = ["update", "shard"]
    )]
    pub accept: Option<PathBuf>,
}

/// `rendiff diff`.
#[derive(Debug, Args)]
pub struct DiffArgs {
    /// The scene files (.toml), or two images (A.png B.png) to compare pixel
    /// by pixel with no scene.
    #[arg(required = true)]
    pub scenes: Vec<PathBuf>,
    /// Side a: a backend, pov or PATH.png, as --b [possible values: raster, ray, painter, bsp, pov, PATH.png]
    #[arg(long = "a", default_value = "raster", value_name = "SIDE", value_parser = parse_side)]
    pub a: String,
    /// Side b: a backend, pov (the POV-Ray reference), or PATH.png (any
    /// argument with '.' or '/') [possible values: raster, ray, painter, bsp, pov, PATH.png]
    #[arg(long = "b", default_value = "ray", value_name = "SIDE", value_parser = parse_side)]
    pub b: String,
    /// Not a diff flag: diff compares two sides, given by --a and --b (this
    /// is here to say so instead of suggesting --b).
    #[arg(long, hide = true, value_name = "BACKEND", num_args = 0..=1, default_missing_value = "")]
    pub backend: Option<String>,
    /// With --b pov: render the POV-Ray reference now instead of reading the stored one.
    #[arg(long)]
    pub render: bool,
    /// Folder of the stored POV-Ray references (for --b pov).
    #[arg(long = "golden", default_value = "golden/pov", value_name = "DIR")]
    pub golden_dir: PathBuf,
    /// Print the JSON verdict (one object per scene; an array for several).
    #[arg(long)]
    pub json: bool,
    /// Write both images, the maps, a composite, report.json and index.html into DIR.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Against an image: the verdict passes when at most PIXELS pixels differ
    /// beyond the images' rounding, none by more than MAX_DIFF 8-bit codes
    /// (replaces the scene's [tolerance] fuzzy; may be looser than the derived rule).
    #[arg(long, value_name = "MAX_DIFF,PIXELS", value_parser = parse_fuzzy)]
    pub fuzzy: Option<(u8, u64)>,
    /// Work on shard K of N only (1-based): a scene belongs to the shard its
    /// path's hash names, the same on every machine and run; merge the
    /// shards' --json outputs with `rendiff report`.
    #[arg(long, value_name = "K/N", value_parser = parse_shard)]
    pub shard: Option<(u64, u64)>,
    /// Render settings.
    #[command(flatten)]
    pub flags: RenderFlags,
}

/// Flags shared by every command that renders.
#[derive(Debug, Args, Clone, Default)]
pub struct RenderFlags {
    /// Image size, overriding the scene's [image] (e.g. 640x480).
    #[arg(long, value_name = "WxH", value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
    /// Samples per pixel side: 1, 2, 4, 8 or 16.
    #[arg(long, value_name = "N")]
    pub samples: Option<u32>,
    /// Worker threads (default: all cores). The output does not depend on it.
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// Write 16-bit linear PNGs (with a gAMA chunk of 1.0) instead of 8-bit sRGB.
    #[arg(long)]
    pub linear16: bool,
    /// Also write the G-buffer (depth.pfm, id.png, flags.png) into DIR
    /// (for diff: DIR/a and DIR/b).
    #[arg(long, value_name = "DIR")]
    pub gbuffer: Option<PathBuf>,
    /// Rasterizer depth buffer format.
    #[arg(long, value_enum, value_name = "FORMAT")]
    pub depth: Option<DepthArg>,
    /// Rasterizer shadows: rays (traced), or map:RES for a shadow map of
    /// RES x RES texels, 64 … 16384 [possible values: rays, map:RES]
    #[arg(long, value_name = "MODE", value_parser = parse_shadows)]
    pub shadows: Option<rendiff::options::ShadowMode>,
    /// Ray tracer geometry.
    #[arg(long, value_enum, value_name = "KIND")]
    pub geometry: Option<GeometryArg>,
    /// Ray tree depth (POV-Ray's max_trace_level), 1 … 64.
    #[arg(long, value_name = "N")]
    pub max_depth: Option<u32>,
    /// The painter's order (default: newell).
    #[arg(long, value_enum, value_name = "ORDER")]
    pub sort: Option<SortArg>,
    /// Switch the render plan off: do all work, needed or not.
    #[arg(long)]
    pub no_plan: bool,
    /// Refuse scenes that would need more memory than this many GiB
    /// (default 4), before allocating it.
    #[arg(long, value_name = "GIB")]
    pub memory_budget: Option<f64>,
}

/// `rendiff render`.
#[derive(Debug, Args)]
pub struct RenderArgs {
    /// The scene file (.toml).
    pub scene: PathBuf,
    /// The renderer.
    #[arg(long, value_enum, default_value_t = BackendArg::Ray, value_name = "BACKEND")]
    pub backend: BackendArg,
    /// With --backend painter: paint the triangles with anti-aliased fills
    /// in one flat colour each (tiny-skia) instead of the sample grid.
    #[arg(long)]
    pub smooth: bool,
    /// Output PNG (default: NAME-BACKEND.png in the current folder).
    #[arg(short = 'o', long = "output", value_name = "OUT.png")]
    pub output: Option<PathBuf>,
    /// Render settings.
    #[command(flatten)]
    pub flags: RenderFlags,
}

/// `rendiff plan`.
#[derive(Debug, Args)]
pub struct PlanArgs {
    /// The scene file (.toml).
    pub scene: PathBuf,
    /// Show the plan with everything forced on.
    #[arg(long)]
    pub no_plan: bool,
    /// Refuse scenes whose loading would need more memory than this many
    /// GiB (default 4), before allocating it.
    #[arg(long, value_name = "GIB")]
    pub memory_budget: Option<f64>,
    /// Also render with the ray tracer and set the rays it cast, level by
    /// level, beside the seed's bound N·[(2ⁿ − 1) + m(2ⁿ − 1)].
    #[arg(long)]
    pub count: bool,
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("expected WxH, e.g. 640x480, got \"{s}\""))?;
    let w: u32 = w
        .trim()
        .parse()
        .map_err(|_| format!("width \"{w}\" is not a whole number"))?;
    let h: u32 = h
        .trim()
        .parse()
        .map_err(|_| format!("height \"{h}\" is not a whole number"))?;
    Ok((w, h))
}

/// `--fuzzy MAX_DIFF,PIXELS`.
fn parse_fuzzy(s: &str) -> Result<(u8, u64), String> {
    let bad = || format!("expected MAX_DIFF,PIXELS (e.g. 2,10; MAX_DIFF 0 … 255), got \"{s}\"");
    let (d, p) = s.split_once(',').ok_or_else(bad)?;
    Ok((
        d.trim().parse().map_err(|_| bad())?,
        p.trim().parse().map_err(|_| bad())?,
    ))
}

/// `--shard K/N`: 1 ≤ K ≤ N.
fn parse_shard(s: &str) -> Result<(u64, u64), String> {
    let bad = || format!("expected K/N with 1 ≤ K ≤ N (e.g. 2/4), got \"{s}\"");
    let (k, n) = s.split_once('/').ok_or_else(bad)?;
    let (k, n): (u64, u64) = (
        k.trim().parse().map_err(|_| bad())?,
        n.trim().parse().map_err(|_| bad())?,
    );
    if k == 0 || k > n {
        return Err(bad());
    }
    Ok((k, n))
}

/// `--a`/`--b`: a side `diff` understands (checked here, so a bad one is
/// a usage error naming the flag).
fn parse_side(s: &str) -> Result<String, String> {
    rendiff::diff::Side::parse(s).map(|_| s.to_string())
}

/// `--shadows rays|map:RES`.
fn parse_shadows(s: &str) -> Result<rendiff::options::ShadowMode, String> {
    s.parse::<rendiff::options::ShadowMode>()
        .map_err(|e| e.to_string())
}
