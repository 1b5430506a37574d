//! Unit tests of the CSV reader, the preparation of logger files and the writer.

use super::*;

fn parse(text: &str) -> Result<Table> {
    parse_table(Path::new("d.csv"), text.as_bytes())
}

fn problem(r: Result<impl std::fmt::Debug>) -> (usize, Option<String>, CsvProblem) {
    match r {
        Err(MmennError::Csv {
            line,
            column,
            problem,
            ..
        }) => (line, column, problem),
        other => panic!("expected a CSV error, got {other:?}"),
    }
}

fn names(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

#[test]
fn round_trip_is_bit_exact_with_missing_samples() {
    let t = [0.0, 0.1, 0.2, 0.30000000000000004];
    let u = [1.0 / 3.0, -2.5e-17, 7.0, 1e300];
    let y = [f64::NAN, 0.1 + 0.2, -0.0, 5.0];
    let text = format_csv(&names(&["t", "u", "y"]), &[&t, &u, &y]);
    let table = parse(&text).unwrap();
    let exp = table_to_experiment(&table, &names(&["u"]), &names(&["y"])).unwrap();
    for k in 0..4 {
        assert_eq!(exp.input(k)[0].to_bits(), u[k].to_bits());
        if y[k].is_nan() {
            assert!(exp.output(k)[0].is_nan());
        } else {
            assert_eq!(exp.output(k)[0].to_bits(), y[k].to_bits());
        }
    }
    assert_eq!(table.lines, vec![2, 3, 4, 5]);
}

#[test]
fn bad_input_classes_name_line_and_column() {
    let io = (names(&["u"]), names(&["y"]));
    let exp = |text: &str| parse(text).and_then(|t| table_to_experiment(&t, &io.0, &io.1));
    assert!(matches!(
        problem(exp("t,u,y\n0,1,2\n0.1,1\n")),
        (
            3,
            None,
            CsvProblem::Ragged {
                expected: 3,
                found: 2
            }
        )
    ));
    assert!(
        matches!(problem(exp("t,u,y\n0,1,2\n0.1,x,2\n")), (3, Some(c), CsvProblem::NotANumber { .. }) if c == "u")
    );
    assert!(
        matches!(problem(exp("t,u,y\n0,1,2\n0.1,,2\n0.2,1,1\n")), (3, Some(c), CsvProblem::Missing { .. }) if c == "u")
    );
    assert!(matches!(
        problem(exp("t,u,y\n0,1,2\n0.1,NaN,2\n0.2,1,1\n")),
        (3, _, CsvProblem::Missing { .. })
    ));
    assert!(matches!(
        problem(exp("t,u,y\n0,1,2\n0.1,1,2\n0.1,1,1\n")),
        (4, _, CsvProblem::NonIncreasingTime { .. })
    ));
    assert!(matches!(
        problem(exp("t,u,y\n0,1,2\n0.1,1,2\n0.25,1,1\n0.3,1,1\n")),
        (4, _, CsvProblem::NonUniformTime { .. })
    ));
    assert!(matches!(
        problem(exp("u,y\n1,2\n1,2\n")),
        (1, _, CsvProblem::NoTimeColumn)
    ));
    assert!(matches!(
        problem(exp("t,u,u\n0,1,2\n0.1,1,2\n")),
        (1, _, CsvProblem::DuplicateColumn(_))
    ));
    assert!(
        matches!(problem(exp("t,u\n0,1\n0.1,1\n")), (1, _, CsvProblem::MissingChannel { name, header }) if name == "y" && header == "t, u")
    );
    assert!(matches!(problem(exp("")), (1, _, CsvProblem::Empty)));
    assert!(matches!(
        problem(exp("t,u,y\n0,1,2\n")),
        (_, _, CsvProblem::TooFewRows(1))
    ));
    assert!(matches!(
        problem(exp("t,u,y\n0,1,inf\n0.1,1,2\n")),
        (2, _, CsvProblem::Infinite)
    ));
}

/// A row missing from the middle of a long uniform record is named where it is: the row
/// after the gap, its step twice the file's typical step (compared with the mean step,
/// which the gap shifts by 0.1 %, the first row already looked off).
#[test]
fn a_missing_row_is_named_where_it_is() {
    let mut text = String::from("t,u,y\n");
    for k in (0..1000).filter(|&k| k != 498) {
        text.push_str(&format!("{},1,2\n", 4 * k));
    }
    let (line, column, p) =
        problem(parse(&text).and_then(|t| table_to_experiment(&t, &names(&["u"]), &names(&["y"]))));
    // Header on line 1, sample k on line k + 2 until the gap; t = 1996 s is on line 500.
    assert_eq!((line, column.as_deref()), (500, Some("t")), "{p}");
    match p {
        CsvProblem::NonUniformTime { step, dt } => assert_eq!((step, dt), (8.0, 4.0)),
        other => panic!("{other:?}"),
    }
}

/// A jittered time column (±30 % of a 2 ms step, seeded) is an error naming its
/// first off-grid row without `--resample`; resampled, a linear signal comes back
/// exactly (linear interpolation is exact on it), a sine within the interpolation
/// bound `h²/8·max|y''|`, and the report states the spacing and the method.
#[test]
fn jittered_time_is_rejected_or_resampled_explicitly() {
    let mut state = 7_u64;
    let mut jitter = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.6
    };
    let n = 500;
    let t: Vec<f64> = (0..n).map(|k| 0.002 * (k as f64 + jitter())).collect();
    let u: Vec<f64> = t.iter().map(|t| 1.0 + 3.0 * t).collect();
    let y: Vec<f64> = t.iter().map(|t| (5.0 * t).sin()).collect();
    let text = format_csv(&names(&["time", "torque", "pos"]), &[&t, &u, &y]);
    let table = parse(&text).unwrap();
    let map = PrepareOptions::parse_map(&["t=time,u=torque".into(), "theta=pos".into()]).unwrap();
    let mapped = PrepareOptions {
        map: map.clone(),
        resample: None,
    };
    // Renaming alone keeps the rows; a jittered time column then fails naming its row.
    let uniform = parse("time,torque,pos\n0,1,2\n0.5,1,2\n1,1,2\n").unwrap();
    let (plain, report) = prepare_table(uniform, &mapped).unwrap();
    assert_eq!(plain.header, names(&["t", "u", "theta"]));
    assert_eq!((report.rows_in, report.rows_out), (3, 3));
    let (line, column, p) = problem(prepare_table(table.clone(), &mapped));
    assert!(matches!(p, CsvProblem::NonUniformTime { .. }), "{p:?}");
    assert!((3..=n + 1).contains(&line) && column.as_deref() == Some("t"));
    assert!(p.to_string().contains("--resample"), "{p}");

    let opts = PrepareOptions {
        map,
        resample: Some(0.002),
    };
    let (table, report) = prepare_table(table, &opts).unwrap();
    let exp = table_to_experiment(&table, &names(&["u"]), &names(&["theta"])).unwrap();
    assert!((exp.dt() - 0.002).abs() < 1e-15);
    assert_eq!(report.rows_in, n);
    assert_eq!(report.rows_out, table.lines.len());
    let s = report.spacing_in.unwrap();
    assert!(s.min < 0.002 && s.max > 0.002 && s.std > 1e-4, "{s:?}");
    assert!(report.describe().contains("linear interpolation"));
    assert!(report.describe().contains("torque → u"));
    for k in 0..exp.len() {
        let tk = exp.t0() + k as f64 * 0.002;
        assert!(
            (exp.input(k)[0] - (1.0 + 3.0 * tk)).abs() < 1e-12,
            "u at {tk}"
        );
        // Steps up to 1.6·2 ms: h²/8·25 = 2.6e-5.
        assert!(
            (exp.output(k)[0] - (5.0 * tk).sin()).abs() < 2.6e-5,
            "y at {tk}"
        );
    }
    // A column the map names that the file lacks; an unmapped model name.
    let bad = PrepareOptions {
        map: vec![("u".into(), "tau".into())],
        resample: None,
    };
    let r = prepare_table(parse("t,x\n0,1\n1,2\n").unwrap(), &bad);
    assert!(matches!(problem(r), (1, _, CsvProblem::MissingChannel { name, .. }) if name == "tau"));
    assert!(PrepareOptions::parse_map(&["t".into()]).is_err());
    // Decreasing time names the row even when resampling.
    let r = prepare_table(
        parse("t,x\n0,1\n0.2,2\n0.1,3\n").unwrap(),
        &opts_resample(0.1),
    );
    assert!(matches!(
        problem(r),
        (4, _, CsvProblem::NonIncreasingTime { .. })
    ));
}

fn opts_resample(dt: f64) -> PrepareOptions {
    PrepareOptions {
        map: Vec::new(),
        resample: Some(dt),
    }
}

#[test]
fn empty_measured_cells_are_missing_samples() {
    let t = parse("t,u,y\n0,1,\n0.1,1,2\n0.2,1,\n").unwrap();
    let e = table_to_experiment(&t, &names(&["u"]), &names(&["y"])).unwrap();
    assert!(e.output(0)[0].is_nan() && e.output(2)[0].is_nan());
    assert!((e.output(1)[0] - 2.0).abs() < 1e-15);
}

/// Tables compare equal with NaN cells equal to each other (file lines compared only when
/// `lines` is set).
fn same_table(a: &Table, b: &Table, lines: bool) -> bool {
    a.header == b.header
        && (!lines || a.lines == b.lines)
        && a.columns.len() == b.columns.len()
        && a.columns.iter().zip(&b.columns).all(|(x, y)| {
            x.len() == y.len()
                && x.iter()
                    .zip(y)
                    .all(|(p, q)| p.to_bits() == q.to_bits() || (p.is_nan() && q.is_nan()))
        })
}

/// Files the fast path takes and files it hands over to the general reader.
fn edge_cases() -> [&'static str; 22] {
    [
        "t,u,y\n0,1,2\n0.1,1.5,\n0.2,-1e-3,nan\n",
        "t,u,y\r\n0,1,2\r\n0.1,1.5,3\r\n",
        "t,u,y\n0,1,2\n\n   \n0.1, 1.5 ,\t3\n",
        "t,u,y\n\n0,0,0\n\n\n1,1,1\r\n\r\n2,2,2\n",
        "t,u,y\n0,1,2\n0.1,1.5,3",
        " t , u ,y\n0,1,2\n",
        "t,\"u\",y\n0,1,2\n",
        "t,u,y\n0,1,2\r0.1,1,2\n",
        "t,u,y\n0,1,\r3\n",
        "t,u,y\n0,1\n",
        "t,u,y\n0,1,2,3\n",
        "t,u,y\n0,abc,2\n",
        "t,u,y\n0,inf,2\n",
        "t,u,y\n0,,2\n , , \n",
        "t,u,t\n0,1,2\n",
        "t,,y\n0,1,2\n",
        "t,\x0Bu,y\n0,\x0B1,2\n",
        "t\n0\n\n1\n",
        "t\n0\n \n1\n",
        "",
        "\nt,u\n0,1\n",
        "t,u,y\n",
    ]
}

/// A file over 1 MiB (two threads) with CRLF line ends, blank lines and empty cells.
fn big_file() -> String {
    let mut big = String::from("t,u,y\n");
    for k in 0..60_000 {
        if k % 7_919 == 0 {
            big.push_str("\r\n");
        }
        big.push_str(&format!(
            "{},{},{}\r\n",
            k as f64 * 0.01,
            (k as f64).sin(),
            k % 3
        ));
        if k % 11 == 0 {
            big.push_str(&format!("{},1,\n", k as f64 * 0.01 + 0.005));
        }
    }
    big
}

/// The fast path of `parse_table` gives what the general reader gives — the same values
/// and file lines, or the same typed error — on plain files, blank lines, CRLF line
/// ends, padded cells, empty cells, and on the files it hands over (quotes, a bare
/// carriage return, ragged rows, text, infinities). A file large enough for the
/// two-thread split (over 1 MiB, with blank lines on both sides of the cut) as well.
/// Both count file lines themselves (the `csv` crate's own count is one low after CRLF
/// line ends and after an empty line that follows a record).
#[test]
fn fast_parse_agrees_with_the_general_reader() {
    for text in edge_cases() {
        let fast = parse_table(Path::new("d.csv"), text.as_bytes());
        let general = parse_table_general(Path::new("d.csv"), text.as_bytes());
        match (&fast, &general) {
            (Ok(a), Ok(b)) => {
                assert!(same_table(a, b, true), "{text:?}: {a:?} vs {b:?}");
                if text.starts_with("t,u,y\r\n") {
                    assert_eq!(a.lines, vec![2, 3], "{text:?}");
                }
            }
            (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string(), "{text:?}"),
            _ => panic!("{text:?}: fast {fast:?}, general {general:?}"),
        }
    }
    let mut big = big_file();
    assert!(big.len() > 1 << 20);
    let a = parse_table(Path::new("d.csv"), big.as_bytes()).unwrap();
    let b = parse_table_general(Path::new("d.csv"), big.as_bytes()).unwrap();
    if !same_table(&a, &b, true) {
        let n = a.lines.len().min(b.lines.len());
        let k = (0..n)
            .find(|&k| {
                a.lines[k] != b.lines[k] || a.columns[1][k].to_bits() != b.columns[1][k].to_bits()
            })
            .unwrap_or(n);
        panic!(
            "rows {} vs {}; first difference at row {k}: fast line {:?} {:?}, general line {:?} {:?}",
            a.lines.len(),
            b.lines.len(),
            a.lines.get(k),
            a.columns.iter().map(|c| c.get(k)).collect::<Vec<_>>(),
            b.lines.get(k),
            b.columns.iter().map(|c| c.get(k)).collect::<Vec<_>>()
        );
    }
    // The file lines of the data rows, by counting.
    let expected: Vec<usize> = big
        .split('\n')
        .enumerate()
        .skip(1)
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, _)| i + 1)
        .collect();
    assert_eq!(a.lines, expected);
    // A bad cell in the second half names its line through the general reader.
    big.push_str("9999,oops,1\n");
    let lines = big.lines().count();
    let (line, column, _) = problem(parse_table(Path::new("d.csv"), big.as_bytes()));
    assert_eq!((line, column.as_deref()), (lines, Some("u")));
}

/// The CSV float text is ryu's, byte for byte (ryu wrote every file before, and the
/// round-trip tests compare files): on edge values (signed zeros, integers, the switch
/// to exponent notation at 1e16 and below 1e-5, subnormals, extremes, infinities), on
/// sampling times `k·0.01` and on 400,000 bit patterns drawn by a seeded splitmix64.
#[test]
fn csv_float_text_is_ryus() {
    let mut values = vec![
        0.0,
        -0.0,
        1.0,
        -1.0,
        100.0,
        0.1,
        1e15,
        9.999999999999998e15,
        1e16,
        1.5e16,
        -1e22,
        1e300,
        f64::MAX,
        f64::MIN,
        1e-4,
        1e-5,
        1.2345e-6,
        1e-7,
        f64::MIN_POSITIVE,
        5e-324,
        -5e-324,
        f64::EPSILON,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    values.extend((0..2000).map(|k| k as f64 * 0.01));
    let mut state = 0x9E37_79B9_7F4A_7C15_u64;
    let mut next = || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    };
    values.extend(
        (0..400_000)
            .map(|_| f64::from_bits(next()))
            .filter(|v| !v.is_nan()),
    );
    let mut ryu = ryu::Buffer::new();
    let mut expected = Vec::new();
    for &v in &values {
        expected.extend_from_slice(ryu.format(v).as_bytes());
        expected.push(b'\n');
    }
    let text = format_csv(&["v".to_string()], &[&values]);
    let body = text.strip_prefix("v\n").unwrap_or_default();
    assert_eq!(body.len(), expected.len());
    for (k, (a, b)) in body
        .lines()
        .zip(expected.split(|&c| c == b'\n'))
        .enumerate()
    {
        assert_eq!(a.as_bytes(), b, "value {k}: {}", values[k]);
    }
}

/// Reading a file in blocks (`read_table`) gives what the general reader gives on its
/// bytes — values, file lines, or the same error — on every edge case, on the large
/// file whose lines cross block boundaries, and on the same without its last line end.
#[test]
fn reading_a_file_in_blocks_agrees_with_the_general_reader() {
    let dir = std::env::temp_dir().join(format!("mmenn-read-blocks-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("d.csv");
    let big = big_file();
    let texts: Vec<&str> = edge_cases()
        .into_iter()
        .chain([big.as_str(), big.trim_end()])
        .collect();
    for text in texts {
        std::fs::write(&path, text).unwrap();
        let read = read_table(&path);
        let general = parse_table_general(&path, text.as_bytes());
        let shown = &text[..text.len().min(60)];
        match (&read, &general) {
            (Ok(a), Ok(b)) => assert!(same_table(a, b, true), "{shown:?}"),
            (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string(), "{shown:?}"),
            _ => panic!("{shown:?}: read {read:?}, general {general:?}"),
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
