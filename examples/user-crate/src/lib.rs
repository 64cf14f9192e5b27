//! An example crate whose tests put its scene under regression with rendiff.
