//! The CI regression guard: `cargo xtask reproduce --quick --check` into a temporary folder
//! must agree with the committed fixtures (tables within their stated tolerances, data
//! files' summary statistics within `DATA_TOLERANCE`), and a fixture moved beyond its
//! tolerance must be caught with a diff naming the table, row and column (or the data
//! file and statistic).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask lives inside the workspace")
        .to_path_buf()
}

fn temp(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("xtask-check-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

fn reproduce(out: &Path, extra: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args(["reproduce", "--quick", "--check", "--out"])
        .arg(out)
        .args(extra)
        .output()
        .expect("running xtask")
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// The whole quick reproduction agrees with the committed fixtures.
#[test]
fn quick_reproduction_matches_the_fixtures() {
    let out = temp("all");
    let o = reproduce(&out, &[]);
    assert!(o.status.success(), "reproduction drifted:\n{}", text(&o));
    // It wrote the results where asked, not into the work tree.
    assert!(out.join("docs/results/quick/README.md").is_file());
    assert!(
        out.join("docs/results/quick/tables/ch2_msd_mme.json")
            .is_file()
    );
    let _ = std::fs::remove_dir_all(&out);
}

/// A fixture value moved by ten times its tolerance fails the check, and the message names
/// the table, the row and the column.
#[test]
fn drift_beyond_tolerance_is_reported() {
    let fixtures = temp("fixtures");
    let src = workspace().join("fixtures");
    // Copy the committed fixtures (tables and data) to perturb them.
    copy_dir(&src, &fixtures);
    let path = fixtures.join("tables/quick/ch2_msd_mme.json");
    let text_in = std::fs::read_to_string(&path).expect("ch2 fixture");
    let mut v: serde_json::Value = serde_json::from_str(&text_in).expect("json");
    let r2 = v["table"]["rows"][0]["values"][0].as_f64().expect("r2");
    let tol = v["table"]["columns"][0]["tolerance"]["abs"]
        .as_f64()
        .expect("abs tol");
    v["table"]["rows"][0]["values"][0] = serde_json::json!(r2 - 10.0 * tol);
    std::fs::write(&path, serde_json::to_string(&v).expect("json")).expect("write");
    let out = temp("drift");
    let o = reproduce(
        &out,
        &[
            "--only",
            "ch2",
            "--fixtures",
            fixtures.to_str().expect("utf-8 path"),
        ],
    );
    let msg = text(&o);
    assert!(!o.status.success(), "a drifted fixture passed:\n{msg}");
    assert!(
        msg.contains("ch2_msd_mme [d_v (model correction, m/s²), whole record] r2"),
        "{msg}"
    );
    let _ = std::fs::remove_dir_all(&out);
    let _ = std::fs::remove_dir_all(&fixtures);
}

/// A data summary moved by 1e-3 of its column's scale (1000 times the tolerance) fails
/// the check, and the message names the file.
#[test]
fn data_drift_is_reported() {
    let fixtures = temp("data-fixtures");
    copy_dir(
        &workspace().join("fixtures").join("tables"),
        &fixtures.join("tables"),
    );
    let src = workspace().join("fixtures/data_summary.json");
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&src).expect("data summary")).expect("json");
    let col = &mut v["files"]["msd_cubic/train/data.csv"]["columns"][1];
    let scale = col["scale"].as_f64().expect("scale");
    let mean = col["mean"].as_f64().expect("mean");
    col["mean"] = serde_json::json!(mean + 1e-3 * scale);
    std::fs::write(
        fixtures.join("data_summary.json"),
        serde_json::to_string(&v).expect("json"),
    )
    .expect("write");
    let out = temp("data-drift");
    let o = reproduce(
        &out,
        &[
            "--only",
            "ch2",
            "--fixtures",
            fixtures.to_str().expect("utf-8 path"),
        ],
    );
    let msg = text(&o);
    assert!(!o.status.success(), "a drifted data summary passed:\n{msg}");
    assert!(msg.contains("msd_cubic/train/data.csv"), "{msg}");
    assert!(msg.contains("mean differs"), "{msg}");
    let _ = std::fs::remove_dir_all(&out);
    let _ = std::fs::remove_dir_all(&fixtures);
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("mkdir");
    for e in std::fs::read_dir(from).expect("read_dir") {
        let e = e.expect("entry");
        let p = e.path();
        let q = to.join(e.file_name());
        if p.is_dir() {
            copy_dir(&p, &q);
        } else {
            std::fs::copy(&p, &q).expect("copy");
        }
    }
}
