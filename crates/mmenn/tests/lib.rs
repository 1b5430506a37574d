//! Integration tests of the facade: every workflow end to end through files.

mod fit;
mod monitor;
mod simulate;
