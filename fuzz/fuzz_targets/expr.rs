//! The term-expression parser on arbitrary text over four variables; an expression it
//! accepts is printed, re-parsed, differentiated and evaluated.
#![no_main]

use libfuzzer_sys::fuzz_target;
use mmenn::sysid_core::Expr;

fuzz_target!(|text: &str| {
    let vars = ["x", "v", "theta", "u"];
    if let Ok(e) = Expr::parse(text, &vars) {
        let printed = e.to_string();
        let _ = Expr::parse(&printed, &vars);
        for i in 0..vars.len() {
            if let Ok(d) = e.derivative(i) {
                let _ = d.eval(&[0.3, -1.2, 2.0, 1e300]);
            }
        }
        let _ = e.eval(&[0.0, f64::NAN, -0.0, f64::INFINITY]);
    }
});
