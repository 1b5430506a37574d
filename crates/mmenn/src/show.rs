//! `mmenn show MODEL`: any model mmenn writes printed as equations, with the names and
//! units of the file and ±σ where they are known, e.g.
//! `v' = -4.03 x - 0.2 v + 1.01 u - 0.803 (±0.01) v*abs(v)`.
//!
//! A physical model file also prints its `[parameters]` as a table (value, ±σ when an
//! estimator wrote one, unit, bounds, free or fixed) and its `[mechanics]` part: each
//! rate equation reads `omega1' = [M⁻¹·F]_theta1`, followed by `M(q)` entry by entry and
//! the generalized forces `F` (the `forces` expressions plus the terms on rate
//! equations, which are generalized forces there).
//!
//! A model with an `[acquisition]` table prints its filter: the pass band, then each
//! band's centre, gain and phase in degrees.
//!
//! The model files hold no uncertainties for term coefficients; a discovered model's ±σ come from the
//! `discovery.json` written beside it by `mmenn discover` (σ = half the 95 % interval of
//! the free-run calibrated coefficient / 1.96), when that file is there.

use std::collections::BTreeMap;
use std::path::Path;

use crate::error::Result;
use crate::model::{LoadedModel, ModelKind};

/// Standard deviations of named-term coefficients by `(equation, expression)`.
pub type TermSigmas = BTreeMap<(String, String), f64>;

/// A number with 4 significant digits, trailing zeros dropped.
pub fn number(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let mag = v.abs().log10().floor() as i32;
    if (-3..6).contains(&mag) {
        let decimals = (3 - mag).max(0) as usize;
        let s = format!("{v:.decimals$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    } else {
        format!("{v:.3e}")
    }
}

/// The ±σ of the terms of a discovered model, from `discovery.json` beside it (empty
/// when there is none or it cannot be read: the equations are then printed without).
pub fn sigmas_beside(model_path: &Path) -> TermSigmas {
    let mut out = TermSigmas::new();
    let Some(dir) = model_path.parent() else {
        return out;
    };
    let Ok(text) = std::fs::read_to_string(dir.join("discovery.json")) else {
        return out;
    };
    let Ok(json) = serde_json::from_str::<serde_json::Value>(&text) else {
        return out;
    };
    for list in ["effects", "unconfirmed"] {
        for e in json[list].as_array().into_iter().flatten() {
            let (Some(state), Some(term), Some(ci)) = (
                e["state"].as_str(),
                e["term"].as_str(),
                e["ci95"].as_array(),
            ) else {
                continue;
            };
            if let (Some(lo), Some(hi)) = (
                ci.first().and_then(|v| v.as_f64()),
                ci.get(1).and_then(|v| v.as_f64()),
            ) && hi >= lo
            {
                out.insert(
                    (state.to_string(), term.to_string()),
                    (hi - lo) / (2.0 * 1.96),
                );
            }
        }
    }
    out
}

fn push_term(line: &mut String, first: &mut bool, coefficient: f64, body: &str) {
    let sign = if coefficient < 0.0 { "-" } else { "+" };
    let mag = number(coefficient.abs());
    if *first {
        if coefficient < 0.0 {
            line.push('-');
        }
        *first = false;
    } else {
        line.push_str(&format!(" {sign} "));
    }
    line.push_str(&mag);
    if !body.is_empty() {
        line.push(' ');
        line.push_str(body);
    }
}

/// The terms entering `state`'s equation (`−` for a transfer into it), with their ±σ.
fn push_terms(
    line: &mut String,
    first: &mut bool,
    terms: &[crate::model_file::TermEntry],
    state: &str,
    sigmas: &TermSigmas,
) {
    for t in terms {
        let sign = if t.state == state {
            1.0
        } else if t.into.as_deref() == Some(state) {
            -1.0
        } else {
            continue;
        };
        let sigma = sigmas
            .get(&(t.state.clone(), t.term.clone()))
            .map(|s| format!("(±{}) ", number(*s)))
            .unwrap_or_default();
        // A constant term (expression `1`) reads as its coefficient alone.
        let expr = if t.term.trim() == "1" {
            String::new()
        } else {
            expression(&t.term)
        };
        push_term(
            line,
            first,
            sign * t.coefficient,
            format!("{sigma}{expr}").trim_end(),
        );
    }
}

fn expression(term: &str) -> String {
    if term.contains([' ', '+', '-']) {
        format!("({term})")
    } else {
        term.to_string()
    }
}

/// The model as lines of text: a header (kind, names with units, hold), one equation per
/// state, and the outputs when they are not plain measured states.
pub fn equations(model: &LoadedModel, sigmas: &TermSigmas) -> Vec<String> {
    let spec = &model.spec;
    let lin = &spec.linear;
    let unit = |name: &str| {
        spec.units
            .get(name)
            .map(|u| format!(" [{u}]"))
            .unwrap_or_default()
    };
    let mut lines = vec![format!("{} — {}", model.path.display(), model.kind)];
    let names = |list: &[String]| {
        list.iter()
            .map(|n| format!("{n}{}", unit(n)))
            .collect::<Vec<_>>()
            .join(", ")
    };
    lines.push(format!("states: {}", names(lin.state_names())));
    if lin.n_inputs() > 0 {
        lines.push(format!(
            "inputs: {} (between samples: {})",
            names(lin.input_names()),
            match model.intersample() {
                sysid_core::InterSample::Zoh => "held, zoh",
                sysid_core::InterSample::Foh => "linear, foh",
                sysid_core::InterSample::Bl => "band-limited, bl",
            }
        ));
    }
    let corrected = lin.corrected_states().unwrap_or_default();
    let mech = spec.mechanics.as_ref();
    let coordinate_of = |state: &str| mech.and_then(|m| m.q.iter().position(|q| q == state));
    let rate_of = |state: &str| mech.and_then(|m| m.qdot.iter().position(|v| v == state));
    for (i, state) in lin.state_names().iter().enumerate() {
        let mut line = format!("{state}' = ");
        let mut first = true;
        if let (Some(m), Some(k)) = (mech, coordinate_of(state)) {
            line.push_str(&m.qdot[k]);
            first = false;
        }
        if let (Some(m), Some(k)) = (mech, rate_of(state)) {
            line.push_str(&format!("[M⁻¹·F]_{}", m.q[k]));
            first = false;
        }
        for (j, s) in lin.state_names().iter().enumerate() {
            let a = lin.a()[(i, j)];
            if a != 0.0 {
                push_term(&mut line, &mut first, a, s);
            }
        }
        for (j, u) in lin.input_names().iter().enumerate() {
            let b = lin.b()[(i, j)];
            if b != 0.0 {
                push_term(&mut line, &mut first, b, u);
            }
        }
        if rate_of(state).is_none() {
            // (on a rate equation the terms are generalized forces, printed with F below)
            push_terms(&mut line, &mut first, &spec.terms, state, sigmas);
        }
        if model.kind == ModelKind::Hybrid && corrected.contains(&i) {
            if first {
                line.push_str(&format!("NN_{state}(x, u)"));
                first = false;
            } else {
                line.push_str(&format!(" + NN_{state}(x, u)"));
            }
        }
        if first {
            line.push('0');
        }
        lines.push(line);
    }
    let measured = lin.measured_states();
    let plain = measured.as_ref().is_some_and(|idx| {
        idx.iter()
            .zip(lin.output_names())
            .all(|(&i, o)| &lin.state_names()[i] == o)
    });
    if plain {
        lines.push(format!("measured: {}", lin.output_names().join(", ")));
    } else {
        for (i, o) in lin.output_names().iter().enumerate() {
            let mut line = format!("{o}{} = ", unit(o));
            let mut first = true;
            for (j, s) in lin.state_names().iter().enumerate() {
                let c = lin.c()[(i, j)];
                if c != 0.0 {
                    push_term(&mut line, &mut first, c, s);
                }
            }
            if first {
                line.push('0');
            }
            lines.push(line);
        }
    }
    if let Some(m) = mech {
        lines.extend(mechanics_lines(m, &spec.terms, sigmas));
    }
    if !spec.parameters.is_empty() {
        lines.extend(parameter_lines(&spec.parameters));
    }
    if let Some(h) = &model.hybrid {
        let net = &h.network;
        lines.push(format!(
            "NN: tanh network, inputs (states, inputs) → corrections ({}); hidden units per layer {}, {} weights; RK4 with {} sub-steps",
            lin.correction_names().join(", "),
            net.hidden()
                .iter()
                .map(|h| h.to_string())
                .collect::<Vec<_>>()
                .join(", "),
            net.n_weights(),
            h.substeps
        ));
    }
    if let Some(f) = &spec.acquisition {
        lines.extend(acquisition_lines(f));
    }
    if !spec.roles.is_empty() {
        lines.push(format!(
            "roles given to discover: {}",
            crate::words::role_list(&spec.roles)
        ));
    }
    if !spec.terms.is_empty() && sigmas.is_empty() {
        lines.push(if spec.parameters.iter().any(|p| p.sigma.is_some()) {
            "(term coefficients without ±σ: the ±σ above are the parameters')".into()
        } else {
            "(no ±σ: the file holds none and no discovery.json is beside it)".into()
        });
    }
    lines
}

/// The `[acquisition]` filter: its pass band, then each band's centre, gain and phase
/// (degrees).
pub fn acquisition_lines(f: &sysid_core::acquisition::AcquisitionFilter) -> Vec<String> {
    let n = f.bands().len();
    let mut lines = vec![format!(
        "acquisition filter Ã on inputs and outputs (judged as y = Ã·N(Ã⁻¹·u)): one below {} Hz, \
         {n} band{} above",
        number(f.pass_below_hz()),
        if n == 1 { "" } else { "s" }
    )];
    for (&(c, g), se) in f.bands().iter().zip(f.standard_errors()) {
        let se = se.map_or(String::new(), |v| {
            format!(" (standard error of the complex gain {})", number(v))
        });
        lines.push(format!(
            "  {} Hz: gain {}, phase {}°{se}",
            number(c),
            number(g.norm()),
            number(g.arg().to_degrees())
        ));
    }
    lines
}

/// `M(q)` (upper triangle, it is symmetric) and `F = Q + terms` per coordinate.
fn mechanics_lines(
    m: &crate::model_file::MechanicsEntry,
    terms: &[crate::model_file::TermEntry],
    sigmas: &TermSigmas,
) -> Vec<String> {
    let mut lines = vec![format!(
        "mechanics: M(q)·[{}]' = F, q = ({})",
        m.qdot.join(", "),
        m.q.join(", ")
    )];
    for (i, row) in m.mass.iter().enumerate() {
        for (j, e) in row.iter().enumerate().skip(i) {
            lines.push(format!("  M[{}, {}] = {e}", m.q[i], m.q[j]));
        }
    }
    for (k, q) in m.q.iter().enumerate() {
        let mut line = format!("  F[{q}] = {}", m.forces[k]);
        push_terms(&mut line, &mut false, terms, &m.qdot[k], sigmas);
        lines.push(line);
    }
    lines
}

/// The parameter table: name, value, ±σ (`—` when not estimated), unit, bounds,
/// free/fixed; columns aligned.
fn parameter_lines(parameters: &[crate::model_file::ParameterEntry]) -> Vec<String> {
    let rows: Vec<[String; 6]> = parameters
        .iter()
        .map(|p| {
            [
                p.name.clone(),
                number(p.value),
                p.sigma.map_or("—".into(), |s| format!("±{}", number(s))),
                p.unit.clone().unwrap_or_else(|| "—".into()),
                p.bounds.map_or("—".into(), |(lo, hi)| {
                    format!("[{}, {}]", number(lo), number(hi))
                }),
                match p.estimation {
                    sysid_core::Estimation::Free => "free".into(),
                    sysid_core::Estimation::Fixed => "fixed".into(),
                },
            ]
        })
        .collect();
    let header = ["parameter", "value", "±σ", "unit", "bounds", ""].map(String::from);
    let mut width = [0usize; 6];
    for r in std::iter::once(&header).chain(&rows) {
        for (w, c) in width.iter_mut().zip(r) {
            *w = (*w).max(c.chars().count());
        }
    }
    std::iter::once(&header)
        .chain(&rows)
        .map(|r| {
            let cells: Vec<String> = r
                .iter()
                .zip(width)
                .map(|(c, w)| format!("{c}{}", " ".repeat(w - c.chars().count())))
                .collect();
            format!("  {}", cells.join("  ").trim_end())
        })
        .collect()
}

/// Read any model and render it (see [`equations`]).
pub fn show_model(path: &Path) -> Result<String> {
    let model = LoadedModel::read(path)?;
    let sigmas = sigmas_beside(path);
    let mut text = equations(&model, &sigmas).join("\n");
    text.push('\n');
    Ok(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A band with a standard error prints it after its phase; one without prints none.
    #[test]
    fn acquisition_bands_print_their_standard_errors() {
        use nalgebra::Complex;
        use sysid_core::acquisition::AcquisitionFilter;
        let f = AcquisitionFilter::from_bands(
            190.0,
            vec![
                (202.5, Complex::new(0.6, -0.8)),
                (207.5, Complex::new(0.5, 0.0)),
            ],
        )
        .and_then(|f| f.with_standard_errors(vec![Some(0.0125), None]))
        .unwrap();
        let lines = acquisition_lines(&f);
        assert_eq!(
            lines[1],
            "  202.5 Hz: gain 1, phase -53.13° (standard error of the complex gain 0.0125)"
        );
        assert_eq!(lines[2], "  207.5 Hz: gain 0.5, phase 0°");
    }

    #[test]
    fn numbers_and_equations() {
        assert_eq!(number(-4.03), "-4.03");
        assert_eq!(number(0.2), "0.2");
        assert_eq!(number(1.0), "1");
        assert_eq!(number(0.80312), "0.8031");
        assert_eq!(number(1.5e-7), "1.500e-7");
        let text = r#"
states = ["x", "v"]
inputs = ["u"]
A = [[0.0, 1.0], [-4.03, -0.2]]
B = [[0.0], [1.01]]
measured = ["x"]
corrected = ["v"]
noise_variance = [1e-4]
units = { x = "m", v = "m/s", u = "N" }

[[terms]]
state = "v"
effect = "quadratic_drag"
term = "v*abs(v)"
coefficient = -0.803
"#;
        let path = Path::new("m.toml");
        let model = LoadedModel::parse(path, text).unwrap();
        let mut sig = TermSigmas::new();
        sig.insert(("v".into(), "v*abs(v)".into()), 0.012);
        let lines = equations(&model, &sig);
        assert!(lines.contains(&"x' = 1 v".to_string()), "{lines:?}");
        assert!(
            lines.contains(&"v' = -4.03 x - 0.2 v + 1.01 u - 0.803 (±0.012) v*abs(v)".to_string()),
            "{lines:?}"
        );
        assert!(lines.iter().any(|l| l.contains("x [m]")), "{lines:?}");
        assert!(!lines.iter().any(|l| l.contains("roles")), "{lines:?}");
        // A `[roles]` table is shown.
        let with_roles = text.replace("[[terms]]", "[roles]\nx = \"position\"\n\n[[terms]]");
        let model = LoadedModel::parse(path, &with_roles).unwrap();
        let lines = equations(&model, &sig);
        assert!(
            lines.contains(&"roles given to discover: x position".to_string()),
            "{lines:?}"
        );
    }

    /// A constant term reads as its coefficient (with its ±σ), not as `c 1`.
    #[test]
    fn constant_term_is_its_coefficient() {
        let text = r#"
states = ["x", "v"]
inputs = ["u"]
A = [[0.0, 1.0], [-4.0, -0.2]]
B = [[0.0], [1.0]]
measured = ["x"]
corrected = ["v"]
noise_variance = [1e-4]

[[terms]]
state = "v"
effect = "offset"
term = "1"
coefficient = -1010.0
"#;
        let model = LoadedModel::parse(Path::new("m.toml"), text).unwrap();
        let plain = equations(&model, &TermSigmas::new());
        assert!(
            plain.contains(&"v' = -4 x - 0.2 v + 1 u - 1010".to_string()),
            "{plain:?}"
        );
        let mut sig = TermSigmas::new();
        sig.insert(("v".into(), "1".into()), 3.0);
        let with = equations(&model, &sig);
        assert!(
            with.contains(&"v' = -4 x - 0.2 v + 1 u - 1010 (±3)".to_string()),
            "{with:?}"
        );
    }
}
