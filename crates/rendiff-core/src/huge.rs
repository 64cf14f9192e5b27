//! Large arrays of plain values in memory advised for transparent huge
//! pages.
//!
//! A BVH build writes every byte of its large arrays once (the boxes it
//! partitions, the nodes, the triangle packs and their ids: about 56 MB
//! for the 940 k-triangle bunny), and each first touch of a 4 KB page is
//! a page fault, about 2 µs apiece on the virtual machines measured: some
//! 14 000 of them, 8 % of the build. Embree asks the kernel to back its
//! allocations with 2 MB pages (`madvise(MADV_HUGEPAGE)`, seen under
//! `strace`); so does [`Big`] on Linux, for arrays of at least
//! [`MAPPED_BYTES`], by an anonymous map ([`memmap2`], the crate ripgrep
//! reads files with) advised before anything touches it and seen as a
//! slice of `T` through [`bytemuck`] (so `T` is plain old data: no
//! padding, every bit pattern a value). The advice is only advice: where
//! the kernel gives no huge pages (THP off) the map is ordinary memory,
//! and a map that cannot be made falls back to a `Vec`; smaller arrays,
//! and every array on other systems, are `Vec`s. Each access through a
//! `Big` checks its form and casts the map's bytes, so a walk takes the
//! slices once ([`Big`] derefs to `[T]`). A frame's sample buffers are
//! `Big`s for the same reason: a one-off render of a 320×240 scene at 2×2
//! samples touches 7.4 MB of fresh frame memory, some 1 800 faults.
//! ARCHITECTURE.md, "Huge pages for the build's arrays" and "Huge pages
//! for the frames", has the measurements.

use bytemuck::Pod;
use memmap2::MmapMut;
use rayon::prelude::*;

/// The size of a transparent huge page on x86-64 and on aarch64 with 4 KB
/// pages (and the alignment a map's array starts at, so that its huge
/// pages cover it from its first byte). Where the kernel's huge pages are
/// larger (aarch64 with 64 KB pages: 512 MB) the alignment is wasted and
/// arrays below that size get no huge page: correct, without the gain.
const HUGE_PAGE: usize = 2 << 20;

/// Arrays of at least this many bytes are mapped: a map is three system
/// calls (map, advise, unmap) and a kernel object, at most 10 µs here,
/// and a huge page's first touch zeroes all of it (touching 8 MB took
/// 0.39 ms in huge pages, so at most 0.1 ms a huge page), against the
/// 256 faults of 4 KB pages that 1 MB takes (the same 8 MB took 1.87 ms
/// in small pages, 0.9 µs a fault: 0.23 ms). The map holds whole huge
/// pages, so a smaller array's one huge page lies wholly inside it.
pub const MAPPED_BYTES: usize = 1 << 20;

/// An array of `T`, mapped and advised for huge pages when large (see the
/// module's documentation), else a `Vec`. It derefs to `[T]`.
pub struct Big<T: Pod> {
    /// The values, unless `map` holds them.
    heap: Vec<T>,
    /// The map, the offset of the array in it (where a huge page starts)
    /// and the number of `T` it holds.
    map: Option<(MmapMut, usize, usize)>,
}

impl<T: Pod + PartialEq> PartialEq for Big<T> {
    fn eq(&self, other: &Self) -> bool {
        **self == **other
    }
}

/// A `Vec`'s values, in the `Vec` (no copy, so no huge pages: arrays made
/// for speed are made by [`Big::filled`], [`Big::from_fn`] or
/// [`Big::zeroed`]).
impl<T: Pod> From<Vec<T>> for Big<T> {
    fn from(heap: Vec<T>) -> Self {
        Big { heap, map: None }
    }
}

/// Collected into a `Vec` (as [`From<Vec<T>>`]).
impl<T: Pod> FromIterator<T> for Big<T> {
    fn from_iter<I: IntoIterator<Item = T>>(iter: I) -> Self {
        Big::from(iter.into_iter().collect::<Vec<T>>())
    }
}

impl<T: Pod> Default for Big<T> {
    fn default() -> Self {
        Big {
            heap: Vec::new(),
            map: None,
        }
    }
}

impl<T: Pod + std::fmt::Debug> std::fmt::Debug for Big<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

impl<T: Pod> Clone for Big<T> {
    fn clone(&self) -> Self {
        match mapped(self.len()) {
            Some(mut c) => {
                c.copy_from_slice(self);
                c
            }
            None => Big {
                heap: self.to_vec(),
                map: None,
            },
        }
    }
}

impl<T: Pod> Big<T> {
    /// `n` values with every byte zero: untouched memory where mapped;
    /// else a `Vec` (for `u64` and other primitives, memory the allocator
    /// gets zeroed from the system; a struct's zeros are written).
    pub fn zeroed(n: usize) -> Big<T> {
        mapped(n).unwrap_or_else(|| Big {
            heap: vec![T::zeroed(); n],
            map: None,
        })
    }

    /// `n` copies of `value`, written in parallel (each page first
    /// touched by the thread that fills it) where large, a run at a time
    /// (`fill`, the compiler's memset-like loop: one value per element
    /// through a closure cost a small frame's reset three times the
    /// instructions).
    pub fn filled(n: usize, value: T) -> Big<T>
    where
        T: Send + Sync,
    {
        match mapped(n) {
            Some(mut b) => {
                fill(&mut b, value);
                b
            }
            None if n < FILL_RUN => Big::from(vec![value; n]),
            None => {
                let mut v = Vec::with_capacity(n);
                v.par_extend(rayon::iter::repeat_n(value, n));
                Big::from(v)
            }
        }
    }

    /// The values `f(0), …, f(n − 1)`, formed in parallel and written
    /// once.
    pub fn from_fn(n: usize, f: impl Fn(usize) -> T + Sync) -> Big<T>
    where
        T: Send + Sync,
    {
        match mapped(n) {
            Some(mut b) => {
                b.par_iter_mut().enumerate().for_each(|(k, x)| *x = f(k));
                b
            }
            None => Big {
                heap: (0..n).into_par_iter().map(&f).collect(),
                map: None,
            },
        }
    }

    /// Appends `values` (a mapped array becomes a `Vec` first: only the
    /// light buffer's leaves grow this way, and they start empty).
    pub fn extend_from_slice(&mut self, values: &[T]) {
        self.heap().extend_from_slice(values);
    }

    /// Appends one value (as [`Big::extend_from_slice`]).
    pub fn push(&mut self, value: T) {
        self.heap().push(value);
    }

    /// The values as a slice (what `Deref` gives).
    #[must_use]
    pub fn as_slice(&self) -> &[T] {
        self
    }

    /// Makes this array `n` copies of `value`, in the memory it holds
    /// where that is large enough (memory written before costs no fault:
    /// `Frame::reset` and the rasterizer's buffers are refilled frame
    /// after frame), else in a fresh array.
    pub fn refill(&mut self, n: usize, value: T)
    where
        T: Send + Sync,
    {
        let room = match &self.map {
            Some((m, at, _)) => (m.len() - at) / size_of::<T>().max(1),
            None => self.heap.capacity(),
        };
        if room < n {
            *self = Big::filled(n, value);
            return;
        }
        if let Some((_, _, len)) = &mut self.map {
            *len = n;
            fill(self, value);
        } else {
            self.heap.truncate(n);
            fill(&mut self.heap, value);
            self.heap.resize(n, value);
        }
    }

    /// The values as a growable `Vec`, converting a map into one.
    fn heap(&mut self) -> &mut Vec<T> {
        if let Some((m, at, n)) = self.map.take() {
            self.heap = values(&m, at, n).to_vec();
        }
        &mut self.heap
    }
}

/// Elements written by one task of [`fill`], and the size below which a
/// fresh `Vec` is filled on the calling thread.
const FILL_RUN: usize = 1 << 16;

/// Writes `value` into every element of `values`, runs of [`FILL_RUN`] in
/// parallel.
fn fill<T: Pod + Send + Sync>(values: &mut [T], value: T) {
    values
        .par_chunks_mut(FILL_RUN)
        .for_each(|run| run.fill(value));
}

/// `n` values with every byte zero in a map advised for huge pages, where
/// they fill at least [`MAPPED_BYTES`] and the system makes the map; on
/// Linux only (the one system `memmap2` advises huge pages on: elsewhere a
/// map would cost its system calls and give nothing).
fn mapped<T: Pod>(n: usize) -> Option<Big<T>> {
    let bytes = n.checked_mul(size_of::<T>())?;
    if bytes < MAPPED_BYTES || !cfg!(target_os = "linux") {
        return None;
    }
    let (map, at) = advised_map(bytes)?;
    Some(Big {
        heap: Vec::new(),
        map: Some((map, at, n)),
    })
}

/// An anonymous map with room for `bytes` from an offset where a huge
/// page starts, advised for transparent huge pages, and that offset;
/// `None` when the system makes no map. (The address space before the
/// array is never touched and costs no memory; the map holds the array's
/// bytes rounded up to whole huge pages after the offset, so the huge
/// page that holds the array's end lies wholly inside it and the kernel
/// can back all of it: up to 2 MB beyond the array, as for any array of
/// huge pages.)
fn advised_map(bytes: usize) -> Option<(MmapMut, usize)> {
    let whole = bytes.checked_next_multiple_of(HUGE_PAGE)?;
    let map = MmapMut::map_anon(whole.checked_add(HUGE_PAGE)?).ok()?;
    let at = (HUGE_PAGE - map.as_ptr().addr() % HUGE_PAGE) % HUGE_PAGE;
    // Only advice: without huge pages the map is ordinary memory.
    #[cfg(target_os = "linux")]
    let _ = map.advise(memmap2::Advice::HugePage);
    Some((map, at))
}

impl<T: Pod> std::ops::Deref for Big<T> {
    type Target = [T];

    fn deref(&self) -> &[T] {
        match &self.map {
            Some((m, at, n)) => values(m, *at, *n),
            None => &self.heap,
        }
    }
}

impl<T: Pod> std::ops::DerefMut for Big<T> {
    fn deref_mut(&mut self) -> &mut [T] {
        match &mut self.map {
            Some((m, at, n)) => bytemuck::cast_slice_mut(&mut m[*at..*at + *n * size_of::<T>()]),
            None => &mut self.heap,
        }
    }
}

impl<'a, T: Pod> IntoIterator for &'a Big<T> {
    type Item = &'a T;
    type IntoIter = std::slice::Iter<'a, T>;

    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

/// The `n` values a map holds from byte `at`. The array starts on a huge
/// page's boundary (aligned for every `T` stored here: the largest
/// alignment is a node's 64 bytes) and spans exactly `n` values' bytes,
/// so the cast cannot fail.
fn values<T: Pod>(m: &MmapMut, at: usize, n: usize) -> &[T] {
    bytemuck::cast_slice(&m[at..at + n * size_of::<T>()])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Both forms hold the values they were given, grow, and clone.
    #[test]
    fn mapped_and_heap_arrays_hold_their_values() {
        for n in [0, 3, MAPPED_BYTES / 4 + 5] {
            let mut b = Big::<u32>::from_fn(n, |k| u32::try_from(k).unwrap_or(0) * 3);
            assert_eq!(
                b.map.is_some(),
                n * 4 >= MAPPED_BYTES && cfg!(target_os = "linux"),
                "{n}: mapped exactly when large"
            );
            assert_eq!(b.len(), n);
            if b.map.is_some() {
                assert_eq!(
                    b.as_ptr().addr() % HUGE_PAGE,
                    0,
                    "{n}: a mapped array starts where a huge page does"
                );
            }
            assert!(
                b.iter()
                    .enumerate()
                    .all(|(k, &x)| x == u32::try_from(k).unwrap_or(0) * 3)
            );
            let c = b.clone();
            assert_eq!(&*c, &*b);
            b.push(7);
            b.extend_from_slice(&[8, 9]);
            assert_eq!(b.len(), n + 3);
            assert_eq!(&b[n..], &[7, 8, 9]);
            assert_eq!(&b[..n], &*c, "growing keeps the values");
        }
        let f = Big::filled(MAPPED_BYTES, 5u8);
        assert!(f.iter().all(|&x| x == 5));
    }

    /// `refill` gives exactly `n` copies whatever the form and size
    /// before (growing past its room, shrinking, growing back within it),
    /// keeps a map's memory while it has room, and `filled` agrees.
    #[test]
    fn refill_gives_n_copies_in_either_form() {
        let big = MAPPED_BYTES / 4 + 5;
        let mut b = Big::<u32>::default();
        for (k, n) in [3, big, 10, big - 1, 0, 70_000, 1, big]
            .into_iter()
            .enumerate()
        {
            let v = u32::try_from(k).unwrap_or(0) + 100;
            let before = b.as_ptr().addr();
            let mapped_before = b.map.is_some();
            b.refill(n, v);
            assert_eq!(b.len(), n, "refill {k} to {n}");
            assert!(b.iter().all(|&x| x == v), "refill {k}: every value");
            if mapped_before && n <= big {
                assert_eq!(b.as_ptr().addr(), before, "a map with room is reused");
            }
            assert_eq!(&*Big::filled(n, v), &*b, "filled agrees at {n}");
        }
    }
}
