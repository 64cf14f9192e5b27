//! The memory budget of one request (`--memory-budget`, 4 GiB by default).
//!
//! Every allocation that grows with the input — the scene's text, a mesh's
//! vertices and faces, a decoded image, a texture, the triangles, the
//! frames, the shadow maps, the painter's pairs — is estimated and
//! reserved here *before* it is made; a request that does not fit is
//! refused with the figure, instead of aborting when the allocator fails.
//! The budget is shared by everything one request loads and renders, so
//! the parts add up.
//!
//! The estimates are upper bounds measured on this code (each constant
//! says where); what is not proportional to the input (the program, the
//! thread stacks, a few small tables) is the fixed overhead that
//! `tests/it/hostile.rs` measures beside the budget.

use std::sync::atomic::{AtomicU64, Ordering};

/// The default memory budget of one request: 4 GiB.
pub const DEFAULT_MEMORY_BUDGET: u64 = 4 << 30;

/// A request that does not fit its budget.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "{what} would need about {}, over the memory budget of {} ({} already in use); shrink the input or raise --memory-budget",
    human(*.need),
    human(*.limit),
    human(*.used)
)]
pub struct OverBudget {
    /// What was asked for.
    pub what: String,
    /// Bytes it needs.
    pub need: u64,
    /// Bytes already reserved.
    pub used: u64,
    /// The budget.
    pub limit: u64,
}

/// A byte count as people read it (`1.50 GiB`, `12.0 MiB`, `800 B`).
#[must_use]
pub fn human(bytes: u64) -> String {
    #[expect(clippy::cast_precision_loss, reason = "a figure for people")]
    let b = bytes as f64;
    if b >= f64::from(1u32 << 30) {
        format!("{:.2} GiB", b / f64::from(1u32 << 30))
    } else if b >= f64::from(1u32 << 20) {
        format!("{:.1} MiB", b / f64::from(1u32 << 20))
    } else if b >= 1024.0 {
        format!("{:.1} KiB", b / 1024.0)
    } else {
        format!("{bytes} B")
    }
}

/// The memory one request may use, and what it has reserved so far.
#[derive(Debug)]
pub struct Budget {
    limit: u64,
    used: AtomicU64,
}

impl Default for Budget {
    fn default() -> Self {
        Budget::new(DEFAULT_MEMORY_BUDGET)
    }
}

impl Budget {
    /// A budget of `limit` bytes, nothing reserved.
    #[must_use]
    pub fn new(limit: u64) -> Budget {
        Budget {
            limit,
            used: AtomicU64::new(0),
        }
    }

    /// The budget in bytes.
    #[must_use]
    pub fn limit(&self) -> u64 {
        self.limit
    }

    /// Bytes reserved so far.
    #[must_use]
    pub fn used(&self) -> u64 {
        self.used.load(Ordering::Relaxed)
    }

    /// Bytes still free.
    #[must_use]
    pub fn remaining(&self) -> u64 {
        self.limit.saturating_sub(self.used())
    }

    /// Reserves `bytes` for `what` (a description, built only when the
    /// request is refused), or refuses without reserving anything.
    ///
    /// # Errors
    ///
    /// [`OverBudget`] when the total would exceed the budget.
    pub fn reserve(&self, bytes: u64, what: impl FnOnce() -> String) -> Result<(), OverBudget> {
        let mut used = self.used();
        loop {
            let total = used.saturating_add(bytes);
            if total > self.limit {
                return Err(OverBudget {
                    what: what(),
                    need: bytes,
                    used,
                    limit: self.limit,
                });
            }
            match self
                .used
                .compare_exchange_weak(used, total, Ordering::Relaxed, Ordering::Relaxed)
            {
                Ok(_) => return Ok(()),
                Err(now) => used = now,
            }
        }
    }

    /// Says whether `bytes` more would fit, reserving nothing.
    ///
    /// # Errors
    ///
    /// [`OverBudget`] when they would not.
    pub fn check(&self, bytes: u64, what: impl FnOnce() -> String) -> Result<(), OverBudget> {
        let used = self.used();
        if used.saturating_add(bytes) > self.limit {
            return Err(OverBudget {
                what: what(),
                need: bytes,
                used,
                limit: self.limit,
            });
        }
        Ok(())
    }

    /// Gives back `bytes` reserved earlier (a temporary buffer freed).
    pub fn release(&self, bytes: u64) {
        let _ = self
            .used
            .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |u| {
                Some(u.saturating_sub(bytes))
            });
    }
}

/// The most worker threads `--threads` may ask for: 8 per core the machine
/// has (at least 64). More would only add scheduling and memory (each
/// thread's stack), never speed; thousands of threads exhaust the process.
#[must_use]
pub fn max_threads() -> usize {
    let cores = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
    (cores * 8).max(64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reservations_add_up_and_refusals_reserve_nothing() {
        let b = Budget::new(1000);
        b.reserve(600, || "a".into()).unwrap();
        let e = b.reserve(500, || "the big one".into()).unwrap_err();
        assert_eq!((e.need, e.used, e.limit), (500, 600, 1000));
        assert!(
            e.to_string()
                .starts_with("the big one would need about 500 B")
        );
        assert_eq!(b.used(), 600);
        b.reserve(400, || "b".into()).unwrap();
        assert_eq!(b.remaining(), 0);
        b.release(400);
        assert_eq!(b.used(), 600);
        assert!(b.check(401, String::new).is_err());
        assert_eq!(human(3 << 30), "3.00 GiB");
    }
}
