//! The expression tree behind `Expr`: simplifying constructors, symbolic differentiation,
//! compilation to a postfix program, and canonical printing.

use std::fmt;

use super::Func;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum BinOp {
    Add,
    Sub,
    Mul,
    Div,
    Pow,
    /// `atan2(a, b)`: the angle of the point `(b, a)`, in `(-π, π]`.
    Atan2,
    /// `min(a, b)` (NaN if either is NaN).
    Min,
    /// `max(a, b)` (NaN if either is NaN).
    Max,
    /// `xmuly(a, b)`: `a·b`, except 0 where `a` is 0 and `a·b` is NaN (`b` infinite or
    /// NaN) — the chain rule's strong zero for a product (see the module doc of `expr`).
    XMulY,
    /// `xdivy(a, b)`: `a/b`, except 0 where `a` is 0 and `a/b` is NaN (`b` zero or NaN).
    XDivY,
}

impl BinOp {
    pub(super) fn apply(self, a: f64, b: f64) -> f64 {
        match self {
            BinOp::Add => a + b,
            BinOp::Sub => a - b,
            BinOp::Mul => a * b,
            BinOp::Div => a / b,
            // Squares are exact products; `powf` may differ from `a·a` by an ulp.
            #[allow(clippy::float_cmp)]
            BinOp::Pow if b == 2.0 => a * a,
            BinOp::Pow => a.powf(b),
            BinOp::Atan2 => a.atan2(b),
            BinOp::Min | BinOp::Max if a.is_nan() || b.is_nan() => f64::NAN,
            BinOp::Min => a.min(b),
            BinOp::Max => a.max(b),
            // Exactly the plain operation wherever that is not NaN (signed zeros included),
            // so a derivative keeps its bits wherever the plain chain rule was defined.
            BinOp::XMulY => strong_zero(a, a * b),
            BinOp::XDivY => strong_zero(a, a / b),
        }
    }

    /// The function name of an operator written as a call (`atan2(a, b)`), if it is one.
    pub(super) fn function_name(self) -> Option<&'static str> {
        match self {
            BinOp::Atan2 => Some("atan2"),
            BinOp::Min => Some("min"),
            BinOp::Max => Some("max"),
            BinOp::XMulY => Some("xmuly"),
            BinOp::XDivY => Some("xdivy"),
            _ => None,
        }
    }

    /// The two-argument function with this name, if any.
    pub(super) fn from_function_name(name: &str) -> Option<BinOp> {
        [
            BinOp::Atan2,
            BinOp::Min,
            BinOp::Max,
            BinOp::XMulY,
            BinOp::XDivY,
        ]
        .into_iter()
        .find(|op| op.function_name() == Some(name))
    }

    fn symbol(self) -> &'static str {
        match self {
            BinOp::Add => " + ",
            BinOp::Sub => " - ",
            BinOp::Mul => "*",
            BinOp::Div => "/",
            BinOp::Pow => "^",
            BinOp::Atan2 | BinOp::Min | BinOp::Max | BinOp::XMulY | BinOp::XDivY => ", ",
        }
    }
}

/// `value` (the plain product or quotient of `a` by something), or 0 where `a` is 0 and
/// `value` is NaN.
#[inline(always)]
fn strong_zero(a: f64, value: f64) -> f64 {
    if a == 0.0 && value.is_nan() {
        0.0
    } else {
        value
    }
}

/// Expression tree. Invariant: built only through the simplifying constructors below, so
/// constants are finite and no rule of the module doc applies to any node.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Tree {
    Const(f64),
    Var(usize),
    Neg(Box<Tree>),
    Bin(BinOp, Box<Tree>, Box<Tree>),
    Call(Func, Box<Tree>),
}

/// One instruction of the postfix program.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Op {
    Const(f64),
    Var(usize),
    Neg,
    Square,
    /// Integer power by repeated multiplication (`powi`): much cheaper than `powf`.
    PowI(i32),
    Call(Func),
    /// Pops `b` then `a`, pushes `a op b`.
    Bin(BinOp),
    /// Pops `a` then `b`, pushes `a op b` (the right operand was evaluated first).
    BinRev(BinOp),
    // A binary operation with a constant or variable operand that is read in the
    // instruction, not pushed: `top ∘ x_i` (`AddVar`, …), `x_i ∘ top` (`VarAdd`, …),
    // `top ∘ c` (`AddConst`, …) and `c ∘ top` (`ConstAdd`, …) for the four arithmetic
    // operations, each its own instruction so that evaluating it is one dispatch; the
    // other operators through `BinVar`, `VarBin`, `BinConst` and `ConstBin`.
    AddVar(usize),
    SubVar(usize),
    MulVar(usize),
    DivVar(usize),
    VarAdd(usize),
    VarSub(usize),
    VarMul(usize),
    VarDiv(usize),
    AddConst(f64),
    SubConst(f64),
    MulConst(f64),
    DivConst(f64),
    ConstAdd(f64),
    ConstSub(f64),
    ConstMul(f64),
    ConstDiv(f64),
    /// `top op x_i`.
    BinVar(BinOp, usize),
    /// `x_i op top`.
    VarBin(BinOp, usize),
    /// `top op c`.
    BinConst(BinOp, f64),
    /// `c op top`.
    ConstBin(BinOp, f64),
}

/// The instruction applying `op` to the top of the stack and a leaf operand read in
/// place: on the right (`leaf_right`) or on the left.
fn fused(op: BinOp, leaf: Leaf, leaf_right: bool) -> Op {
    // The four arithmetic instructions of one operand form, or the general one.
    let pick = |[add, sub, mul, div]: [Op; 4], other: Op| match op {
        BinOp::Add => add,
        BinOp::Sub => sub,
        BinOp::Mul => mul,
        BinOp::Div => div,
        _ => other,
    };
    match (leaf, leaf_right) {
        (Leaf::Var(i), true) => pick(
            [Op::AddVar(i), Op::SubVar(i), Op::MulVar(i), Op::DivVar(i)],
            Op::BinVar(op, i),
        ),
        (Leaf::Var(i), false) => pick(
            [Op::VarAdd(i), Op::VarSub(i), Op::VarMul(i), Op::VarDiv(i)],
            Op::VarBin(op, i),
        ),
        (Leaf::Const(c), true) => pick(
            [
                Op::AddConst(c),
                Op::SubConst(c),
                Op::MulConst(c),
                Op::DivConst(c),
            ],
            Op::BinConst(op, c),
        ),
        (Leaf::Const(c), false) => pick(
            [
                Op::ConstAdd(c),
                Op::ConstSub(c),
                Op::ConstMul(c),
                Op::ConstDiv(c),
            ],
            Op::ConstBin(op, c),
        ),
    }
}

/// A constant or variable operand.
#[derive(Clone, Copy)]
enum Leaf {
    Const(f64),
    Var(usize),
}

fn leaf(t: &Tree) -> Option<Leaf> {
    match *t {
        Tree::Const(c) => Some(Leaf::Const(c)),
        Tree::Var(i) => Some(Leaf::Var(i)),
        _ => None,
    }
}

// ---------------------------------------------------------------------------------------
// Simplifying constructors.

/// Exact equality with a literal, on purpose (simplification rules fire on exact 0, ±1).
#[allow(clippy::float_cmp)]
pub(super) fn is(t: &Tree, value: f64) -> bool {
    matches!(t, Tree::Const(c) if *c == value)
}

fn raw(op: BinOp, a: Tree, b: Tree) -> Tree {
    Tree::Bin(op, Box::new(a), Box::new(b))
}

pub(super) fn neg(a: Tree) -> Tree {
    match a {
        Tree::Const(c) => Tree::Const(-c),
        Tree::Neg(inner) => *inner,
        other => Tree::Neg(Box::new(other)),
    }
}

pub(super) fn call(f: Func, a: Tree) -> Tree {
    if let Tree::Const(c) = a {
        let v = f.apply(c);
        if v.is_finite() {
            return Tree::Const(v);
        }
    }
    Tree::Call(f, Box::new(a))
}

pub(super) fn bin(op: BinOp, a: Tree, b: Tree) -> Tree {
    if let (Tree::Const(x), Tree::Const(y)) = (&a, &b) {
        // Fold a power exactly as the compiled program evaluates it (`powi` for a small
        // integer exponent), so folding never changes a value.
        let v = match integer_exponent(&b) {
            Some(n) if op == BinOp::Pow && !is(&b, 2.0) => x.powi(n),
            _ => op.apply(*x, *y),
        };
        if v.is_finite() {
            return Tree::Const(v);
        }
    }
    match op {
        BinOp::Add | BinOp::Sub => {
            if is(&b, 0.0) {
                return a;
            }
            if is(&a, 0.0) {
                return if op == BinOp::Add { b } else { neg(b) };
            }
            let flipped = if op == BinOp::Add {
                BinOp::Sub
            } else {
                BinOp::Add
            };
            match b {
                Tree::Neg(inner) => raw(flipped, a, *inner),
                Tree::Const(c) if c < 0.0 => raw(flipped, a, Tree::Const(-c)),
                b => raw(op, a, b),
            }
        }
        BinOp::Mul => {
            if is(&a, 0.0) || is(&b, 0.0) {
                Tree::Const(0.0)
            } else if is(&a, 1.0) {
                b
            } else if is(&b, 1.0) {
                a
            } else if is(&a, -1.0) {
                neg(b)
            } else if is(&b, -1.0) {
                neg(a)
            } else {
                raw(op, a, b)
            }
        }
        BinOp::Div => {
            if is(&a, 0.0) {
                Tree::Const(0.0)
            } else if is(&b, 1.0) {
                a
            } else if is(&b, -1.0) {
                neg(a)
            } else {
                raw(op, a, b)
            }
        }
        BinOp::Pow => {
            if is(&b, 0.0) || is(&a, 1.0) {
                Tree::Const(1.0)
            } else if is(&b, 1.0) {
                a
            } else {
                raw(op, a, b)
            }
        }
        // 0 in the first place is 0 whatever the second (the strong zero); a nonzero
        // constant there makes the plain operation, which then equals it everywhere.
        BinOp::XMulY | BinOp::XDivY => {
            let plain = if op == BinOp::XMulY {
                BinOp::Mul
            } else {
                BinOp::Div
            };
            if is(&a, 0.0) {
                Tree::Const(0.0)
            } else if matches!(a, Tree::Const(_))
                || is(&b, 1.0)
                || is(&b, -1.0)
                || (plain == BinOp::Mul && is(&b, 0.0))
            {
                bin(plain, a, b)
            } else {
                raw(op, a, b)
            }
        }
        BinOp::Atan2 | BinOp::Min | BinOp::Max => raw(op, a, b),
    }
}

fn add(a: Tree, b: Tree) -> Tree {
    bin(BinOp::Add, a, b)
}
fn sub(a: Tree, b: Tree) -> Tree {
    bin(BinOp::Sub, a, b)
}
fn mul(a: Tree, b: Tree) -> Tree {
    bin(BinOp::Mul, a, b)
}
fn div(a: Tree, b: Tree) -> Tree {
    bin(BinOp::Div, a, b)
}
pub(super) fn pow(a: Tree, b: Tree) -> Tree {
    bin(BinOp::Pow, a, b)
}

// ---------------------------------------------------------------------------------------
// Derivative, variable walks, compilation.

/// The chain rule's `outer·da` where `outer` may be infinite or NaN while the function is
/// finite: `xmuly(da, outer)`, 0 wherever `da` is (the strong zero). A constant `da`
/// (nonzero: a zero folds the product away) gives the plain `outer*da`, which then equals
/// it everywhere and prints as before.
fn chain_mul(outer: Tree, da: Tree) -> Tree {
    if matches!(da, Tree::Const(_)) {
        mul(outer, da)
    } else {
        bin(BinOp::XMulY, da, outer)
    }
}

/// Symbolic derivative. Where the outer derivative of a chain-rule product can be
/// infinite or NaN while the function is finite (`sqrt`, `log`, `asin`, `acos`, a
/// fractional or negative constant power, a power with a varying exponent, `atan2` at the
/// origin), the product is `xmuly`/`xdivy`: 0 wherever the inner derivative is 0. A
/// constant inner derivative, which is never 0 there, gives the plain form (the
/// simplifying constructors see to it).
pub(super) fn diff(t: &Tree, v: usize) -> Tree {
    match t {
        Tree::Const(_) => Tree::Const(0.0),
        Tree::Var(i) => Tree::Const(if *i == v { 1.0 } else { 0.0 }),
        Tree::Neg(a) => neg(diff(a, v)),
        Tree::Bin(op, a, b) => {
            let (da, db) = (diff(a, v), diff(b, v));
            let (a, b) = (a.as_ref().clone(), b.as_ref().clone());
            match op {
                BinOp::Add => add(da, db),
                BinOp::Sub => sub(da, db),
                BinOp::Mul => add(mul(da, b), mul(a, db)),
                BinOp::Div if is(&db, 0.0) => div(da, b),
                BinOp::Div => div(
                    sub(mul(da, b.clone()), mul(a, db)),
                    pow(b, Tree::Const(2.0)),
                ),
                BinOp::Pow => match (&a, &b) {
                    // c·a^(c-1)·da; c - 1 is finite because c is. a^(c-1) is infinite at
                    // a = 0 (c < 1) or NaN below it (fractional c) where a^c may be finite:
                    // a strong zero there.
                    (_, Tree::Const(c)) => {
                        let c = *c;
                        let outer = mul(Tree::Const(c), pow(a, Tree::Const(c - 1.0)));
                        if c < 1.0 || c.fract() != 0.0 {
                            chain_mul(outer, da)
                        } else {
                            mul(outer, da)
                        }
                    }
                    // a^b·log(a)·db for a constant base.
                    (Tree::Const(_), _) => mul(mul(t.clone(), call(Func::Log, a)), db),
                    // b·a^(b-1)·da + a^b·log(a)·db. At a = 0 both outer factors are
                    // singular: a^(b-1) is infinite for b < 1, and a^b·log(a) is 0·(-inf)
                    // for b > 0, whose limit is 0. Each product is a strong zero of its
                    // first factor: `xmuly(da, ·)` is 0 where the base is held, and
                    // `xmuly(a^b, log(a))` is the limit 0 where the base is 0.
                    _ => {
                        let by_base = mul(b.clone(), pow(a.clone(), sub(b, Tree::Const(1.0))));
                        let by_exponent = bin(BinOp::XMulY, t.clone(), call(Func::Log, a));
                        add(chain_mul(by_base, da), bin(BinOp::XMulY, db, by_exponent))
                    }
                },
                // (b·da − a·db)/(a² + b²), which is 0/0 at the origin even where a and b
                // are held there (da = db = 0); with a varying inner derivative, each
                // partial is a strong zero: xmuly(da, b/(a² + b²)) − xmuly(db, a/(a² + b²)).
                BinOp::Atan2 => {
                    let norm = add(
                        pow(a.clone(), Tree::Const(2.0)),
                        pow(b.clone(), Tree::Const(2.0)),
                    );
                    if matches!(da, Tree::Const(_)) && matches!(db, Tree::Const(_)) {
                        div(sub(mul(b, da), mul(a, db)), norm)
                    } else {
                        sub(
                            bin(BinOp::XMulY, da, div(b, norm.clone())),
                            bin(BinOp::XMulY, db, div(a, norm)),
                        )
                    }
                }
                // min(a, b) = (a + b − |a − b|)/2, max(a, b) = (a + b + |a − b|)/2, so
                // the derivative is (da + db ∓ sign(a − b)·(da − db))/2.
                BinOp::Min | BinOp::Max => {
                    let s = mul(call(Func::Sign, sub(a, b)), sub(da.clone(), db.clone()));
                    let sum = add(da, db);
                    let inner = if *op == BinOp::Min {
                        sub(sum, s)
                    } else {
                        add(sum, s)
                    };
                    mul(Tree::Const(0.5), inner)
                }
                // Each product rule term keeps the strong zero of its first factor.
                BinOp::XMulY => add(bin(BinOp::XMulY, da, b.clone()), bin(BinOp::XMulY, a, db)),
                BinOp::XDivY => sub(
                    bin(BinOp::XDivY, da, b.clone()),
                    bin(BinOp::XDivY, mul(a, db), pow(b, Tree::Const(2.0))),
                ),
            }
        }
        Tree::Call(f, a) => {
            let da = diff(a, v);
            if is(&da, 0.0) {
                return Tree::Const(0.0);
            }
            let a = a.as_ref().clone();
            match f {
                Func::Sin => mul(call(Func::Cos, a), da),
                Func::Cos => neg(mul(call(Func::Sin, a), da)),
                Func::Tan => div(da, pow(call(Func::Cos, a), Tree::Const(2.0))),
                Func::Exp => mul(t.clone(), da),
                // 1/a and 1/(2·sqrt(a)) are infinite at a = 0: strong zeros.
                Func::Log => bin(BinOp::XDivY, da, a),
                Func::Sqrt => bin(BinOp::XDivY, da, mul(Tree::Const(2.0), t.clone())),
                Func::Abs => mul(call(Func::Sign, a), da),
                Func::Sign => Tree::Const(0.0),
                Func::Tanh => mul(sub(Tree::Const(1.0), pow(t.clone(), Tree::Const(2.0))), da),
                Func::Atan => div(da, add(Tree::Const(1.0), pow(a, Tree::Const(2.0)))),
                Func::Asin | Func::Acos => {
                    let root = call(Func::Sqrt, sub(Tree::Const(1.0), pow(a, Tree::Const(2.0))));
                    let da = if *f == Func::Asin { da } else { neg(da) };
                    // Infinite at a = ±1: a strong zero.
                    bin(BinOp::XDivY, da, root)
                }
                Func::Sinh => mul(call(Func::Cosh, a), da),
                Func::Cosh => mul(call(Func::Sinh, a), da),
            }
        }
    }
}

pub(super) fn collect_vars(t: &Tree, out: &mut Vec<usize>) {
    match t {
        Tree::Const(_) => {}
        Tree::Var(i) => out.push(*i),
        Tree::Neg(a) | Tree::Call(_, a) => collect_vars(a, out),
        Tree::Bin(_, a, b) => {
            collect_vars(a, out);
            collect_vars(b, out);
        }
    }
}

/// Re-index variables; `map[i]` is `Some` for every used `i` (checked by the caller).
pub(super) fn remap(t: &Tree, map: &[Option<usize>]) -> Tree {
    match t {
        Tree::Const(c) => Tree::Const(*c),
        Tree::Var(i) => Tree::Var(map.get(*i).copied().flatten().unwrap_or(*i)),
        Tree::Neg(a) => Tree::Neg(Box::new(remap(a, map))),
        Tree::Call(f, a) => Tree::Call(*f, Box::new(remap(a, map))),
        Tree::Bin(op, a, b) => raw(*op, remap(a, map), remap(b, map)),
    }
}

/// Replace every variable `i` with `values[i] = Some(c)` by the constant `c`, folding
/// through the simplifying constructors (a folded result that is not finite stays a
/// node, as in parsing).
pub(super) fn substitute(t: &Tree, values: &[Option<f64>]) -> Tree {
    match t {
        Tree::Const(c) => Tree::Const(*c),
        Tree::Var(i) => match values.get(*i).copied().flatten() {
            Some(c) if c.is_finite() => Tree::Const(c),
            _ => Tree::Var(*i),
        },
        Tree::Neg(a) => neg(substitute(a, values)),
        Tree::Call(f, a) => call(*f, substitute(a, values)),
        Tree::Bin(op, a, b) => bin(*op, substitute(a, values), substitute(b, values)),
    }
}

/// A constant exponent that is a small integer (|n| ≤ 16), evaluated by `powi`.
fn integer_exponent(t: &Tree) -> Option<i32> {
    match t {
        #[allow(clippy::float_cmp)]
        Tree::Const(c) if c.fract() == 0.0 && c.abs() <= 16.0 => Some(*c as i32),
        _ => None,
    }
}

/// Postfix program and the stack slots it needs. A binary operation with a constant or
/// variable operand reads that operand in its own instruction instead of pushing it (one
/// dispatch instead of two, one slot fewer; the right operand when both are leaves);
/// otherwise its operands are emitted deeper-subtree-first (Sethi–Ullman). Both are exact:
/// every operation gets the same operands in the same places, only the evaluation order
/// of independent operands changes.
pub(super) fn compile(t: &Tree) -> (Vec<Op>, usize) {
    match t {
        Tree::Const(c) => (vec![Op::Const(*c)], 1),
        Tree::Var(i) => (vec![Op::Var(*i)], 1),
        Tree::Neg(a) | Tree::Call(_, a) => {
            let (mut p, need) = compile(a);
            p.push(match t {
                Tree::Call(f, _) => Op::Call(*f),
                _ => Op::Neg,
            });
            (p, need)
        }
        Tree::Bin(BinOp::Pow, a, b) if is(b, 2.0) => {
            let (mut p, need) = compile(a);
            p.push(Op::Square);
            (p, need)
        }
        Tree::Bin(BinOp::Pow, a, b) if integer_exponent(b).is_some() => {
            let (mut p, need) = compile(a);
            p.push(Op::PowI(integer_exponent(b).unwrap_or(1)));
            (p, need)
        }
        Tree::Bin(op, a, b) => {
            let leaf_operand = match (leaf(a), leaf(b)) {
                (_, Some(l)) => Some((a, l, true)),
                (Some(l), None) => Some((b, l, false)),
                (None, None) => None,
            };
            if let Some((other, l, leaf_right)) = leaf_operand {
                let (mut p, need) = compile(other);
                p.push(fused(*op, l, leaf_right));
                return (p, need);
            }
            let (pa, na) = compile(a);
            let (pb, nb) = compile(b);
            let need = if na == nb { na + 1 } else { na.max(nb) };
            let (mut first, second, last) = if nb > na {
                (pb, pa, Op::BinRev(*op))
            } else {
                (pa, pb, Op::Bin(*op))
            };
            first.extend(second);
            first.push(last);
            (first, need)
        }
    }
}

// ---------------------------------------------------------------------------------------
// Printing.

const SUM: u8 = 1;
const PRODUCT: u8 = 2;
const NEG: u8 = 3;
const POWER: u8 = 4;
const ATOM: u8 = 5;

fn precedence(t: &Tree) -> u8 {
    match t {
        Tree::Const(c) if c.is_sign_negative() => NEG,
        Tree::Const(_) | Tree::Var(_) | Tree::Call(..) => ATOM,
        Tree::Neg(_) => NEG,
        Tree::Bin(BinOp::Add | BinOp::Sub, ..) => SUM,
        Tree::Bin(BinOp::Mul | BinOp::Div, ..) => PRODUCT,
        Tree::Bin(BinOp::Pow, ..) => POWER,
        Tree::Bin(BinOp::Atan2 | BinOp::Min | BinOp::Max | BinOp::XMulY | BinOp::XDivY, ..) => ATOM,
    }
}

fn write_operand(
    t: &Tree,
    parens: bool,
    names: &[String],
    f: &mut fmt::Formatter<'_>,
) -> fmt::Result {
    if parens {
        f.write_str("(")?;
        write_tree(t, names, f)?;
        f.write_str(")")
    } else {
        write_tree(t, names, f)
    }
}

pub(super) fn write_tree(t: &Tree, names: &[String], f: &mut fmt::Formatter<'_>) -> fmt::Result {
    match t {
        Tree::Const(c) => {
            if c.is_sign_negative() {
                f.write_str("-")?;
            }
            // `{:?}` is the shortest text that reads back to the same f64, with an
            // exponent for very large or small magnitudes; drop its `.0` on integers.
            let text = format!("{:?}", c.abs());
            f.write_str(text.strip_suffix(".0").unwrap_or(&text))
        }
        Tree::Var(i) => f.write_str(names.get(*i).map_or("?", String::as_str)),
        Tree::Neg(a) => {
            f.write_str("-")?;
            write_operand(a, precedence(a) < POWER, names, f)
        }
        Tree::Call(func, a) => {
            f.write_str(func.name())?;
            write_operand(a, true, names, f)
        }
        Tree::Bin(op, a, b) if op.function_name().is_some() => {
            f.write_str(op.function_name().unwrap_or("?"))?;
            f.write_str("(")?;
            write_tree(a, names, f)?;
            f.write_str(", ")?;
            write_tree(b, names, f)?;
            f.write_str(")")
        }
        Tree::Bin(op, a, b) => {
            let (left_min, right_min) = match op {
                BinOp::Add | BinOp::Sub => (SUM, PRODUCT),
                BinOp::Mul | BinOp::Div => (PRODUCT, POWER),
                BinOp::Pow => (ATOM, POWER),
                BinOp::Atan2 | BinOp::Min | BinOp::Max | BinOp::XMulY | BinOp::XDivY => (0, 0),
            };
            write_operand(a, precedence(a) < left_min, names, f)?;
            f.write_str(op.symbol())?;
            let pb = precedence(b);
            write_operand(b, pb < right_min || pb == NEG, names, f)
        }
    }
}
