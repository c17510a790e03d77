//! Test support, kept out of the product's crates: tests link it as a dev-dependency, no
//! process does.

pub mod python;
