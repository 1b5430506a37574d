//! Evaluation cost of model-file terms: the Silverbox grey box's terms and their
//! derivatives with respect to each state (what a right-hand side and its sensitivities
//! evaluate at every RK4 stage of a calibration), over 4096 points of a fixed sequence.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use sysid_core::Expr;

const STATES: [&str; 3] = ["y", "v", "w"];
const TERMS: [&str; 11] = [
    "u",
    "1",
    "y",
    "v",
    "y^3",
    "y^2",
    "y^2*v",
    "v*abs(v)",
    "w",
    "tanh(v/0.0003)",
    "sqrt((y + abs(y))/2 + 0.0001)",
];

fn exprs() -> Vec<Expr> {
    let names: Vec<&str> = STATES.iter().copied().chain(["u"]).collect();
    let mut all = Vec::new();
    for t in TERMS {
        let e = Expr::parse(t, &names).expect("valid term");
        for s in 0..STATES.len() {
            all.push(e.derivative(s).expect("differentiable"));
        }
        all.push(e);
    }
    all
}

fn points() -> Vec<[f64; 4]> {
    // A fixed low-discrepancy walk: no random numbers needed.
    (0..4096)
        .map(|k| {
            let t = k as f64;
            [
                0.2 * (0.37 * t).sin(),
                0.05 * (0.91 * t).cos(),
                0.1 * (0.13 * t).sin(),
                (0.07 * t).cos(),
            ]
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let exprs = exprs();
    let points = points();
    let mut g = c.benchmark_group("expr");
    g.throughput(Throughput::Elements((exprs.len() * points.len()) as u64));
    g.bench_function("silverbox terms and state derivatives", |b| {
        b.iter(|| {
            let mut acc = 0.0;
            for p in &points {
                let (x, u) = p.split_at(3);
                for e in &exprs {
                    acc += e.eval_parts(black_box(x), black_box(u));
                }
            }
            acc
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
