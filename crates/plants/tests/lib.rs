//! Integration tests of `plants`: truth corrections against independent evaluation, the
//! request entry point (determinism, noise, rates, overrides, errors).

mod corrections;
mod requests;
