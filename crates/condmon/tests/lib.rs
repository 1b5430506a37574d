//! Integration tests of `condmon`: classifiers against analytic Bayes errors, PCA against
//! an independent SVD, weight canonicalisation against network outputs, cross-validation
//! folds and hand-computed leave-one-out, and typed errors for bad input.

#[path = "cases/bad_input.rs"]
mod bad_input;
#[path = "cases/bayes_error.rs"]
mod bayes_error;
#[path = "cases/canonical.rs"]
mod canonical;
#[path = "cases/common.rs"]
mod common;
#[path = "cases/cv.rs"]
mod cv;
#[path = "cases/pca.rs"]
mod pca;
