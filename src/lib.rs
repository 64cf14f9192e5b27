//! The library half of the `rendiff` command line: the benchmark sweeps
//! (`rendiff bench`), their plots and the scaling fits. They live here, not
//! in the `rendiff` library, because they need plotters and indicatif,
//! which no user of the library should have to compile.

#![warn(missing_docs, missing_debug_implementations)]

pub mod bench;
