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
        eprintln!("rendiff: internal error (this is a bug, please report it): {info}");
    }));
    let cli = args::Cli::parse();
    let result = std::panic::catch_unwind(|| cmd::run(cli));
    match result {
        Ok(Ok(Outcome::Ok)) => ExitCode::SUCCESS,
        Ok(Ok(Outcome::Differs)) => ExitCode::from(1),
        Ok(Err(err)) => {
            eprintln!("error: {}", one_paragraph(&err));
            ExitCode::from(2)
        }
        Err(_) => ExitCode::from(101),
    }
}

/// The error and its causes, each once, as one paragraph.
fn one_paragraph(err: &anyhow::Error) -> String {
    let mut parts: Vec<String> = Vec::new();
    for cause in err.chain() {
        let s = cause.to_string();
        if !parts.iter().any(|p| p.contains(&s)) {
            parts.push(s);
        }
    }
    parts.join(": ")
}
