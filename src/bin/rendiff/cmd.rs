//! The commands, each a thin use of the library.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use rendiff::image_io::PngEncoding;
use rendiff::options::Geometry;
use rendiff::shade::{LightKind, Pigment};
use rendiff::{Backend, Overrides, Prepared};

use crate::Outcome;
use crate::args::{
    BenchArgs, Cli, Command, CompletionsArgs, DiffArgs, GoldenArgs, LinesArgs, ManArgs, PlanArgs,
    PovArgs, RenderArgs, RenderFlags, ReportArgs, ReviewArgs,
};

/// Set once standard output is a closed pipe: later output is dropped.
static STDOUT_CLOSED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Writes text for a person to standard output, control characters
/// escaped (a scene or file name cannot reach the terminal raw).
pub fn say(text: &str) -> Result<()> {
    emit(rendiff::escape::lines(text).as_bytes())
}

/// Writes data (SDL, JSON) to standard output as it is. A closed pipe
/// (`rendiff diff s.toml | head -c 10`) drops the rest of the output and
/// leaves the exit status to the verdict, so `pipefail` still sees a
/// failure; any other error (a full disk, `/dev/full`) is an error.
pub fn emit(bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    use std::sync::atomic::Ordering;
    if STDOUT_CLOSED.load(Ordering::Relaxed) {
        return Ok(());
    }
    let mut out = std::io::stdout().lock();
    match out.write_all(bytes).and_then(|()| out.flush()) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => {
            STDOUT_CLOSED.store(true, Ordering::Relaxed);
            Ok(())
        }
        Err(e) => Err(anyhow::anyhow!("could not write to standard output: {e}")),
    }
}

/// A warning on standard error, control characters escaped (a warning
/// that cannot be written is dropped: there is nowhere else to say it).
pub fn warn(text: &str) {
    use std::io::Write;
    let _ = writeln!(
        std::io::stderr(),
        "warning: {}",
        rendiff::escape::message(text)
    );
}

/// Refuses an output that is one of the request's inputs.
fn refuse_inputs(out: &Path, inputs: &[PathBuf]) -> Result<()> {
    rendiff::output::refuse_inputs(out, inputs)?;
    Ok(())
}

/// Runs a parsed command line.
pub fn run(cli: Cli) -> Result<Outcome> {
    match cli.command {
        Command::Render(a) => with_threads(a.flags.threads, || render(&a)),
        Command::Diff(a) => with_threads(a.flags.threads, || diff(&a)),
        Command::Plan(a) => plan(&a),
        Command::Pov(a) => pov(&a),
        Command::Golden(a) => golden(&a),
        Command::Bench(a) => bench(&a),
        Command::Lines(a) => lines(&a),
        Command::Review(a) => review(&a),
        Command::Report(a) => report(&a),
        Command::Completions(a) => completions(&a),
        Command::Man(a) => man(&a),
    }
}

/// `rendiff completions SHELL`: the script on standard output.
fn completions(a: &CompletionsArgs) -> Result<Outcome> {
    use clap::CommandFactory;
    let mut cmd = Cli::command();
    let mut script = Vec::new();
    clap_complete::generate(a.shell, &mut cmd, "rendiff", &mut script);
    emit(&script)?;
    Ok(Outcome::Ok)
}

/// `rendiff man [-o FILE]`: the roff manual page, every command's
/// options in it.
fn man(a: &ManArgs) -> Result<Outcome> {
    use clap::CommandFactory;
    let cmd = Cli::command();
    let mut page = Vec::new();
    let main = clap_mangen::Man::new(cmd.clone());
    main.render_title(&mut page)
        .and_then(|()| main.render_name_section(&mut page))
        .and_then(|()| main.render_synopsis_section(&mut page))
        .and_then(|()| main.render_description_section(&mut page))
        .and_then(|()| main.render_options_section(&mut page))
        .context("could not render the manual page")?;
    // Then each command, with its own options, in this one page.
    for sub in cmd
        .get_subcommands()
        .filter(|s| !s.is_hide_set() && s.get_name() != "help")
    {
        let name = sub.get_name().to_string();
        let sub = sub.clone().bin_name(format!("rendiff {name}"));
        let mut part = Vec::new();
        let man = clap_mangen::Man::new(sub);
        man.render_synopsis_section(&mut part)
            .and_then(|()| man.render_description_section(&mut part))
            .and_then(|()| man.render_options_section(&mut part))
            .context("could not render the manual page")?;
        page.extend_from_slice(format!(".SH \"RENDIFF {}\"\n", name.to_uppercase()).as_bytes());
        // The part's sections become subsections of this one.
        let text = String::from_utf8_lossy(&part)
            .lines()
            .map(|l| match l.strip_prefix(".SH ") {
                Some(rest) => format!(".SS {rest}\n"),
                None => format!("{l}\n"),
            })
            .collect::<String>();
        page.extend_from_slice(text.as_bytes());
    }
    main.render_version_section(&mut page)
        .context("could not render the manual page")?;
    match &a.output {
        Some(out) => {
            check_output_dir(out)?;
            rendiff::image_io::write_atomic(out, |f| std::io::Write::write_all(f, &page))?;
        }
        None => emit(&page)?,
    }
    Ok(Outcome::Ok)
}

/// The scene's warnings (a capped segment count, no lights, …) on
/// standard error.
fn warn_job(job: &Prepared) {
    for w in &job.tri.warnings {
        warn(w);
    }
}

fn lines(a: &LinesArgs) -> Result<Outcome> {
    use crate::args::MethodArg;
    use rendiff::lines::{LinesOptions, hidden_lines, roberts_lines, to_rgba, to_svg};
    let ext = a
        .output
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if !matches!(ext.as_deref(), Some("svg" | "png")) {
        bail!(
            "{}: expected an output ending in .svg or .png",
            a.output.display()
        );
    }
    if !(a.crease.is_finite() && (0.0..=180.0).contains(&a.crease)) {
        bail!(
            "--crease {}: expected an angle from 0 to 180 degrees",
            a.crease
        );
    }
    let job = Prepared::load(
        &a.scene,
        &Overrides {
            size: a.size,
            ..Overrides::default()
        },
    )?;
    warn_job(&job);
    check_output_dir(&a.output)?;
    refuse_inputs(&a.output, &job.scene.input_files())?;
    let start = std::time::Instant::now();
    let opts = LinesOptions {
        crease_deg: a.crease,
        hidden: a.hidden,
        verify: false,
    };
    let d = match a.method {
        MethodArg::Appel => {
            let accel =
                rendiff::accel::Accel::new(&job.tri, rendiff::accel::AccelOptions::default());
            hidden_lines(&job.tri, &accel, &opts)
        }
        MethodArg::Roberts => {
            roberts_lines(&job.tri, &opts).with_context(|| a.scene.display().to_string())?
        }
    };
    let ms = start.elapsed().as_secs_f64() * 1e3;
    if ext.as_deref() == Some("svg") {
        let svg = to_svg(&d);
        rendiff::image_io::write_atomic(&a.output, |f| {
            std::io::Write::write_all(f, svg.as_bytes())
        })?;
    } else {
        rendiff::image_io::write_png_rgba8(&a.output, d.width, d.height, &to_rgba(&d))?;
    }
    let s = d.stats;
    let work = match a.method {
        MethodArg::Appel => format!(
            "{} drawn ({} contours), {} QI changes",
            s.drawn_edges, s.contours, s.qi_changes
        ),
        MethodArg::Roberts => format!(
            "{} drawn ({} culled with back faces); {} convex objects, {} edge-object pairs ({} rejected by bounding boxes), {} plane clips",
            s.drawn_edges, s.culled, s.objects, s.pairs, s.box_rejected, s.plane_tests
        ),
    };
    say(&format!(
        "{}: {} edges, {work}; {} visible and {} hidden pieces in {ms:.1} ms -> {}\n",
        a.scene.display(),
        s.edges,
        s.visible,
        s.hidden,
        a.output.display()
    ))?;
    Ok(Outcome::Ok)
}

fn bench_scaling(a: &BenchArgs) -> Result<Outcome> {
    use rendiff_cli::bench::{plot, scaling};
    let mut opts = scaling::ScalingOptions {
        repeats: a.repeats,
        ..scaling::ScalingOptions::default()
    };
    if let Some(scene) = a.scenes.first() {
        opts.scene.clone_from(scene);
    }
    if a.out.exists() && !a.out.is_dir() {
        bail!("--out {}: exists and is not a folder", a.out.display());
    }
    // The resolution scene must load before the long work starts.
    Prepared::load(&opts.scene, &Overrides::default())?;
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("could not create {}", a.out.display()))?;
    let progress = Progress::new(opts.segments.len() + opts.sizes.len());
    let rows = scaling::run(&opts, &|label| progress.done(label))?;
    progress.finish();
    scaling::write_csv(&rows, &a.out.join("scaling.csv"))?;
    let svg = plot::scaling(&rows)?;
    rendiff::image_io::write_atomic(&a.out.join("scaling.svg"), |f| {
        std::io::Write::write_all(f, svg.as_bytes())
    })?;
    let mut text = String::new();
    for r in &rows {
        let _ = writeln!(
            text,
            "{:9} {:9} {:>9} triangles {:>8} px {:10.2} ms",
            r.series, r.what, r.triangles, r.pixels, r.median_ms
        );
    }
    for line in scaling::fits(&rows) {
        let _ = writeln!(text, "{line}");
    }
    let _ = writeln!(text, "results in {}", a.out.display());
    say(&text)?;
    Ok(Outcome::Ok)
}

fn bench(a: &BenchArgs) -> Result<Outcome> {
    use rendiff_cli::bench::{self, Bench, BenchOptions, Sweep, plot};
    if a.scaling {
        return bench_scaling(a);
    }
    let mut opts = BenchOptions {
        repeats: a.repeats,
        size: a.size,
        quick: a.quick,
        golden_dir: a.golden_dir.clone(),
        ..BenchOptions::default()
    };
    if !a.sweeps.is_empty() {
        opts.sweeps = a
            .sweeps
            .iter()
            .map(|s| s.parse::<Sweep>())
            .collect::<Result<_, _>>()
            .map_err(|e| anyhow::anyhow!("--sweep: {e}"))?;
    }
    if !a.threads.is_empty() {
        opts.threads.clone_from(&a.threads);
    }
    if a.out.exists() && !a.out.is_dir() {
        bail!("--out {}: exists and is not a folder", a.out.display());
    }
    let scenes = scene_list(&a.scenes)?;
    // Every scene loads and every option is checked before any work.
    let run = Bench::new(&scenes, opts)?;
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("could not create {}", a.out.display()))?;
    let progress = Progress::new(run.len());
    let rows = run.run(&|label| progress.done(label))?;
    progress.finish();

    bench::write_csv(&rows, &a.out.join("results.csv"))?;
    let mut names: Vec<String> = rows.iter().map(|r| r.scene.clone()).collect();
    names.dedup();
    let mut html = String::from(
        "<!doctype html><meta charset=\"utf-8\"><title>rendiff bench</title>\n<h1>rendiff bench</h1>\n<p><a href=\"results.csv\">results.csv</a></p>\n<img src=\"plan_savings.svg\" alt=\"plan savings\">\n",
    );
    for name in &names {
        let svg = plot::time_vs_error(name, &rows)?;
        let file = format!("time_vs_error_{name}.svg");
        rendiff::image_io::write_atomic(&a.out.join(&file), |f| {
            std::io::Write::write_all(f, svg.as_bytes())
        })?;
        let _ = writeln!(
            html,
            "<h2>{}</h2>\n<img src=\"{}\" alt=\"{}\">",
            rendiff::escape::html(name),
            rendiff::escape::href(&file),
            rendiff::escape::html(name)
        );
    }
    let savings = bench::plan_savings(&rows);
    let svg = plot::plan_savings(&savings)?;
    rendiff::image_io::write_atomic(&a.out.join("plan_savings.svg"), |f| {
        std::io::Write::write_all(f, svg.as_bytes())
    })?;
    rendiff::image_io::write_atomic(&a.out.join("index.html"), |f| {
        std::io::Write::write_all(f, html.as_bytes())
    })?;

    // The summary: each scene's own settings, and what the plan saved.
    let mut text = String::new();
    for name in &names {
        for backend in [Backend::Raster, Backend::Ray] {
            let base = rows.iter().find(|r| {
                r.scene == *name
                    && r.backend == backend
                    && r.sweep == Sweep::Plan
                    && r.setting == "on"
            });
            if let Some(r) = base {
                let _ = writeln!(
                    text,
                    "{name:16} {backend:6} {:9.2} ms  error {:.4}/255 ({:.3} % beyond 2/255) vs {}",
                    r.median_ms, r.mae8, r.beyond2_pct, r.reference
                );
            }
        }
    }
    for (scene, backend, on, off) in &savings {
        let _ = writeln!(
            text,
            "{scene:16} {backend:6} plan saved {:5.1} % (median {off:.2} ms -> {on:.2} ms)",
            if *off > 0.0 {
                (off - on) / off * 100.0
            } else {
                0.0
            }
        );
    }
    let _ = writeln!(
        text,
        "{} settings measured; results in {}",
        rows.len(),
        a.out.display()
    );
    say(&text)?;
    Ok(Outcome::Ok)
}

fn pov(a: &PovArgs) -> Result<Outcome> {
    use rendiff::pov::{Destination, ExportOptions, export, export_to};
    let geometry = Geometry::from(a.geometry);
    let ov = Overrides {
        size: a.size,
        max_depth: a.max_depth,
        ..Overrides::default()
    };
    let job = Prepared::load(&a.scene, &ov)?;
    warn_job(&job);
    let opts = ExportOptions {
        geometry,
        max_depth: job.settings.max_depth,
        abridged: false,
    };
    let e = match &a.output {
        // Written to a file: its names resolve from the file's folder.
        Some(out) => {
            check_output_dir(out)?;
            export_to(
                &job.scene,
                &job.tri,
                &opts,
                Destination {
                    pov: out,
                    absolute_paths: a.absolute_paths,
                },
            )?
        }
        None if a.absolute_paths => export_to(
            &job.scene,
            &job.tri,
            &opts,
            Destination {
                pov: Path::new("scene.pov"),
                absolute_paths: true,
            },
        )?,
        None => export(&job.scene, &job.tri, &opts)?,
    };
    match &a.output {
        Some(out) => {
            check_output_dir(out)?;
            let inputs = job.scene.input_files();
            refuse_inputs(out, &inputs)?;
            require_extension(out, "pov", "rendiff pov writes POV-Ray SDL")?;
            let dir = out
                .parent()
                .filter(|p| !p.as_os_str().is_empty())
                .unwrap_or(Path::new("."));
            for img in e.images.iter().filter(|i| i.rgb_copy) {
                refuse_inputs(&dir.join(&img.name), &inputs)?;
            }
            for img in &e.images {
                img.materialise(dir)?;
            }
            rendiff::image_io::write_atomic(out, |f| {
                std::io::Write::write_all(f, e.text.as_bytes())
            })?;
        }
        None => emit(e.text.as_bytes())?,
    }
    Ok(Outcome::Ok)
}

/// The scenes to work on: those given, or every scenes/*.toml.
fn scene_list(given: &[PathBuf]) -> Result<Vec<PathBuf>> {
    if !given.is_empty() {
        return Ok(given.to_vec());
    }
    let mut v: Vec<PathBuf> = std::fs::read_dir("scenes")
        .context("no scenes given and no scenes/ folder here")?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    v.sort();
    Ok(v)
}

fn golden(a: &GoldenArgs) -> Result<Outcome> {
    use rendiff::pov::golden;
    if let Some(dir) = &a.accept {
        if !a.scenes.is_empty() {
            bail!(
                "--accept: accepts the pending snapshot images under a folder; it takes no scenes"
            );
        }
        return review(&ReviewArgs {
            dir: dir.clone(),
            accept_all: true,
            reject_all: false,
            out: None,
        });
    }
    let scenes = shard(scene_list(&a.scenes)?, a.shard);
    // Load every scene first: bad input fails (naming its file) before
    // POV-Ray is looked for or anything renders.
    let jobs: Vec<Prepared> = scenes
        .iter()
        .map(|p| Prepared::load(p, &Overrides::default()))
        .collect::<Result<_, _>>()?;
    refuse_shared_reference_names(jobs.iter())?;
    let version = golden::povray_version()?;
    let progress = progress_bar(jobs.len());
    let mut outcome = Outcome::Ok;
    // POV-Ray runs single-threaded (+WT1, for reproducibility), so the
    // scenes render side by side, each in its own scratch folder.
    let renders: Vec<_> = {
        use rayon::prelude::*;
        jobs.par_iter()
            .map(|job| {
                let r = golden::render_all(&job.scene, &job.tri, &a.golden_dir);
                progress.inc(1);
                r
            })
            .collect()
    };
    let result = (|| -> Result<()> {
        for (job, rendered) in jobs.iter().zip(renders) {
            let rendered: Vec<_> = rendered?;
            if a.update {
                golden::store(&job.scene, &version, &rendered, &a.golden_dir)?;
                note(
                    &progress,
                    format!(
                        "{}: {} reference(s) written",
                        job.scene.path.display(),
                        rendered.len()
                    ),
                )?;
            } else {
                let _lock = golden::GoldenLock::shared(&a.golden_dir)?;
                let mut problems = golden::stale(&job.scene, &job.tri, &a.golden_dir)?;
                for (_, img, path) in &rendered {
                    let size = Some((img.width, img.height));
                    match rendiff::image_io::read_png_linear_within(path, size, &job.budget) {
                        Ok(stored) => match golden::max_code_difference(&stored, img) {
                            Some(0) => {}
                            Some(d) => problems.push(format!(
                                "{}: POV-Ray now renders it differently (up to {d}/65535)",
                                path.display()
                            )),
                            None => problems
                                .push(format!("{}: POV-Ray renders another size", path.display())),
                        },
                        Err(e) => problems.push(format!("{}: unreadable ({e})", path.display())),
                    }
                }
                if problems.is_empty() {
                    note(
                        &progress,
                        format!(
                            "{}: {} reference(s) reproduced exactly",
                            job.scene.path.display(),
                            rendered.len()
                        ),
                    )?;
                } else {
                    outcome = Outcome::Differs;
                    for p in problems {
                        note(&progress, format!("{}: {p}", job.scene.path.display()))?;
                    }
                }
            }
        }
        Ok(())
    })();
    progress.finish_and_clear();
    result?;
    if matches!(outcome, Outcome::Differs) {
        warn(
            "some references are stale or no longer reproduced; after checking why, re-render them with `rendiff golden --update SCENE...`",
        );
    }
    Ok(outcome)
}

/// A line of output above the progress bar (or plain, without one).
fn note(bar: &indicatif::ProgressBar, line: String) -> Result<()> {
    if bar.is_hidden() {
        say(&format!("{line}\n"))
    } else {
        bar.println(rendiff::escape::message(&line));
        Ok(())
    }
}

/// Progress of a long run of items (`bench`) on standard error: a bar
/// with the time left on a terminal; one line per finished item
/// otherwise, so a piped or logged run is seen to move.
struct Progress {
    bar: indicatif::ProgressBar,
    plain: Option<std::sync::Mutex<(usize, std::time::Instant)>>,
    len: usize,
}

impl Progress {
    fn new(len: usize) -> Self {
        use std::io::IsTerminal;
        if std::io::stderr().is_terminal() {
            let bar = indicatif::ProgressBar::new(u64::try_from(len).unwrap_or(u64::MAX));
            if let Ok(style) = indicatif::ProgressStyle::with_template(
                "{bar:30} {pos}/{len} {elapsed_precise} elapsed, ETA {eta_precise}  {msg}",
            ) {
                bar.set_style(style);
            }
            Progress {
                bar,
                plain: None,
                len,
            }
        } else {
            Progress {
                bar: indicatif::ProgressBar::hidden(),
                plain: Some(std::sync::Mutex::new((0, std::time::Instant::now()))),
                len,
            }
        }
    }

    /// One item finished.
    fn done(&self, label: &str) {
        use std::io::Write;
        match &self.plain {
            None => {
                self.bar
                    .set_message(rendiff::escape::message(label).into_owned());
                self.bar.inc(1);
            }
            Some(m) => {
                let mut g = m.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
                g.0 += 1;
                let _ = writeln!(
                    std::io::stderr(),
                    "[{}/{}] {:.1} s {}",
                    g.0,
                    self.len,
                    g.1.elapsed().as_secs_f64(),
                    rendiff::escape::message(label)
                );
            }
        }
    }

    fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

/// A progress bar on a terminal, nothing otherwise.
fn progress_bar(len: usize) -> indicatif::ProgressBar {
    use std::io::IsTerminal;
    if !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(u64::try_from(len).unwrap_or(u64::MAX));
    if let Ok(style) = indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} {msg}") {
        bar.set_style(style);
    }
    bar
}

fn diff(a: &DiffArgs) -> Result<Outcome> {
    use rendiff::compare::report::index_html;
    use rendiff::diff;
    if let Some(b) = &a.backend {
        let (given, example) = if b.is_empty() {
            (String::new(), "ray")
        } else {
            (format!(" {b}"), b.as_str())
        };
        bail!(
            "--backend{given}: diff compares two sides: use --a and --b (e.g. --a raster --b {example})"
        );
    }
    let image_ext = |p: &PathBuf| {
        p.extension().is_some_and(|e| {
            ["png", "pfm", "exr"]
                .iter()
                .any(|x| e.eq_ignore_ascii_case(x))
        })
    };
    if a.scenes.len() == 2 && a.scenes.iter().all(image_ext) {
        let f = &a.flags;
        let scene_only = [
            ("--size", f.size.is_some()),
            ("--samples", f.samples.is_some()),
            ("--gbuffer", f.gbuffer.is_some()),
            ("--depth", f.depth.is_some()),
            ("--shadows", f.shadows.is_some()),
            ("--geometry", f.geometry.is_some()),
            ("--max-depth", f.max_depth.is_some()),
            ("--sort", f.sort.is_some()),
            ("--no-plan", f.no_plan),
            ("--shard", a.shard.is_some()),
            ("--render", a.render),
        ];
        if let Some((flag, _)) = scene_only.iter().find(|(_, on)| *on) {
            bail!("{flag}: two images are compared as they are; {flag} applies to scenes");
        }
    }
    if a.scenes.iter().any(image_ext) {
        return diff_two_images(a, a.scenes.iter().all(image_ext));
    }
    let ov = overrides(&a.flags)?;
    let (side_a, side_b) = diff_sides(a, &ov)?;
    if a.fuzzy.is_some()
        && [&side_a, &side_b]
            .iter()
            .all(|s| matches!(s, diff::Side::Backend(_)))
    {
        bail!(
            "--fuzzy: the rule is for comparisons against an image (--b PATH.png or pov); two backends are judged sample by sample"
        );
    }
    let scenes = shard(a.scenes.clone(), a.shard);
    if scenes.is_empty() {
        // A shard may hold none of a short list: an empty result, not an error.
        if a.json {
            emit(b"[]\n")?;
        } else {
            say("this shard holds none of the scenes given\n")?;
        }
        return Ok(Outcome::Ok);
    }
    // Load every scene first: bad input fails before any work or output.
    let jobs: Vec<(String, Prepared)> = scenes
        .iter()
        .map(|p| Ok((p.display().to_string(), Prepared::load(p, &ov)?)))
        .collect::<Result<_>>()?;
    for (_, job) in &jobs {
        warn_job(job);
    }
    if [&side_a, &side_b]
        .iter()
        .any(|s| matches!(s, diff::Side::Pov { .. }))
    {
        refuse_shared_reference_names(jobs.iter().map(|(_, j)| j))?;
    }
    let inputs = diff_inputs(&jobs, [&side_a, &side_b]);
    let several = jobs.len() > 1;
    let folders = rendiff::output::scene_folders(&scenes);
    // The --out set is written into a fresh folder and swapped in whole.
    let out_dir = a
        .out
        .as_ref()
        .map(|dir| rendiff::output::OutputDir::begin(dir, &inputs))
        .transpose()?;
    let gbuffer_base = |k: usize| {
        a.flags.gbuffer.as_ref().map(|gb| {
            if several {
                gb.join(&folders[k])
            } else {
                gb.clone()
            }
        })
    };
    for k in 0..jobs.len() {
        if let Some(base) = gbuffer_base(k) {
            for side in ["a", "b"] {
                for f in rendiff::frame::GBUFFER_FILES {
                    refuse_inputs(&base.join(side).join(f), &inputs)?;
                }
            }
        }
    }
    let mut reports = Vec::new();
    let mut entries = Vec::new();
    for (k, (label, job)) in jobs.iter().enumerate() {
        let fuzzy = a
            .fuzzy
            .map(|(max_diff, pixels)| rendiff::compare::Fuzzy { max_diff, pixels });
        let r = diff::diff_with(job, label, &side_a, &side_b, fuzzy)?;
        if let Some(base) = gbuffer_base(k) {
            for (side, out) in [("a", &r.a), ("b", &r.b)] {
                if let diff::Output::Frame(f, _) = out {
                    f.write_gbuffer(&base.join(side))?;
                }
            }
        }
        if let Some(od) = &out_dir {
            let target = if several {
                let sub = od.path().join(&folders[k]);
                std::fs::create_dir(&sub)
                    .with_context(|| format!("could not create {}", sub.display()))?;
                sub
            } else {
                od.path().to_path_buf()
            };
            diff::write_outputs(&r, Some(job), &target, encoding(&a.flags)).map_err(
                |e| match e {
                    rendiff::Error::Image(e) => rendiff::Error::Image(od.relabel(e)),
                    e => e,
                },
            )?;
            entries.push((r.report.clone(), folders[k].clone()));
        }
        if !a.json {
            say(&r.report.summary())?;
        }
        reports.push(r.report);
    }
    if let Some(od) = out_dir {
        if several {
            let html = index_html(&entries);
            rendiff::image_io::write_atomic(&od.path().join("index.html"), |f| {
                std::io::Write::write_all(f, html.as_bytes())
            })
            .map_err(|e| od.relabel(e))?;
        }
        od.commit()?;
    }
    if a.json {
        let text = if several {
            serde_json::to_string_pretty(&reports)?
        } else {
            serde_json::to_string_pretty(&reports[0])?
        };
        emit(format!("{text}\n").as_bytes())?;
    }
    Ok(
        if reports.iter().all(rendiff::compare::report::Report::passed) {
            Outcome::Ok
        } else {
            Outcome::Differs
        },
    )
}

/// `rendiff diff A.png B.png`: two images, no scene.
fn diff_two_images(a: &DiffArgs, all_png: bool) -> Result<Outcome> {
    use rendiff::diff;
    if !all_png || a.scenes.len() != 2 {
        bail!(
            "diff: give two images (A.png B.png) or scene files (.toml), not a mix; got {} argument(s)",
            a.scenes.len()
        );
    }
    let (pa, pb) = (&a.scenes[0], &a.scenes[1]);
    let budget = rendiff::budget::Budget::new(
        memory_budget(a.flags.memory_budget)?.unwrap_or(rendiff::budget::DEFAULT_MEMORY_BUDGET),
    );
    let fuzzy = a
        .fuzzy
        .map(|(max_diff, pixels)| rendiff::compare::Fuzzy { max_diff, pixels });
    let inputs = vec![pa.clone(), pb.clone()];
    let out_dir = a
        .out
        .as_ref()
        .map(|dir| rendiff::output::OutputDir::begin(dir, &inputs))
        .transpose()?;
    let r = diff::diff_images(pa, pb, fuzzy, &budget)?;
    if let Some(od) = out_dir {
        diff::write_outputs(&r, None, od.path(), encoding(&a.flags)).map_err(|e| match e {
            rendiff::Error::Image(e) => rendiff::Error::Image(od.relabel(e)),
            e => e,
        })?;
        od.commit()?;
    }
    if a.json {
        let text = serde_json::to_string_pretty(&r.report)?;
        emit(format!("{text}\n").as_bytes())?;
    } else {
        say(&r.report.summary())?;
    }
    Ok(if r.report.passed() {
        Outcome::Ok
    } else {
        Outcome::Differs
    })
}

/// The two sides of `diff` as asked for (`--b pov` takes the golden folder
/// and `--render`); analytic geometry only where both sides can draw it.
fn diff_sides(a: &DiffArgs, ov: &Overrides) -> Result<(rendiff::diff::Side, rendiff::diff::Side)> {
    use rendiff::diff::Side;
    let side_a = Side::parse(&a.a).map_err(|e| anyhow::anyhow!("--a: {e}"))?;
    let side_b = match Side::parse(&a.b).map_err(|e| anyhow::anyhow!("--b: {e}"))? {
        Side::Pov { .. } => Side::Pov {
            golden_dir: a.golden_dir.clone(),
            render: a.render,
        },
        other => other,
    };
    if ov.geometry == Some(Geometry::Analytic) {
        for (flag, side) in [("--a", &side_a), ("--b", &side_b)] {
            if let Side::Backend(b) = side
                && *b != Backend::Ray
            {
                bail!(
                    "--geometry analytic: only the ray tracer renders analytic shapes ({flag} is {b})"
                );
            }
        }
    }
    Ok((side_a, side_b))
}

/// What a `diff` request reads (scenes, their meshes and textures, a
/// `--b` image, a stored golden folder), which no output may replace.
fn diff_inputs(jobs: &[(String, Prepared)], sides: [&rendiff::diff::Side; 2]) -> Vec<PathBuf> {
    use rendiff::diff::Side;
    let mut inputs: Vec<PathBuf> = jobs
        .iter()
        .flat_map(|(_, job)| job.scene.input_files())
        .collect();
    for side in sides {
        match side {
            Side::Image(p) | Side::External(p) => inputs.push(p.clone()),
            Side::Pov {
                golden_dir,
                render: false,
            } => inputs.push(golden_dir.clone()),
            _ => {}
        }
    }
    inputs
}

/// Runs `f` on a pool of `threads` workers (all cores when `None`); at
/// most [`rendiff::budget::max_threads`] (8 per core, at least 64).
fn with_threads<T: Send>(
    threads: Option<usize>,
    f: impl FnOnce() -> Result<T> + Send,
) -> Result<T> {
    let most = rendiff::budget::max_threads();
    match threads {
        None => f(),
        Some(0) => bail!("--threads 0: expected at least 1"),
        Some(n) if n > most => bail!(
            "--threads {n}: expected at most {most} (8 per core of this machine, at least 64)"
        ),
        Some(n) => {
            let mut builder = rayon::ThreadPoolBuilder::new().num_threads(n);
            if n == 1 {
                // One worker: this thread itself, so no second thread is
                // started and handed the work. Rayon leaks the registry of a
                // local pool with the current thread: one per process here.
                builder = builder.use_current_thread();
            }
            let pool = builder
                .build()
                .context("could not start the worker threads")?;
            pool.install(f)
        }
    }
}

/// The overrides given by the render flags.
pub fn overrides(flags: &RenderFlags) -> Result<Overrides> {
    let depth = flags.depth.map(Into::into);
    let shadows = flags.shadows;
    let geometry = flags.geometry.map(Into::into);
    let painter_sort = flags.sort.map(Into::into);
    let memory_budget = memory_budget(flags.memory_budget)?;
    Ok(Overrides {
        size: flags.size,
        samples: flags.samples,
        depth,
        shadows,
        geometry,
        bvh: None,
        max_depth: flags.max_depth,
        painter_sort,
        memory_budget,
        no_plan: flags.no_plan,
    })
}

/// `--memory-budget GIB` in bytes.
fn memory_budget(gib: Option<f64>) -> Result<Option<u64>> {
    match gib {
        None => Ok(None),
        Some(g) if g.is_finite() && g > 0.0 && g <= 1e6 => {
            #[expect(
                clippy::cast_possible_truncation,
                clippy::cast_sign_loss,
                reason = "a positive number of GiB, at most 1e6"
            )]
            let bytes = (g * f64::from(1u32 << 30)) as u64;
            Ok(Some(bytes))
        }
        Some(g) => bail!("--memory-budget {g}: expected a positive number of GiB"),
    }
}

fn encoding(flags: &RenderFlags) -> PngEncoding {
    if flags.linear16 {
        PngEncoding::Linear16
    } else {
        PngEncoding::Srgb8
    }
}

fn render(a: &RenderArgs) -> Result<Outcome> {
    let backend = Backend::from(a.backend);
    let ov = overrides(&a.flags)?;
    if ov.geometry == Some(Geometry::Analytic) && backend != Backend::Ray {
        bail!(
            "--geometry analytic: only the ray tracer renders analytic shapes (the {backend} draws triangles)"
        );
    }
    let job = Prepared::load(&a.scene, &ov)?;
    warn_job(&job);
    let out = a
        .output
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("{}-{backend}.png", job.scene.name())));
    check_output_dir(&out)?;
    let inputs = job.scene.input_files();
    refuse_inputs(&out, &inputs)?;
    require_extension(&out, "png", "rendiff writes PNG")?;
    if let Some(dir) = &a.flags.gbuffer {
        for f in rendiff::frame::GBUFFER_FILES {
            refuse_inputs(&dir.join(f), &inputs)?;
        }
    }
    if a.smooth {
        if backend != Backend::Painter {
            bail!(
                "--smooth: only the painter paints with anti-aliased fills (use --backend painter)"
            );
        }
        let start = std::time::Instant::now();
        let rgba = rendiff::raster::painter::draw_smooth(
            &job.tri,
            &job.raster_options(),
            job.settings.painter_sort,
            &job.budget,
        )?;
        let (w, h) = (job.tri.camera.width(), job.tri.camera.height());
        rendiff::image_io::write_png_rgba8(&out, w, h, &rgba)?;
        say(&format!(
            "{}: painter ({} order), anti-aliased fills, {w}x{h} in {:.1} ms -> {}\n",
            a.scene.display(),
            job.settings.painter_sort,
            start.elapsed().as_secs_f64() * 1e3,
            out.display()
        ))?;
        return Ok(Outcome::Ok);
    }
    let r = job.render(backend)?;
    r.frame.write_png(&out, encoding(&a.flags))?;
    if let Some(dir) = &a.flags.gbuffer {
        r.frame.write_gbuffer(dir)?;
    }
    say(&format!(
        "{}: {} {}x{} ({} sample{}/pixel) in {:.1} ms -> {}\n",
        a.scene.display(),
        backend,
        r.frame.width,
        r.frame.height,
        r.frame.samples * r.frame.samples,
        if r.frame.samples == 1 { "" } else { "s" },
        r.time_ms,
        out.display()
    ))?;
    Ok(Outcome::Ok)
}

/// Refuses `-o` names that do not end in `.EXT` (any case): the bytes
/// written would not be what the name says (`-o x.jpg` holding a PNG).
/// What exists and is not a file (`/dev/null`, a FIFO, a terminal) is
/// written into as it is: its name says nothing about a format. Checked
/// after the output is known not to be an input, which says more.
fn require_extension(out: &Path, ext: &str, what: &str) -> Result<()> {
    if std::fs::metadata(out).is_ok_and(|m| !m.is_file() && !m.is_dir()) {
        return Ok(());
    }
    let ok = out
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case(ext));
    if !ok {
        bail!("-o {}: {what}; use a .{ext} name", out.display());
    }
    Ok(())
}

/// An output's folder must exist before a long render starts.
fn check_output_dir(out: &Path) -> Result<()> {
    if let Some(dir) = out.parent().filter(|p| !p.as_os_str().is_empty())
        && !dir.is_dir()
    {
        bail!(
            "{}: the output folder {} does not exist",
            out.display(),
            dir.display()
        );
    }
    Ok(())
}

fn plan(a: &PlanArgs) -> Result<Outcome> {
    let ov = Overrides {
        no_plan: a.no_plan,
        memory_budget: memory_budget(a.memory_budget)?,
        ..Overrides::default()
    };
    let job = Prepared::load(&a.scene, &ov)?;
    warn_job(&job);
    say(&describe(&job))?;
    if a.count {
        let rendered = job.render(Backend::Ray)?;
        if let rendiff::Work::Ray { rays, .. } = rendered.work {
            say(&ray_count(&job, &rays))?;
        }
    }
    Ok(Outcome::Ok)
}

/// The seed's ray-count formula (p. 17) beside what a render cast: with N
/// samples, a ray tree of depth n (`max_depth`) and m lights, at most
/// N·(2ⁿ − 1) tree rays (2^(k−1) per sample at level k: one reflected and
/// one refracted child per node) and N·m·(2ⁿ − 1) shadow rays.
fn ray_count(job: &Prepared, r: &rendiff::ray::RayStats) -> String {
    let cam = &job.tri.camera;
    let n_samples = u64::from(cam.sample_width()) * u64::from(cam.sample_height());
    let depth = job.settings.max_depth.min(63);
    let m = job.tri.lights.len() as u64;
    let nodes = (1u64 << depth) - 1;
    let sat = |a: u64, b: u64| a.saturating_mul(b);
    let mut o = String::new();
    let _ = writeln!(
        o,
        "ray count (seed p. 17): N = {n_samples} samples, n = {depth} (max_depth), m = {m} lights"
    );
    let _ = writeln!(
        o,
        "  level 1 (primary)  {:>12} of at most {:>14}",
        r.primary, n_samples
    );
    for k in 2..=depth.min(u32::try_from(rendiff::ray::LEVELS).unwrap_or(u32::MAX) + 1) {
        let got = r.by_level[(k - 2) as usize];
        let _ = writeln!(
            o,
            "  level {k:<12} {got:>12} of at most {:>14}",
            sat(n_samples, 1u64 << (k - 1))
        );
    }
    let tree = r.primary + r.by_level.iter().sum::<u64>();
    let _ = writeln!(
        o,
        "  ray tree           {tree:>12} of at most {:>14} = N·(2ⁿ − 1)",
        sat(n_samples, nodes)
    );
    let _ = writeln!(
        o,
        "  shadow rays        {:>12} of at most {:>14} = N·m·(2ⁿ − 1)",
        r.shadow,
        sat(sat(n_samples, m), nodes)
    );
    let _ = writeln!(
        o,
        "  straight through   {:>12} (ior = 1 surfaces keep their level: outside the tree)",
        r.straight
    );
    let _ = writeln!(
        o,
        "  the gap: rays that leave the scene end their branch, only reflecting or refracting surfaces spawn children, total internal reflection spawns one, and the plan skips shadow rays no light needs"
    );
    o
}

/// What a scene contains and what the plan decides.
pub fn describe(job: &Prepared) -> String {
    let (s, t) = (&job.scene, &job.tri);
    let mut o = String::new();
    let cam = &t.camera;
    let _ = writeln!(o, "scene {}", s.path.display());
    let _ = writeln!(
        o,
        "image {}x{}, {} sample{}/pixel, background {:?}",
        cam.width(),
        cam.height(),
        cam.samples() * cam.samples(),
        if cam.samples() == 1 { "" } else { "s" },
        t.background.to_array()
    );
    let proj = match cam.projection() {
        rendiff::camera::Projection::Perspective { tan_half_fov } => {
            format!(
                "perspective fov_y {:.4}°",
                2.0 * tan_half_fov.atan().to_degrees()
            )
        }
        rendiff::camera::Projection::Orthographic { view_height } => {
            format!("orthographic view_height {view_height}")
        }
    };
    let _ = writeln!(
        o,
        "camera {proj}, eye {:?}, forward {:?}, near {}, far {:.6}",
        cam.eye().to_array(),
        round3(cam.forward().to_array()),
        cam.near(),
        cam.far()
    );
    let _ = writeln!(o, "lights {}", t.lights.len());
    for (i, l) in t.lights.iter().enumerate() {
        let what = match l.kind {
            LightKind::Point { position } => format!("point at {:?}", position.to_array()),
            LightKind::Parallel { direction } => format!(
                "parallel along {:?}",
                round3(direction.to_array().map(f64::from))
            ),
        };
        let mut extra = String::new();
        if l.shadowless {
            extra.push_str(", shadowless");
        }
        if let Some((d, p)) = l.fade {
            let _ = write!(extra, ", fade {d} power {p}");
        }
        let _ = writeln!(o, "  [{i}] {what}, color {:?}{extra}", l.color.to_array());
    }
    let _ = writeln!(o, "materials {}", t.materials.len());
    for m in &t.materials {
        let pig = match &m.pigment {
            Pigment::Color(c) => format!("{:?}", c.to_array()),
            Pigment::Image(tex) => format!("image {}x{}", tex.width(), tex.height()),
        };
        let _ = writeln!(
            o,
            "  {}: pigment {pig}, ambient {} diffuse {} phong {} specular {} reflection {} filter {} transmit {} ior {}{}",
            m.name,
            m.ambient,
            m.diffuse,
            m.phong,
            m.specular,
            m.reflection,
            m.filter,
            m.transmit,
            m.ior,
            if m.bump.is_some() { ", bump" } else { "" }
        );
    }
    let _ = writeln!(o, "objects {}, triangles {}", t.objects.len(), t.len());
    for info in &t.objects {
        let b = info.bounds;
        let _ = writeln!(
            o,
            "  {}: {} triangles{}{}, {}{}{}, bounds {:?} .. {:?}",
            info.label,
            info.tris.len(),
            info.segments
                .map(|n| format!(" ({n} segments)"))
                .unwrap_or_default(),
            if info.tris.is_empty() {
                String::new()
            } else {
                format!(", ids {}-{}", info.tris.start, info.tris.end - 1)
            },
            if info.closed { "closed" } else { "open" },
            if info.smooth { ", smooth" } else { "" },
            if info.no_shadow { ", no_shadow" } else { "" },
            round3(b.min.to_array().map(f64::from)),
            round3(b.max.to_array().map(f64::from)),
        );
    }
    let _ = writeln!(
        o,
        "plan{}",
        if job.settings.plan {
            ""
        } else {
            " (--no-plan)"
        }
    );
    o.push_str(&job.plan.to_string());
    o
}

fn round3(v: [f64; 3]) -> [f64; 3] {
    v.map(|x| (x * 1000.0).round() / 1000.0 + 0.0)
}

/// `rendiff review`: the pending snapshot images, one by one.
fn review(a: &ReviewArgs) -> Result<Outcome> {
    use rendiff::snapshot;
    use std::io::{BufRead, IsTerminal};
    let pending = snapshot::pending(&a.dir)?;
    if pending.is_empty() {
        say(&format!("no pending images under {}\n", a.dir.display()))?;
        return Ok(Outcome::Ok);
    }
    let budget = rendiff::budget::Budget::new(rendiff::budget::DEFAULT_MEMORY_BUDGET);
    let interactive = !a.accept_all && !a.reject_all && std::io::stdin().is_terminal();
    let mut left = 0usize;
    let mut stdin = std::io::stdin().lock();
    for (k, p) in pending.iter().enumerate() {
        let name = p
            .pending
            .strip_prefix(&a.dir)
            .unwrap_or(&p.pending)
            .display()
            .to_string();
        say(&format!("[{}/{}] {name}\n", k + 1, pending.len()))?;
        // A pending file that is not a readable PNG can be rejected, never
        // accepted.
        let readable = rendiff::image_io::read_png_linear_within(&p.pending, None, &budget)
            .map_err(|e| e.to_string());
        if let Err(e) = &readable {
            say(&format!("  not a readable image: {e}\n"))?;
        } else if p.golden.exists() {
            match rendiff::diff::diff_images(&p.golden, &p.pending, None, &budget) {
                Ok(r) => {
                    say(&r.report.summary())?;
                    if let Some(out) = &a.out {
                        let dir = out.join(name.trim_end_matches(snapshot::PENDING_SUFFIX));
                        if let Some(parent) = dir.parent() {
                            std::fs::create_dir_all(parent).with_context(|| {
                                format!("could not create {}", parent.display())
                            })?;
                        }
                        let o = rendiff::output::OutputDir::begin(
                            &dir,
                            &[p.golden.clone(), p.pending.clone(), a.dir.clone()],
                        )?;
                        rendiff::diff::write_outputs(
                            &r,
                            None,
                            o.path(),
                            rendiff::image_io::PngEncoding::Srgb8,
                        )?;
                        o.commit()?;
                        say(&format!(
                            "  pictures: {}\n",
                            dir.join("index.html").display()
                        ))?;
                    }
                }
                // A changed size (or an unreadable golden) is a verdict too.
                Err(e) => say(&format!("  differs: {e}\n"))?,
            }
        } else {
            say(&format!("  new: no golden yet at {}\n", p.golden.display()))?;
        }
        let choice = if a.accept_all {
            'a'
        } else if a.reject_all {
            'r'
        } else if interactive {
            eprint!("  [a]ccept, [r]eject, [s]kip? ");
            let mut line = String::new();
            stdin.read_line(&mut line)?;
            line.trim().chars().next().unwrap_or('s')
        } else {
            's'
        };
        match choice {
            'a' | 'A' if readable.is_err() => {
                say("  not accepted: it is not a readable image (reject it)\n")?;
                left += 1;
            }
            'a' | 'A' => {
                p.accept()?;
                say(&format!("  accepted: {}\n", p.golden.display()))?;
            }
            'r' | 'R' => {
                p.reject()?;
                say("  rejected\n")?;
            }
            _ => left += 1,
        }
    }
    if left > 0 {
        warn(&format!(
            "{left} image(s) still pending; accept or reject them with `rendiff review {} --accept-all`, `--reject-all`, or one by one on a terminal",
            a.dir.display()
        ));
        return Ok(Outcome::Differs);
    }
    Ok(Outcome::Ok)
}

/// The scenes of shard `K/N` (all without one): a scene belongs to shard
/// `1 + fnv1a(path) mod N`, its path relative to the current folder (as
/// given, or with the current folder's prefix taken off an absolute one)
/// with `/` separators, so the assignment is the same on every machine,
/// run and order of arguments.
fn shard(scenes: Vec<PathBuf>, shard: Option<(u64, u64)>) -> Vec<PathBuf> {
    let Some((k, n)) = shard else {
        return scenes;
    };
    let fnv1a = |s: &str| {
        s.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
            (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
        })
    };
    let cwd = std::env::current_dir().unwrap_or_default();
    scenes
        .into_iter()
        .filter(|p| {
            let rel = p.strip_prefix(&cwd).unwrap_or(p);
            let key = rel.to_string_lossy().replace('\\', "/");
            fnv1a(key.trim_start_matches("./")) % n == k - 1
        })
        .collect()
}

/// POV-Ray references are named by the scene's file name in one golden
/// folder (DESIGN.md §5): two scenes of one name (`a/x.toml`, `b/x.toml`)
/// would read and overwrite each other's references, so a request that
/// names both is refused, naming both.
fn refuse_shared_reference_names<'a>(jobs: impl Iterator<Item = &'a Prepared>) -> Result<()> {
    let mut seen: std::collections::HashMap<String, &Path> = std::collections::HashMap::new();
    for job in jobs {
        let name = job.scene.name();
        if let Some(first) = seen.insert(name.clone(), &job.scene.path) {
            bail!(
                "{} and {}: both would use the POV-Ray references named {name} in one golden folder; give one its own --golden DIR (or rename it)",
                first.display(),
                job.scene.path.display()
            );
        }
    }
    Ok(())
}

/// `rendiff report`: verdicts of several runs as one.
fn report(a: &ReportArgs) -> Result<Outcome> {
    fn collect(path: &Path, out: &mut Vec<serde_json::Value>) -> Result<()> {
        if path.is_dir() {
            let mut entries: Vec<PathBuf> = std::fs::read_dir(path)
                .with_context(|| format!("could not read {}", path.display()))?
                .map(|e| e.map(|e| e.path()))
                .collect::<Result<_, _>>()
                .with_context(|| format!("could not read {}", path.display()))?;
            entries.sort();
            for e in entries {
                if e.is_dir() || e.file_name().is_some_and(|n| n == "report.json") {
                    collect(&e, out)?;
                }
            }
            return Ok(());
        }
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("could not read {}", path.display()))?;
        let v: serde_json::Value = serde_json::from_str(&text).with_context(|| {
            format!(
                "{}: expected the JSON of `rendiff diff --json`",
                path.display()
            )
        })?;
        let items = match v {
            serde_json::Value::Array(items) => items,
            one => vec![one],
        };
        for item in items {
            if item
                .get("scene")
                .and_then(serde_json::Value::as_str)
                .is_none()
                || !matches!(
                    item.get("verdict").and_then(serde_json::Value::as_str),
                    Some("pass" | "fail")
                )
                || item
                    .get("schema_version")
                    .is_some_and(|v| v.as_u64() != Some(2))
            {
                bail!(
                    "{}: expected reports with \"scene\" and a \"verdict\" of pass or fail, schema_version 2 (the JSON of `rendiff diff --json`)",
                    path.display()
                );
            }
            out.push(item);
        }
        Ok(())
    }
    let mut all = Vec::new();
    for p in &a.inputs {
        let before = all.len();
        collect(p, &mut all)?;
        if all.len() == before {
            // A shard's artefact that is missing must not turn the merge green.
            bail!(
                "{}: holds no report (expected the JSON of `rendiff diff --json`, or folders with report.json)",
                p.display()
            );
        }
    }
    let str_of = |v: &serde_json::Value, k: &str| v[k].as_str().unwrap_or_default().to_string();
    all.sort_by_key(|v| (str_of(v, "scene"), str_of(v, "a"), str_of(v, "b")));
    let failed = all.iter().filter(|v| v["verdict"] != "pass").count();
    for w in all.windows(2) {
        let key = |v: &serde_json::Value| (str_of(v, "scene"), str_of(v, "a"), str_of(v, "b"));
        if key(&w[0]) == key(&w[1]) {
            warn(&format!(
                "{}: {} vs {} is reported twice (overlapping shards or inputs)",
                str_of(&w[0], "scene"),
                str_of(&w[0], "a"),
                str_of(&w[0], "b")
            ));
        }
    }
    if a.json {
        emit(format!("{}\n", serde_json::to_string_pretty(&all)?).as_bytes())?;
    } else {
        let mut text = String::new();
        for v in &all {
            text.push_str(&format!(
                "{}: {} vs {}: {}\n",
                str_of(v, "scene"),
                str_of(v, "a"),
                str_of(v, "b"),
                str_of(v, "verdict")
            ));
        }
        text.push_str(&format!(
            "{} report(s): {} passed, {failed} failed\n",
            all.len(),
            all.len() - failed
        ));
        say(&text)?;
    }
    Ok(if failed == 0 {
        Outcome::Ok
    } else {
        Outcome::Differs
    })
}
