//! What an interrupted run must undo: the temporary files and folders it
//! has not renamed into place yet, and the child processes (POV-Ray) it
//! started.
//!
//! Everything that creates a temporary or a child registers it here for
//! as long as it exists (a guard unregisters it on drop). A program that
//! catches SIGINT or SIGTERM calls [`interrupted`] from its handler before
//! it exits: the temporaries are removed and the children terminated, so
//! nothing is left behind but what was complete. (A SIGKILL cannot be
//! caught; what it leaves is a temporary file with an unpredictable name,
//! never a half-written target.)

use std::path::{Path, PathBuf};
use std::sync::Mutex;

#[derive(Default)]
struct Registry {
    temps: Vec<(u64, PathBuf)>,
    children: Vec<(u64, u32)>,
    next: u64,
}

static REGISTRY: Mutex<Registry> = Mutex::new(Registry {
    temps: Vec::new(),
    children: Vec::new(),
    next: 0,
});

fn registry() -> std::sync::MutexGuard<'static, Registry> {
    REGISTRY
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// A registered temporary file or folder: removed by [`interrupted`] while
/// the guard lives; dropping the guard only unregisters it (the owner has
/// renamed or removed it).
#[derive(Debug)]
pub struct TempGuard(u64);

impl TempGuard {
    /// Registers `path`.
    #[must_use]
    pub fn new(path: &Path) -> TempGuard {
        let mut r = registry();
        r.next += 1;
        let id = r.next;
        r.temps.push((id, path.to_path_buf()));
        TempGuard(id)
    }
}

impl Drop for TempGuard {
    fn drop(&mut self) {
        registry().temps.retain(|(id, _)| *id != self.0);
    }
}

/// A registered child process: terminated by [`interrupted`] while the
/// guard lives.
#[derive(Debug)]
pub struct ChildGuard(u64);

impl ChildGuard {
    /// Registers the child with process id `pid`.
    #[must_use]
    pub fn new(pid: u32) -> ChildGuard {
        let mut r = registry();
        r.next += 1;
        let id = r.next;
        r.children.push((id, pid));
        ChildGuard(id)
    }
}

impl Drop for ChildGuard {
    fn drop(&mut self) {
        registry().children.retain(|(id, _)| *id != self.0);
    }
}

/// Kills every registered child (SIGKILL: POV-Ray can take seconds to
/// act on SIGTERM, and it writes only into rendiff's scratch folder, which
/// goes next), then removes every registered temporary; returns how many
/// of each. For a signal handler that is about to exit. (A child is
/// unregistered right after it is reaped, so the window in which its
/// process id could be reused by another process is the drop of a guard.)
pub fn interrupted() -> (usize, usize) {
    INTERRUPTED.store(true, std::sync::atomic::Ordering::SeqCst);
    let r = registry();
    for (_, pid) in &r.children {
        if let Some(pid) = i32::try_from(*pid)
            .ok()
            .and_then(rustix::process::Pid::from_raw)
        {
            let _ = rustix::process::kill_process(pid, rustix::process::Signal::KILL);
        }
    }
    // SIGKILL is delivered asynchronously: a child tearing down a large
    // address space on a loaded machine can run on for a moment. Wait
    // (2 s at most) until each is dead, so none outlives rendiff in its
    // scratch folder.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(2);
    while r.children.iter().any(|(_, pid)| !dead(*pid)) && std::time::Instant::now() < deadline {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    for (_, path) in &r.temps {
        if path.is_dir() {
            let _ = std::fs::remove_dir_all(path);
        } else {
            let _ = std::fs::remove_file(path);
        }
    }
    (r.children.len(), r.temps.len())
}

/// Whether process `pid` has ended (a zombie awaiting its parent, or
/// gone), from the state field of `/proc/PID/stat`.
fn dead(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat")).map_or(true, |stat| {
        stat.rsplit_once(')')
            .and_then(|(_, rest)| rest.trim_start().chars().next())
            .is_none_or(|state| matches!(state, 'Z' | 'X'))
    })
}

static INTERRUPTED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Whether [`interrupted`] has run: what fails after it (a POV-Ray child it
/// killed) is the interruption, not an error to report.
#[must_use]
pub fn is_interrupted() -> bool {
    INTERRUPTED.load(std::sync::atomic::Ordering::SeqCst)
}

#[cfg(test)]
/// The temporaries registered now (for tests).
#[must_use]
pub(crate) fn registered_temps() -> Vec<PathBuf> {
    registry().temps.iter().map(|(_, p)| p.clone()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// (What [`interrupted`] removes is tested on the binary, by signalling
    /// a running `rendiff`: calling it here would remove the temporaries of
    /// the other tests running beside this one.)
    #[test]
    fn guards_register_while_they_live() {
        let file = std::env::temp_dir().join("rendiff-cleanup-guard-test.tmp");
        let g = TempGuard::new(&file);
        assert!(registered_temps().contains(&file));
        drop(g);
        assert!(!registered_temps().contains(&file));
        let c = ChildGuard::new(u32::MAX);
        assert!(registry().children.iter().any(|(_, p)| *p == u32::MAX));
        drop(c);
        assert!(!registry().children.iter().any(|(_, p)| *p == u32::MAX));
    }
}
