//! The sweep against a brute-force dense least-squares solution of the same discrete
//! problem: unknowns `x_0` and every correction piece stacked, solved by Householder QR.

use mme_core::{MmeConfig, NoiseSpec, WeightSpec, estimate};
use nalgebra::{DMatrix, DVector};
use sysid_core::{Dataset, Experiment, LinearModel, MmeEstimate};

use super::common::{dataset, gaussian, linear};

/// Dense solution of one experiment: states at samples, pieces and `J`.
struct Dense {
    states: DMatrix<f64>,
    pieces: DMatrix<f64>,
    cost: f64,
}

fn brute(
    model: &LinearModel,
    data: &Dataset,
    e: usize,
    s: usize,
    w: &DMatrix<f64>,
    r: &[f64],
) -> Dense {
    let exp = &data.experiments()[e];
    let (n, q, p) = (model.n_states(), model.n_corrections(), model.n_outputs());
    let big_n = exp.len();
    let pieces = (big_n - 1) * s;
    let h = exp.dt() / s as f64;
    let zoh = model.discretize(h).unwrap();
    let out_rows: Vec<usize> = model
        .output_names()
        .iter()
        .map(|nm| data.output_index(nm).unwrap())
        .collect();
    let in_rows: Vec<usize> = model
        .input_names()
        .iter()
        .map(|nm| data.input_index(nm).unwrap())
        .collect();
    let dim = n + q * pieces;
    // x_j = M θ + m, propagated through every sub-step.
    let mut m_mat = DMatrix::<f64>::zeros(n, dim);
    m_mat.view_mut((0, 0), (n, n)).fill_with_identity();
    let mut m_vec = DVector::<f64>::zeros(n);
    let mut at_sample = vec![(m_mat.clone(), m_vec.clone())];
    for j in 0..pieces {
        let k = j / s;
        let u = DVector::from_iterator(
            in_rows.len(),
            in_rows.iter().map(|&row| exp.inputs()[(row, k)]),
        );
        let mut next = &zoh.ad * &m_mat;
        next.view_mut((0, n + q * j), (n, q)).copy_from(&zoh.ed);
        m_mat = next;
        m_vec = &zoh.ad * &m_vec + &zoh.bd * u;
        if (j + 1) % s == 0 {
            at_sample.push((m_mat.clone(), m_vec.clone()));
        }
    }
    // Rows: whitened residuals of observed samples, then √h·Lᵀ d_j.
    let lw = w.clone().cholesky().unwrap().l();
    let mut rows: Vec<(DVector<f64>, f64)> = Vec::new();
    for (k, (mk, vk)) in at_sample.iter().enumerate() {
        for i in 0..p {
            let y = exp.outputs()[(out_rows[i], k)];
            if y.is_nan() {
                continue;
            }
            let ci = model.c().row(i);
            let sw = 1.0 / r[i].sqrt();
            rows.push(((ci * mk).transpose() * sw, (y - (ci * vk)[0]) * sw));
        }
    }
    for j in 0..pieces {
        for a in 0..q {
            let mut row = DVector::zeros(dim);
            for b in 0..q {
                row[n + q * j + b] = h.sqrt() * lw[(b, a)];
            }
            rows.push((row, 0.0));
        }
    }
    let hm = DMatrix::from_fn(rows.len(), dim, |i, j| rows[i].0[j]);
    let bv = DVector::from_iterator(rows.len(), rows.iter().map(|r| r.1));
    let qr = hm.clone().qr();
    let rhs = qr.q().transpose() * &bv;
    let theta = qr.r().solve_upper_triangular(&rhs).unwrap();
    let cost = (&hm * &theta - &bv).norm_squared();
    let states = DMatrix::from_fn(n, big_n, |i, k| {
        let (mk, vk) = &at_sample[k];
        (mk * &theta + vk)[i]
    });
    let pieces_m = DMatrix::from_fn(q, pieces, |a, j| theta[n + q * j + a]);
    Dense {
        states,
        pieces: pieces_m,
        cost,
    }
}

fn rel(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).norm() / b.norm().max(1e-300)
}

/// Run the sweep and the dense solve; compare states, pieces and `J`.
fn check(
    model: &LinearModel,
    data: &Dataset,
    s: usize,
    w: DMatrix<f64>,
    r: Vec<f64>,
) -> MmeEstimate {
    let config = MmeConfig {
        w: WeightSpec::Matrix(w.clone()),
        noise_variance: NoiseSpec::Given(r.clone()),
        substeps: Some(s),
        ..MmeConfig::default()
    };
    let est = estimate(model, data, &config).unwrap();
    let mut cost = 0.0;
    for e in 0..data.experiments().len() {
        let dense = brute(model, data, e, s, &w, &r);
        let got = &est.experiments[e];
        // The dense QR solve is backward stable; with condition numbers up to ~1e6 here,
        // 1e-8 relative leaves a wide margin above round-off in both solutions.
        assert!(
            rel(&got.states, &dense.states) < 1e-8,
            "states: {}",
            rel(&got.states, &dense.states)
        );
        assert!(
            rel(&got.corrections, &dense.pieces) < 1e-8,
            "d: {}",
            rel(&got.corrections, &dense.pieces)
        );
        cost += dense.cost;
    }
    assert!(
        (est.cost - cost).abs() < 1e-8 * cost,
        "J {} vs {}",
        est.cost,
        cost
    );
    est
}

/// Outputs: a smooth signal plus noise, with NaN at the given samples of the given row.
fn outputs(p: usize, len: usize, seed: u64, missing: &[(usize, usize)]) -> DMatrix<f64> {
    let noise = gaussian(seed, p * len, 0.1);
    let mut y = DMatrix::from_fn(p, len, |i, k| {
        let t = k as f64 * 0.05;
        (t * (0.7 + 0.3 * i as f64)).sin() * (1.0 + i as f64) + 0.3 * t.cos() + noise[k * p + i]
    });
    for &(i, k) in missing {
        y[(i, k)] = f64::NAN;
    }
    y
}

fn inputs(m: usize, len: usize) -> DMatrix<f64> {
    DMatrix::from_fn(m, len, |l, k| {
        ((k as f64) * 0.11 * (l + 1) as f64).sin() + 0.2
    })
}

fn oscillator() -> LinearModel {
    linear(
        &[0.0, 1.0, -2.0, -0.3],
        &[0.0, 1.0],
        &[1.0, 0.0],
        &[0.0, 1.0],
        2,
        (&["x", "v"], &["u"], &["x"], &["dv"]),
    )
}

#[test]
fn n2_partial_measurement_with_gaps_matches_dense_solution() {
    let model = oscillator();
    for (s, len) in [(1usize, 200usize), (3, 80)] {
        let missing: Vec<(usize, usize)> =
            [0, 7, 8, 9, 50, len - 1].iter().map(|&k| (0, k)).collect();
        let exp = Experiment::new(0.0, 0.05, inputs(1, len), outputs(1, len, 1, &missing)).unwrap();
        let data = dataset(&["u"], &["x"], vec![exp]);
        check(
            &model,
            &data,
            s,
            DMatrix::from_element(1, 1, 3.0),
            vec![0.01],
        );
    }
}

#[test]
fn n4_two_corrections_full_w_matches_dense_solution() {
    // Two masses coupled by springs; positions measured, both velocity rows corrected.
    let model = linear(
        &[
            0.0, 0.0, 1.0, 0.0, //
            0.0, 0.0, 0.0, 1.0, //
            -2.0, 1.0, -0.1, 0.0, //
            1.0, -1.5, 0.0, -0.2,
        ],
        &[0.0, 0.0, 1.0, 0.0],
        &[1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
        &[0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0],
        4,
        (
            &["x1", "x2", "v1", "v2"],
            &["u"],
            &["x1", "x2"],
            &["d1", "d2"],
        ),
    );
    let w = DMatrix::from_row_slice(2, 2, &[2.0, 0.5, 0.5, 1.0]);
    for (s, len) in [(1usize, 200usize), (3, 60)] {
        let missing = [(1, 3), (1, 4), (0, 10), (0, len - 1), (1, 0)];
        let y = outputs(2, len, 2, &missing);
        // Dataset lists outputs in another order plus an unused channel: matched by name.
        let y_data = DMatrix::from_fn(3, len, |i, k| match i {
            0 => y[(1, k)],
            1 => 42.0,
            _ => y[(0, k)],
        });
        let exp = Experiment::new(1.0, 0.05, inputs(1, len), y_data).unwrap();
        let data = dataset(&["u"], &["x2", "unused", "x1"], vec![exp]);
        check(&model, &data, s, w.clone(), vec![0.02, 0.05]);
    }
}

#[test]
fn n3_general_c_dynamic_path_and_two_experiments_match_dense_solution() {
    // n = 3, q = 1 runs on dynamically sized matrices; C is not a selection.
    let model = linear(
        &[-0.5, 1.0, 0.0, 0.0, -0.2, 1.0, -0.3, 0.0, -1.0],
        &[0.0, 0.0, 1.0, 1.0, 0.0, 0.5],
        &[1.0, 0.5, 0.0, 0.0, 1.0, -1.0],
        &[0.0, 1.0, 0.0],
        3,
        (&["a", "b", "c"], &["u1", "u2"], &["y1", "y2"], &["d"]),
    );
    let e1 = Experiment::new(
        0.0,
        0.05,
        inputs(2, 120),
        outputs(2, 120, 3, &[(0, 5), (1, 6)]),
    )
    .unwrap();
    let e2 = Experiment::new(0.0, 0.1, inputs(2, 70), outputs(2, 70, 4, &[(1, 69)])).unwrap();
    let data = dataset(&["u1", "u2"], &["y1", "y2"], vec![e1, e2]);
    let est = check(
        &model,
        &data,
        2,
        DMatrix::from_element(1, 1, 0.7),
        vec![0.01, 0.03],
    );
    assert_eq!(est.experiments[1].corrections.ncols(), 69 * 2);
}
