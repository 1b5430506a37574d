//! Integration tests of `mme-core`: every result is checked against something
//! independent (brute-force least squares, analytic limits, simulated truth).

mod suite;
