//! Plain math expressions over named variables — the `term` strings of a model file
//! (SPEC §5): parsing with column-accurate errors, allocation-free evaluation, symbolic
//! derivatives and canonical, re-parseable printing.
//!
//! # Grammar
//!
//! From the loosest to the tightest binding:
//!
//! ```text
//! sum     := product (('+' | '-') product)*      left-associative: 1-2-3 = (1-2)-3
//! product := unary (('*' | '/') unary)*          left-associative: 8/4/2 = (8/4)/2
//! unary   := '-' unary | power                   -x^2 = -(x^2)
//! power   := primary ('^' unary)?                right-associative: 2^3^2 = 2^(3^2)
//! primary := number | name | function '(' sum ')' | function2 '(' sum ',' sum ')'
//!          | '(' sum ')'
//! ```
//!
//! Numbers are decimal literals with an optional exponent (`3`, `0.5`, `.5`, `1e-3`,
//! `2.5E+4`); a literal must be finite. Names are identifiers (a letter or `_`, then
//! letters, digits or `_`) and must be among the declared variables, except `pi`, which
//! is π unless a variable of that name is declared (it prints as its value). A name directly
//! followed by `(` is a function call; the one-argument functions are [`Func`]: `sin cos
//! tan asin acos atan exp log sqrt abs sign tanh sinh cosh`, where `log` is the natural
//! logarithm (`ln` is accepted for it) and `sign(0) = 0` (`sgn` is accepted for it); the
//! two-argument functions are `atan2(y, x)` (the angle of the point `(x, y)`, in
//! `(-π, π]`), `min(a, b)` and `max(a, b)` (NaN if either argument is NaN), and
//! `xmuly(a, b)` and `xdivy(a, b)`, which are `a*b` and `a/b` except that they are 0
//! where `a` is 0 (even where `b` is infinite or NaN, or 0 for `xdivy`): the chain rule's
//! products in symbolic derivatives (below), named after SciPy's and TensorFlow's
//! `xlogy`/`xdivy`. Powers are written with `^`. There is no implicit multiplication
//! (`2x` is an error) and no unary plus.
//!
//! # Values outside a function's domain
//!
//! Evaluation follows IEEE arithmetic (`a^b` is `a·a` when `b` is exactly 2, `powi` for another constant integer exponent up to 16 in magnitude, `powf`
//! otherwise): `sqrt(-1)` and `log(-1)` are NaN, `1/0` is `+inf`.
//! Callers that need finite values (integrators, estimators) check the results.
//!
//! # Derivatives
//!
//! [`Expr::derivative`] differentiates symbolically with the usual rules. Conventions at
//! points where the function is not differentiable, valid almost everywhere:
//! `d abs(a) = sign(a)·da` (0 at `a = 0`, a subgradient); `d sign(a) = 0`;
//! `d sqrt(a) = da/(2·sqrt(a))`, which is `+inf·da` at `a = 0`; `d a^c = c·a^(c-1)·da`
//! for a constant exponent `c`, and `a^b·(db·log(a) + b·da/a)` otherwise (needs `a > 0`);
//! `d min(a, b) = (da + db − sign(a − b)·(da − db))/2` and likewise for `max` with `+`
//! (the mean of both slopes where `a = b`); `d asin(a) = da/sqrt(1 − a²)` is infinite at
//! `a = ±1`.
//!
//! The chain rule has a strong zero: a term `g'(a)·da` is 0 wherever `da` is 0, even
//! where the outer slope `g'(a)` is infinite or NaN (the NaN-safe mode of forward-mode
//! automatic differentiation). So `d sqrt(max(x, 0))/dx` is 0 for `x < 0`, where the
//! function is constant, not `0/(2·sqrt(0))` = NaN; likewise `log`, `asin`, `acos`,
//! `a^c` for a constant `c < 1` or fractional, `a^b` (its `db·log(a)` and `b·da/a`) and
//! `atan2` at the origin (each argument's partial). Such a term is `xdivy(da, g)` or
//! `xmuly(da, g')` when `da` varies, and the plain `da/g` or `g'*da` when `da` is a
//! constant, which is never 0 there: `d sqrt(x)/dx = 1/(2*sqrt(x))` is still `+inf` at
//! `x = 0`. Wherever the plain rule gives a number (not NaN) both forms give the same
//! bits, except for `atan2` with a varying inner derivative: its two partials, written
//! apart, round differently from the plain `(b·da − a·db)/(a² + b²)`.
//!
//! # Simplification
//!
//! Every tree (parsed or differentiated) is built through the same light rules: constant
//! folding when the result is finite, `0·a = 0`, `0/a = 0`, `1·a = a`, `a/1 = a`,
//! `a ± 0 = a`, `0 - a = -a`, `-(-a) = a`, `a - (-b) = a + b`, `a + (-b) = a - b`,
//! `a^0 = 1`, `a^1 = a`, `1^a = 1`, `xmuly(0, b) = xdivy(0, b) = 0`, and `xmuly`/`xdivy`
//! become `*`/`/` with a nonzero constant first argument or a second argument of 0
//! (`xmuly`) or ±1. The rules `0·a = 0` and `0/a = 0` ignore the NaN that
//! IEEE gives for `a = ±inf` (or `a = 0` in `0/a`), so the simplified function equals the
//! written one wherever the written one is finite. Constants are always finite.
//!
//! # Printing
//!
//! [`Display`](std::fmt::Display) prints a canonical form: spaces around `+` and `-`,
//! none around `*`, `/` and `^`, and parentheses only where the grammar needs them (plus
//! around a negative right operand, `a*(-b)`, for readability). Parsing the printed text
//! with the same variables gives back the identical tree, hence the identical function.

use std::fmt;
use std::sync::Arc;

use thiserror::Error;

use parse::checked_names;
use tree::{Op, Tree, collect_vars, compile, diff, remap, substitute, write_tree};

mod parse;
#[cfg(test)]
mod tests;
mod tree;

/// Deepest nesting the parser accepts: parentheses, calls, unary minus, powers and
/// operator chains all add a level. Model-file terms are a few levels deep; the limit
/// keeps the recursive parser and the tree walks far from the thread's stack limit.
pub const MAX_DEPTH: usize = 100;

/// Evaluation stack size. Operands are emitted deeper-subtree-first (Sethi–Ullman order),
/// so a tree needs at most `log2(leaves) + 1` slots: 32 slots cover 2^31 leaves.
const STACK: usize = 32;

/// Errors from parsing, differentiating or re-binding an [`Expr`].
///
/// Columns are 0-based character (not byte) positions in the expression text.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum ExprError {
    /// The text holds no expression at all.
    #[error("empty expression (column {column})")]
    Empty {
        /// Column where an expression was expected.
        column: usize,
    },
    /// A character that starts no token.
    #[error("column {column}: unexpected character '{character}'")]
    UnexpectedCharacter {
        /// Column of the character.
        column: usize,
        /// The character.
        character: char,
    },
    /// A malformed or non-finite numeric literal.
    #[error("column {column}: invalid number '{text}': {reason}")]
    InvalidNumber {
        /// Column where the literal starts.
        column: usize,
        /// The literal as written.
        text: String,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// A name that is not a declared variable.
    #[error("column {column}: unknown name '{name}' (variables: {})", .known.join(", "))]
    UnknownName {
        /// Column where the name starts.
        column: usize,
        /// The name.
        name: String,
        /// The declared variables.
        known: Vec<String>,
    },
    /// A call of a function that does not exist.
    #[error(
        "column {column}: unknown function '{name}' (functions: sin cos tan asin acos atan \
         exp log sqrt abs sign tanh sinh cosh; atan2(y, x) min(a, b) max(a, b) xmuly(a, b) \
         xdivy(a, b))"
    )]
    UnknownFunction {
        /// Column where the function name starts.
        column: usize,
        /// The name.
        name: String,
    },
    /// A token where something else was required.
    #[error("column {column}: expected {expected}, found {found}")]
    UnexpectedToken {
        /// Column of the token.
        column: usize,
        /// The token as written (quoted), or `end of input`.
        found: String,
        /// What the grammar required there.
        expected: &'static str,
    },
    /// A `(` that is never closed.
    #[error("column {column}: '(' is never closed")]
    UnclosedParenthesis {
        /// Column of the `(`.
        column: usize,
    },
    /// A `)` with no matching `(`.
    #[error("column {column}: ')' has no matching '('")]
    UnmatchedParenthesis {
        /// Column of the `)`.
        column: usize,
    },
    /// Tokens left over after a complete expression.
    #[error("column {column}: expected an operator or the end, found {found}")]
    TrailingInput {
        /// Column of the first left-over token.
        column: usize,
        /// That token, quoted.
        found: String,
    },
    /// Nesting deeper than [`MAX_DEPTH`].
    #[error("column {column}: expression nested deeper than {limit} levels")]
    TooDeep {
        /// Column where the limit was passed.
        column: usize,
        /// The limit.
        limit: usize,
    },
    /// A declared variable name that is not an identifier (it could not be printed back).
    #[error("variable name '{name}' is not an identifier")]
    InvalidVariableName {
        /// The name.
        name: String,
    },
    /// A variable declared twice.
    #[error("variable '{name}' is declared twice")]
    DuplicateVariable {
        /// The name.
        name: String,
    },
    /// A variable index beyond the declared variables.
    #[error("variable index {index} is out of range for {n_variables} variables")]
    VariableIndex {
        /// The index asked for.
        index: usize,
        /// Number of declared variables.
        n_variables: usize,
    },
    /// Re-binding to a variable list that lacks a variable the expression uses.
    #[error("the expression uses '{name}', which is not among the new variables")]
    MissingVariable {
        /// The variable's name.
        name: String,
    },
}

/// The functions an expression may call.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Func {
    /// Sine (radians).
    Sin,
    /// Cosine (radians).
    Cos,
    /// Tangent (radians).
    Tan,
    /// Exponential `e^x`.
    Exp,
    /// Natural logarithm (NaN below 0, `-inf` at 0).
    Log,
    /// Square root (NaN below 0).
    Sqrt,
    /// Absolute value.
    Abs,
    /// Sign: 1 above 0, -1 below, 0 at 0 (NaN for NaN).
    Sign,
    /// Hyperbolic tangent.
    Tanh,
    /// Arc tangent, in `(-π/2, π/2)`.
    Atan,
    /// Arc sine, in `[-π/2, π/2]` (NaN outside `[-1, 1]`).
    Asin,
    /// Arc cosine, in `[0, π]` (NaN outside `[-1, 1]`).
    Acos,
    /// Hyperbolic sine.
    Sinh,
    /// Hyperbolic cosine.
    Cosh,
}

impl Func {
    /// Every function, in the order the grammar lists them.
    pub const ALL: [Func; 14] = [
        Func::Sin,
        Func::Cos,
        Func::Tan,
        Func::Exp,
        Func::Log,
        Func::Sqrt,
        Func::Abs,
        Func::Sign,
        Func::Tanh,
        Func::Atan,
        Func::Asin,
        Func::Acos,
        Func::Sinh,
        Func::Cosh,
    ];

    /// The name used in expressions.
    pub fn name(self) -> &'static str {
        match self {
            Func::Sin => "sin",
            Func::Cos => "cos",
            Func::Tan => "tan",
            Func::Exp => "exp",
            Func::Log => "log",
            Func::Sqrt => "sqrt",
            Func::Abs => "abs",
            Func::Sign => "sign",
            Func::Tanh => "tanh",
            Func::Atan => "atan",
            Func::Asin => "asin",
            Func::Acos => "acos",
            Func::Sinh => "sinh",
            Func::Cosh => "cosh",
        }
    }

    /// The function with this name (or the aliases `sgn` for `sign`, `ln` for `log`),
    /// if any.
    pub fn from_name(name: &str) -> Option<Func> {
        match name {
            "sgn" => Some(Func::Sign),
            "ln" => Some(Func::Log),
            _ => Self::ALL.into_iter().find(|f| f.name() == name),
        }
    }

    /// Evaluate the function at `x`.
    pub fn apply(self, x: f64) -> f64 {
        match self {
            Func::Sin => x.sin(),
            Func::Cos => x.cos(),
            Func::Tan => x.tan(),
            Func::Exp => x.exp(),
            Func::Log => x.ln(),
            Func::Sqrt => x.sqrt(),
            Func::Abs => x.abs(),
            Func::Sign => {
                // `f64::signum` gives 1 at +0; the mathematical sign is 0 there.
                if x > 0.0 {
                    1.0
                } else if x < 0.0 {
                    -1.0
                } else {
                    x
                }
            }
            Func::Tanh => x.tanh(),
            Func::Atan => x.atan(),
            Func::Asin => x.asin(),
            Func::Acos => x.acos(),
            Func::Sinh => x.sinh(),
            Func::Cosh => x.cosh(),
        }
    }
}

/// A parsed expression over an ordered list of named variables.
///
/// It keeps the tree (for derivatives and printing) and a postfix program compiled from
/// it (for evaluation: no allocation, no recursion).
///
/// ```
/// use sysid_core::Expr;
///
/// let e = Expr::parse("omega*abs(omega) - 2^-1", &["theta", "omega"])?;
/// assert_eq!(e.eval(&[0.0, -3.0]), -9.5);
/// assert_eq!(e.derivative(1)?.to_string(), "abs(omega) + omega*sign(omega)");
/// assert_eq!(e.to_string(), "omega*abs(omega) - 0.5");
/// # Ok::<(), sysid_core::ExprError>(())
/// ```
#[derive(Debug, Clone)]
pub struct Expr {
    tree: Tree,
    names: Arc<[String]>,
    program: Box<[Op]>,
    shape: Shape,
}

/// How [`Expr::run`] evaluates the program: the shapes most model terms and their
/// derivatives have (a constant, a variable, its square or integer power, a product of two
/// variables, and the polynomial terms' `c·x`, `c·x²`, `c·xⁿ`, `x²·y`, `c·x·y`, `y·|x|`)
/// directly, the rest on a stack of the size the program needs. Each shape computes
/// exactly what its program computes (same operations, same operands, same order).
#[derive(Debug, Clone, Copy)]
enum Shape {
    Const(f64),
    Var(usize),
    Square(usize),
    PowI(usize, i32),
    Product(usize, usize),
    /// `c·x_i`.
    ConstTimes(f64, usize),
    /// `c·(x_i·x_i)`.
    ConstTimesSquare(f64, usize),
    /// `c·x_iⁿ` (`powi`).
    ConstTimesPowI(f64, usize, i32),
    /// `(x_i·x_i)·x_j`.
    SquareTimes(usize, usize),
    /// `x_j·(x_i·x_i)`.
    TimesSquare(usize, usize),
    /// `(c·x_i)·x_j`.
    ConstProduct(f64, usize, usize),
    /// `x_j·|x_i|`.
    TimesAbs(usize, usize),
    /// The stack machine with [`SMALL_STACK`] slots.
    Small,
    /// The stack machine with [`STACK`] slots.
    Large,
}

/// Stack slots of [`Shape::Small`]: enough for trees of up to 8 leaves.
const SMALL_STACK: usize = 4;

impl Shape {
    fn of(program: &[Op], need: usize) -> Shape {
        match *program {
            [Op::Const(c)] => Shape::Const(c),
            [Op::Var(i)] => Shape::Var(i),
            [Op::Var(i), Op::Square] => Shape::Square(i),
            [Op::Var(i), Op::PowI(n)] => Shape::PowI(i, n),
            [Op::Var(i), Op::MulVar(j)] => Shape::Product(i, j),
            [Op::Const(c), Op::MulVar(i)] | [Op::Var(i), Op::ConstMul(c)] => {
                Shape::ConstTimes(c, i)
            }
            [Op::Var(i), Op::Square, Op::ConstMul(c)] => Shape::ConstTimesSquare(c, i),
            [Op::Var(i), Op::PowI(n), Op::ConstMul(c)] => Shape::ConstTimesPowI(c, i, n),
            [Op::Var(i), Op::Square, Op::MulVar(j)] => Shape::SquareTimes(i, j),
            [Op::Var(i), Op::Square, Op::VarMul(j)] => Shape::TimesSquare(i, j),
            [Op::Const(c), Op::MulVar(i), Op::MulVar(j)] => Shape::ConstProduct(c, i, j),
            [Op::Var(i), Op::Call(Func::Abs), Op::VarMul(j)] => Shape::TimesAbs(i, j),
            _ if need <= SMALL_STACK => Shape::Small,
            _ => Shape::Large,
        }
    }
}

impl PartialEq for Expr {
    /// Same tree over the same variable names (the program follows from the tree).
    fn eq(&self, other: &Self) -> bool {
        self.tree == other.tree && self.names == other.names
    }
}

impl Expr {
    /// Parse `text` with the given variables (index `i` in `variables` is the `i`-th entry
    /// of the slice passed to [`Expr::eval`]).
    pub fn parse(text: &str, variables: &[&str]) -> Result<Expr, ExprError> {
        let names = checked_names(variables)?;
        let tree = parse::parse_tree(text, variables)?;
        Ok(Expr::from_tree(tree, names))
    }

    fn from_tree(tree: Tree, names: Arc<[String]>) -> Expr {
        let (program, need) = compile(&tree);
        debug_assert!(need <= STACK, "Sethi-Ullman bound exceeded");
        let shape = Shape::of(&program, need);
        Expr {
            tree,
            names,
            program: program.into_boxed_slice(),
            shape,
        }
    }

    /// Evaluate at `vars` (one value per declared variable, in declaration order).
    ///
    /// # Panics
    /// If `vars` is shorter than the highest variable index the expression uses
    /// (like slice indexing).
    pub fn eval(&self, vars: &[f64]) -> f64 {
        self.eval_parts(vars, &[])
    }

    /// Evaluate with the variables split over two slices: variable `i` is `head[i]` for
    /// `i < head.len()` and `tail[i - head.len()]` after it. Lets a model evaluate over
    /// states followed by inputs without copying them into one buffer.
    ///
    /// # Panics
    /// If `head` and `tail` together are shorter than the highest variable index used.
    #[inline]
    pub fn eval_parts(&self, head: &[f64], tail: &[f64]) -> f64 {
        self.run(|i| {
            if i < head.len() {
                head[i]
            } else {
                tail[i - head.len()]
            }
        })
    }

    /// Evaluate with the variables split over three slices, in order: a model's states,
    /// inputs and parameters (variable `i` is `x[i]`, then `u[i - x.len()]`, then
    /// `p[i - x.len() - u.len()]`), without copying them into one buffer.
    ///
    /// # Panics
    /// If the three slices together are shorter than the highest variable index used.
    pub fn eval3(&self, x: &[f64], u: &[f64], p: &[f64]) -> f64 {
        let (nx, nxu) = (x.len(), x.len() + u.len());
        self.run(|i| {
            if i < nx {
                x[i]
            } else if i < nxu {
                u[i - nx]
            } else {
                p[i - nxu]
            }
        })
    }

    /// The program, variable `i` read by `var(i)` (see [`Shape`]).
    #[inline(always)]
    fn run(&self, var: impl Fn(usize) -> f64) -> f64 {
        match self.shape {
            Shape::Const(c) => c,
            Shape::Var(i) => var(i),
            Shape::Square(i) => {
                let x = var(i);
                x * x
            }
            Shape::PowI(i, n) => var(i).powi(n),
            Shape::Product(i, j) => var(i) * var(j),
            Shape::ConstTimes(c, i) => c * var(i),
            Shape::ConstTimesSquare(c, i) => {
                let x = var(i);
                c * (x * x)
            }
            Shape::ConstTimesPowI(c, i, n) => c * var(i).powi(n),
            Shape::SquareTimes(i, j) => {
                let x = var(i);
                x * x * var(j)
            }
            Shape::TimesSquare(i, j) => {
                let x = var(i);
                var(j) * (x * x)
            }
            Shape::ConstProduct(c, i, j) => c * var(i) * var(j),
            Shape::TimesAbs(i, j) => var(j) * var(i).abs(),
            Shape::Small => self.exec_small(var),
            Shape::Large => self.exec_large(var),
        }
    }

    // The stack machine stays out of line so that `run`, inlined into its callers, costs
    // them only the shape dispatch, and the short shapes run without a call.
    #[inline(never)]
    fn exec_small(&self, var: impl Fn(usize) -> f64) -> f64 {
        self.exec::<SMALL_STACK>(var)
    }

    #[inline(never)]
    fn exec_large(&self, var: impl Fn(usize) -> f64) -> f64 {
        self.exec::<STACK>(var)
    }

    /// The postfix program on a stack of `N` slots.
    // Every operation is written `a op b` with its operands in their places in the tree
    // (`x_i + top` is not `top += x_i`): the program computes what the tree says, operand
    // for operand.
    #[allow(clippy::assign_op_pattern)]
    #[inline(always)]
    fn exec<const N: usize>(&self, var: impl Fn(usize) -> f64) -> f64 {
        let mut stack = [0.0_f64; N];
        let mut sp = 0_usize;
        for op in self.program.iter() {
            match *op {
                Op::Const(c) => {
                    stack[sp] = c;
                    sp += 1;
                }
                Op::Var(i) => {
                    stack[sp] = var(i);
                    sp += 1;
                }
                Op::Neg => stack[sp - 1] = -stack[sp - 1],
                Op::Square => stack[sp - 1] *= stack[sp - 1],
                Op::PowI(n) => stack[sp - 1] = stack[sp - 1].powi(n),
                Op::Call(f) => stack[sp - 1] = f.apply(stack[sp - 1]),
                Op::Bin(op) => {
                    sp -= 1;
                    stack[sp - 1] = op.apply(stack[sp - 1], stack[sp]);
                }
                Op::BinRev(op) => {
                    sp -= 1;
                    stack[sp - 1] = op.apply(stack[sp], stack[sp - 1]);
                }
                Op::AddVar(i) => stack[sp - 1] = stack[sp - 1] + var(i),
                Op::SubVar(i) => stack[sp - 1] = stack[sp - 1] - var(i),
                Op::MulVar(i) => stack[sp - 1] = stack[sp - 1] * var(i),
                Op::DivVar(i) => stack[sp - 1] = stack[sp - 1] / var(i),
                Op::VarAdd(i) => stack[sp - 1] = var(i) + stack[sp - 1],
                Op::VarSub(i) => stack[sp - 1] = var(i) - stack[sp - 1],
                Op::VarMul(i) => stack[sp - 1] = var(i) * stack[sp - 1],
                Op::VarDiv(i) => stack[sp - 1] = var(i) / stack[sp - 1],
                Op::AddConst(c) => stack[sp - 1] = stack[sp - 1] + c,
                Op::SubConst(c) => stack[sp - 1] = stack[sp - 1] - c,
                Op::MulConst(c) => stack[sp - 1] = stack[sp - 1] * c,
                Op::DivConst(c) => stack[sp - 1] = stack[sp - 1] / c,
                Op::ConstAdd(c) => stack[sp - 1] = c + stack[sp - 1],
                Op::ConstSub(c) => stack[sp - 1] = c - stack[sp - 1],
                Op::ConstMul(c) => stack[sp - 1] = c * stack[sp - 1],
                Op::ConstDiv(c) => stack[sp - 1] = c / stack[sp - 1],
                Op::BinVar(op, i) => stack[sp - 1] = op.apply(stack[sp - 1], var(i)),
                Op::VarBin(op, i) => stack[sp - 1] = op.apply(var(i), stack[sp - 1]),
                Op::BinConst(op, c) => stack[sp - 1] = op.apply(stack[sp - 1], c),
                Op::ConstBin(op, c) => stack[sp - 1] = op.apply(c, stack[sp - 1]),
            }
        }
        stack[0]
    }

    /// Symbolic derivative with respect to variable `var` (see the module doc for the
    /// conventions at non-differentiable points).
    pub fn derivative(&self, var: usize) -> Result<Expr, ExprError> {
        if var >= self.names.len() {
            return Err(ExprError::VariableIndex {
                index: var,
                n_variables: self.names.len(),
            });
        }
        Ok(Expr::from_tree(
            diff(&self.tree, var),
            Arc::clone(&self.names),
        ))
    }

    /// Indices of the variables the expression uses, ascending, without repeats.
    pub fn variables_used(&self) -> Vec<usize> {
        let mut used = Vec::new();
        collect_vars(&self.tree, &mut used);
        used.sort_unstable();
        used.dedup();
        used
    }

    /// The declared variable names, in order.
    pub fn variables(&self) -> &[String] {
        &self.names
    }

    /// The value, if the expression is a constant.
    pub fn constant(&self) -> Option<f64> {
        match self.tree {
            Tree::Const(c) => Some(c),
            _ => None,
        }
    }

    /// The expression with some variables replaced by constants: variable `i` becomes
    /// `values[i]` where that is `Some` and finite (missing entries and `None` stay
    /// variables). Constant subtrees fold as in parsing, so `substitute` of every variable
    /// gives a [`Expr::constant`] wherever the value is finite. The variable list is
    /// unchanged; drop the replaced names with [`Expr::with_variables`].
    ///
    /// ```
    /// use sysid_core::Expr;
    ///
    /// let e = Expr::parse("cf*atan(100*omega)", &["omega", "cf"])?;
    /// let bound = e.substitute(&[None, Some(0.5)]).with_variables(&["omega"])?;
    /// assert_eq!(bound.to_string(), "0.5*atan(100*omega)");
    /// # Ok::<(), sysid_core::ExprError>(())
    /// ```
    pub fn substitute(&self, values: &[Option<f64>]) -> Expr {
        Expr::from_tree(substitute(&self.tree, values), Arc::clone(&self.names))
    }

    /// The same function over another variable list, matching variables by name. Fails
    /// if a used variable is missing from `variables` (unused ones may be dropped).
    pub fn with_variables(&self, variables: &[&str]) -> Result<Expr, ExprError> {
        let names = checked_names(variables)?;
        let mut map = Vec::with_capacity(self.names.len());
        for name in self.names.iter() {
            map.push(variables.iter().position(|v| v == name));
        }
        for i in self.variables_used() {
            if map[i].is_none() {
                return Err(ExprError::MissingVariable {
                    name: self.names[i].clone(),
                });
            }
        }
        Ok(Expr::from_tree(remap(&self.tree, &map), names))
    }
}

impl fmt::Display for Expr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write_tree(&self.tree, &self.names, f)
    }
}
