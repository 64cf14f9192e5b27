//! The `rendiff` command: a thin layer over the library's public API.
//!
//! Exit status: 0 success (or within tolerance), 1 a comparison outside its
//! tolerance (or a stale golden), 2 bad input or usage. Errors are one
//! paragraph naming the file, the place and what was expected.

mod args;
mod cmd;

use std::process::ExitCode;

use clap::Parser;

/// What a command concluded.
pub enum Outcome {
    /// Success / within tolerance.
    Ok,
    /// A comparison outside its tolerance, or a stale reference.
    Differs,
}

fn main() -> ExitCode {
    // A panic is a bug, never an answer: report it as one, without a
    // backtrace, and with an exit status no normal outcome uses.
    std::panic::set_hook(Box::new(|info| {
        use std::io::Write;
        let text = info.to_string();
        let _ = writeln!(
            std::io::stderr(),
            "rendiff: internal error (this is a bug, please report it): {}",
            rendiff::escape::message(&text)
        );
    }));
    on_signals();
    let cli = args::Cli::parse();
    let result = std::panic::catch_unwind(|| cmd::run(cli));
    report_peak_memory();
    if rendiff::cleanup::is_interrupted() {
        // The signal's thread is exiting with the signal's status; what
        // the run ended with (a killed child's failure) is not an answer.
        loop {
            std::thread::park();
        }
    }
    match result {
        Ok(Ok(Outcome::Ok)) => ExitCode::SUCCESS,
        Ok(Ok(Outcome::Differs)) => ExitCode::from(1),
        Ok(Err(err)) => {
            use std::io::Write;
            let text = one_paragraph(&err);
            let _ = writeln!(
                std::io::stderr(),
                "error: {}",
                rendiff::escape::message(&text)
            );
            ExitCode::from(2)
        }
        Err(_) => ExitCode::from(101),
    }
}

/// On SIGINT, SIGTERM or SIGHUP: remove the temporaries not yet renamed
/// into place, stop the POV-Ray children, and exit as the signal would
/// (128 + its number), leaving only complete files behind.
///
/// SIGXFSZ (a file-size limit reached, `ulimit -f`) is caught rather than
/// left to kill the process: the write then fails with EFBIG and is
/// reported like a full disk, with the old outputs kept.
fn on_signals() {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM, SIGXFSZ};
    let _ = signal_hook::flag::register(
        SIGXFSZ,
        std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false)),
    );
    let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]) else {
        return;
    };
    std::thread::spawn(move || {
        if let Some(sig) = signals.forever().next() {
            rendiff::cleanup::interrupted();
            std::process::exit(128 + sig);
        }
    });
}

/// With `RENDIFF_PEAK_RSS` set, the process's peak resident memory
/// (`VmHWM` of /proc/self/status, read by the process itself just before
/// it exits, so nothing is missed) on standard error as `peak RSS: N kB`:
/// how the tests measure the memory of a refused or completed request.
fn report_peak_memory() {
    use std::io::Write;
    if std::env::var_os("RENDIFF_PEAK_RSS").is_none() {
        return;
    }
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    if let Some(line) = status.lines().find(|l| l.starts_with("VmHWM:")) {
        let kb = line.trim_start_matches("VmHWM:").trim();
        let _ = writeln!(std::io::stderr(), "peak RSS: {kb}");
    }
}

/// The error and its causes as one paragraph (no error's Display repeats
/// its source, so each appears once).
fn one_paragraph(err: &anyhow::Error) -> String {
    err.chain()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join(": ")
}
