//! The subspace start of the linear state-space baseline: the poles of PO-MOESP's `A`
//! grouped into sections, then numerators, feedthrough and (optionally) the input bias by
//! linear least squares.

use nalgebra::DMatrix;

use super::model::{LinearSsModel, Record, Section};
use crate::error::{BaselineError, Result};
use crate::subspace::{Moesp, StreamingQr, solve_augmented_r};

/// Group eigenvalues into sections with zero numerators: complex pairs (upper half
/// plane), real poles paired in increasing order, one first-order block left for an odd
/// count.
fn sections_from_poles(poles: &[(f64, f64)], integrator: bool) -> Vec<Section> {
    let tol = 1e-10;
    let mut out = Vec::new();
    let mut poles = poles.to_vec();
    if integrator {
        // The pole nearest 1 becomes the integrator; its partner is the next real pole
        // nearest 1 (0.5 when none is real).
        let near = |v: &[(f64, f64)], real_only: bool| {
            v.iter()
                .enumerate()
                .filter(|(_, p)| !real_only || p.1.abs() <= tol)
                .min_by(|a, b| {
                    let d = |p: &(f64, f64)| (p.0 - 1.0).hypot(p.1);
                    d(a.1).total_cmp(&d(b.1))
                })
                .map(|(i, _)| i)
        };
        if let Some(i) = near(&poles, false) {
            let removed = poles.remove(i);
            if removed.1.abs() > tol
                && let Some(j) = poles
                    .iter()
                    .position(|p| (p.0 - removed.0).abs() <= tol && (p.1 + removed.1).abs() <= tol)
            {
                // A complex pair loses its conjugate too; the section keeps the modulus.
                poles.remove(j);
                poles.push((removed.0.hypot(removed.1), 0.0));
            }
            let p = match near(&poles, true) {
                Some(j) => poles.remove(j).0,
                None => 0.5,
            };
            out.push(Section::Integrating {
                p,
                b1: 0.0,
                b2: 0.0,
            });
        }
    }
    let mut real: Vec<f64> = Vec::new();
    for &(re, im) in &poles {
        if im > tol {
            out.push(Section::Second {
                a1: -2.0 * re,
                a2: re * re + im * im,
                b1: 0.0,
                b2: 0.0,
            });
        } else if im.abs() <= tol {
            real.push(re);
        }
    }
    real.sort_by(f64::total_cmp);
    for pair in real.chunks(2) {
        match pair {
            [p, q] => out.push(Section::Second {
                a1: -(p + q),
                a2: p * q,
                b1: 0.0,
                b2: 0.0,
            }),
            [p] => out.push(Section::First { lambda: *p, b: 0.0 }),
            _ => {}
        }
    }
    out
}

/// Numerators and `d` (and a whole-record `x0`, discarded) by linear least squares for
/// fixed poles. With `bias`, then the input bias `δ` (with a whole-record `x0` again) by
/// least squares on the model's response to a constant input.
fn numerators(template: &LinearSsModel, rec: &Record<'_>, bias: bool) -> Result<LinearSsModel> {
    let len = rec.u.len();
    let n = template.order();
    let n_num: usize = template
        .sections
        .iter()
        .map(|s| if s.states() == 2 { 2 } else { 1 })
        .sum();
    let cols = n_num + 1 + n;
    if len <= cols {
        return Err(BaselineError::TooFewRows {
            what: "samples for the numerators of the subspace model",
            found: len,
            needed: cols + 1,
        });
    }
    // Per section, the state driven by v: its first component responds to b1 through
    // e1 and to b2 through e2 (the observer form is linear in b).
    let mut phi = DMatrix::zeros(len, cols);
    let mut c = 0;
    let mut free_col = n_num + 1;
    for s in &template.sections {
        let k = s.states();
        for e in 0..k {
            let (u1, u2) = (f64::from(e == 0), f64::from(e == 1));
            let unit = match *s {
                Section::Second { a1, a2, .. } => Section::Second {
                    a1,
                    a2,
                    b1: u1,
                    b2: u2,
                },
                Section::Integrating { p, .. } => Section::Integrating { p, b1: u1, b2: u2 },
                Section::First { lambda, .. } => Section::First { lambda, b: 1.0 },
            };
            let mut x = vec![0.0; k];
            let mut f = vec![0.0; k];
            f[e] = 1.0;
            for t in 0..len {
                phi[(t, c)] = x[0];
                phi[(t, free_col)] = f[0];
                unit.step(&mut x, rec.u[t] - template.input_offset);
                unit.step(&mut f, 0.0);
            }
            c += 1;
            free_col += 1;
        }
    }
    for t in 0..len {
        phi[(t, n_num)] = rec.u[t] - template.input_offset;
    }
    let mut qr = StreamingQr::new(cols + 1);
    let mut row = vec![0.0; cols + 1];
    for t in 0..len {
        for (j, v) in row.iter_mut().take(cols).enumerate() {
            *v = phi[(t, j)];
        }
        row[cols] = rec.y[t] - template.output_offset;
        qr.push(&row);
    }
    let names = |i: usize| match i {
        i if i < n_num => format!("numerator coefficient {i}"),
        i if i == n_num => "d".to_string(),
        i => format!("x0[{}]", i - n_num - 1),
    };
    let theta = solve_augmented_r(&qr.finish(), &names)?;
    let mut m = template.clone();
    let mut o = 0;
    for s in &mut m.sections {
        *s = match *s {
            Section::Second { a1, a2, .. } => {
                o += 2;
                Section::Second {
                    a1,
                    a2,
                    b1: theta[o - 2],
                    b2: theta[o - 1],
                }
            }
            Section::Integrating { p, .. } => {
                o += 2;
                Section::Integrating {
                    p,
                    b1: theta[o - 2],
                    b2: theta[o - 1],
                }
            }
            Section::First { lambda, .. } => {
                o += 1;
                Section::First {
                    lambda,
                    b: theta[o - 1],
                }
            }
        };
    }
    m.d = theta[n_num];
    if bias && let Some(delta) = input_bias(&m, rec) {
        m.input_offset += delta;
    }
    Ok(m)
}

/// Least-squares input bias `δ` of `model` on `rec` with a free whole-record `x0`:
/// `y − y_off − forced ≈ −δ·h + F x0`, `h` the response to a unit constant input. `None`
/// when `h` is not separable from the free responses (or the model diverges).
fn input_bias(model: &LinearSsModel, rec: &Record<'_>) -> Option<f64> {
    let len = rec.u.len();
    let n = model.order();
    let basis = model.window_basis(rec.u, 0, len)?;
    let shifted: Vec<f64> = vec![model.input_offset + 1.0; len];
    let step = model.run(&shifted, &vec![0.0; n], 0, len)?;
    let mut qr = StreamingQr::new(n + 2);
    let mut row = vec![0.0; n + 2];
    for (t, s) in step.iter().enumerate() {
        row[0] = s - model.output_offset;
        for j in 0..n {
            row[1 + j] = basis.free[(t, j)];
        }
        row[n + 1] = rec.y[t] - basis.forced[t];
        qr.push(&row);
    }
    let theta = solve_augmented_r(&qr.finish(), &|_| String::new()).ok()?;
    Some(-theta[0])
}

/// Subspace model of order `n` on `rec` (MOESP done once per record).
pub(super) fn subspace_model(
    mo: &Moesp,
    n: usize,
    base: &LinearSsModel,
    rec: &Record<'_>,
    bias: bool,
    integrator: bool,
) -> Result<LinearSsModel> {
    let (a, _) = mo.a_c(n)?;
    let poles: Vec<(f64, f64)> = a
        .complex_eigenvalues()
        .iter()
        .map(|z| (z.re, z.im))
        .collect();
    let mut template = base.clone();
    template.sections = sections_from_poles(&poles, integrator);
    numerators(&template, rec, bias)
}
