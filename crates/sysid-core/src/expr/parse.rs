//! Lexer and recursive-descent parser for expression text, with column-accurate errors.

use std::sync::Arc;

use super::tree::{BinOp, Tree, bin, call, neg, pow};
use super::{ExprError, Func, MAX_DEPTH};

// ---------------------------------------------------------------------------------------
// Lexer and parser.

fn is_name_start(c: char) -> bool {
    c.is_alphabetic() || c == '_'
}

fn is_name_char(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

pub(super) fn checked_names(variables: &[&str]) -> Result<Arc<[String]>, ExprError> {
    for (k, name) in variables.iter().enumerate() {
        let mut chars = name.chars();
        let ok = chars.next().is_some_and(is_name_start) && chars.all(is_name_char);
        if !ok {
            return Err(ExprError::InvalidVariableName {
                name: (*name).to_owned(),
            });
        }
        if variables[..k].contains(name) {
            return Err(ExprError::DuplicateVariable {
                name: (*name).to_owned(),
            });
        }
    }
    Ok(variables.iter().map(|s| (*s).to_owned()).collect())
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Num(f64),
    Name(String),
    Plus,
    Minus,
    Star,
    Slash,
    Caret,
    Open,
    Close,
    Comma,
    End,
}

#[derive(Debug, Clone)]
struct Token {
    tok: Tok,
    column: usize,
    text: String,
}

fn describe(t: &Token) -> String {
    match t.tok {
        Tok::End => "end of input".to_owned(),
        _ => format!("'{}'", t.text),
    }
}

fn lex(text: &str) -> Result<Vec<Token>, ExprError> {
    let chars: Vec<char> = text.chars().collect();
    let n = chars.len();
    let digits_from = |mut j: usize| {
        while j < n && chars[j].is_ascii_digit() {
            j += 1;
        }
        j
    };
    let mut out = Vec::new();
    let mut i = 0;
    while i < n {
        let c = chars[i];
        let start = i;
        let single = match c {
            '+' => Some(Tok::Plus),
            '-' => Some(Tok::Minus),
            '*' => Some(Tok::Star),
            '/' => Some(Tok::Slash),
            '^' => Some(Tok::Caret),
            '(' => Some(Tok::Open),
            ')' => Some(Tok::Close),
            ',' => Some(Tok::Comma),
            _ => None,
        };
        if c.is_whitespace() {
            i += 1;
            continue;
        } else if let Some(tok) = single {
            i += 1;
            out.push(Token {
                tok,
                column: start,
                text: c.to_string(),
            });
            continue;
        } else if c.is_ascii_digit() || c == '.' {
            let int_end = digits_from(i);
            let mut end = int_end;
            let mut digits = int_end - i;
            if end < n && chars[end] == '.' {
                let frac_end = digits_from(end + 1);
                digits += frac_end - end - 1;
                end = frac_end;
            }
            let invalid = |end: usize, reason| ExprError::InvalidNumber {
                column: start,
                text: chars[start..end].iter().collect(),
                reason,
            };
            if digits == 0 {
                return Err(invalid(end, "a number needs at least one digit"));
            }
            if end < n && (chars[end] == 'e' || chars[end] == 'E') {
                let mut k = end + 1;
                if k < n && (chars[k] == '+' || chars[k] == '-') {
                    k += 1;
                }
                let exp_end = digits_from(k);
                if exp_end == k {
                    return Err(invalid(k.min(n), "the exponent has no digits"));
                }
                end = exp_end;
            }
            let literal: String = chars[start..end].iter().collect();
            let value: f64 = literal
                .parse()
                .map_err(|_| invalid(end, "not a decimal number"))?;
            if !value.is_finite() {
                return Err(invalid(end, "too large for a 64-bit float"));
            }
            out.push(Token {
                tok: Tok::Num(value),
                column: start,
                text: literal,
            });
            i = end;
        } else if is_name_start(c) {
            let mut end = i + 1;
            while end < n && is_name_char(chars[end]) {
                end += 1;
            }
            let name: String = chars[start..end].iter().collect();
            out.push(Token {
                tok: Tok::Name(name.clone()),
                column: start,
                text: name,
            });
            i = end;
        } else {
            return Err(ExprError::UnexpectedCharacter {
                column: start,
                character: c,
            });
        }
    }
    out.push(Token {
        tok: Tok::End,
        column: n,
        text: String::new(),
    });
    Ok(out)
}

/// Recursive-descent parser; every method returns the tree and an upper bound on its
/// height. `level` counts recursion, so both are kept under [`MAX_DEPTH`].
struct Parser<'a> {
    tokens: Vec<Token>,
    pos: usize,
    variables: &'a [&'a str],
    /// Parentheses currently open.
    open: usize,
}

type Parsed = (Tree, usize);

pub(super) const OPERAND: &str = "a number, a variable, a function call or '('";

impl Parser<'_> {
    /// The current token; the last token is `End`, and `pos` never moves past it.
    fn peek(&self) -> &Token {
        &self.tokens[self.pos.min(self.tokens.len() - 1)]
    }

    fn bump(&mut self) {
        if self.pos + 1 < self.tokens.len() {
            self.pos += 1;
        }
    }

    fn limit(value: usize, column: usize) -> Result<usize, ExprError> {
        if value > MAX_DEPTH {
            Err(ExprError::TooDeep {
                column,
                limit: MAX_DEPTH,
            })
        } else {
            Ok(value)
        }
    }

    fn sum(&mut self, level: usize) -> Result<Parsed, ExprError> {
        let (mut tree, mut height) = self.product(level)?;
        loop {
            let op = match self.peek().tok {
                Tok::Plus => BinOp::Add,
                Tok::Minus => BinOp::Sub,
                _ => return Ok((tree, height)),
            };
            let column = self.peek().column;
            self.bump();
            let (rhs, h) = self.product(level)?;
            height = Self::limit(height.max(h) + 1, column)?;
            tree = bin(op, tree, rhs);
        }
    }

    fn product(&mut self, level: usize) -> Result<Parsed, ExprError> {
        let (mut tree, mut height) = self.unary(level)?;
        loop {
            let op = match self.peek().tok {
                Tok::Star => BinOp::Mul,
                Tok::Slash => BinOp::Div,
                _ => return Ok((tree, height)),
            };
            let column = self.peek().column;
            self.bump();
            let (rhs, h) = self.unary(level)?;
            height = Self::limit(height.max(h) + 1, column)?;
            tree = bin(op, tree, rhs);
        }
    }

    fn unary(&mut self, level: usize) -> Result<Parsed, ExprError> {
        if self.peek().tok != Tok::Minus {
            return self.power(level);
        }
        let column = self.peek().column;
        self.bump();
        let level = Self::limit(level + 1, column)?;
        let (tree, h) = self.unary(level)?;
        Ok((neg(tree), Self::limit(h + 1, column)?))
    }

    fn power(&mut self, level: usize) -> Result<Parsed, ExprError> {
        let (base, hb) = self.primary(level)?;
        if self.peek().tok != Tok::Caret {
            return Ok((base, hb));
        }
        let column = self.peek().column;
        self.bump();
        let level = Self::limit(level + 1, column)?;
        let (exponent, he) = self.unary(level)?;
        Ok((pow(base, exponent), Self::limit(hb.max(he) + 1, column)?))
    }

    fn primary(&mut self, level: usize) -> Result<Parsed, ExprError> {
        let token = self.peek().clone();
        match token.tok {
            Tok::Num(v) => {
                self.bump();
                Ok((Tree::Const(v), 1))
            }
            Tok::Name(name) => {
                self.bump();
                let next = self.peek();
                if next.tok == Tok::Open
                    && let Some(op) = BinOp::from_function_name(&name)
                {
                    let open_column = next.column;
                    self.bump();
                    let (a, b, h) = self.pair(level, open_column)?;
                    Ok((bin(op, a, b), Self::limit(h + 1, token.column)?))
                } else if next.tok == Tok::Open {
                    let func = Func::from_name(&name).ok_or(ExprError::UnknownFunction {
                        column: token.column,
                        name,
                    })?;
                    let open_column = next.column;
                    self.bump();
                    let (arg, h) = self.group(level, open_column)?;
                    Ok((call(func, arg), Self::limit(h + 1, token.column)?))
                } else if let Some(i) = self.variables.iter().position(|v| *v == name) {
                    Ok((Tree::Var(i), 1))
                } else if name == "pi" {
                    Ok((Tree::Const(std::f64::consts::PI), 1))
                } else if Func::from_name(&name).is_some()
                    || BinOp::from_function_name(&name).is_some()
                {
                    Err(ExprError::UnexpectedToken {
                        column: next.column,
                        found: describe(next),
                        expected: "'(' after a function name",
                    })
                } else {
                    let known = self.variables.iter().map(|v| (*v).to_owned()).collect();
                    Err(ExprError::UnknownName {
                        column: token.column,
                        name,
                        known,
                    })
                }
            }
            Tok::Open => {
                self.bump();
                self.group(level, token.column)
            }
            Tok::Close if self.open == 0 => Err(ExprError::UnmatchedParenthesis {
                column: token.column,
            }),
            Tok::End if self.pos == 0 => Err(ExprError::Empty { column: 0 }),
            _ => Err(ExprError::UnexpectedToken {
                column: token.column,
                found: describe(&token),
                expected: OPERAND,
            }),
        }
    }

    /// The two arguments of a two-argument call whose `(` at `open_column` is consumed,
    /// and its `)`; the height is the taller argument's.
    fn pair(&mut self, level: usize, open_column: usize) -> Result<(Tree, Tree, usize), ExprError> {
        let level = Self::limit(level + 1, open_column)?;
        self.open += 1;
        let (a, ha) = self.sum(level)?;
        let next = self.peek();
        match next.tok {
            Tok::Comma => self.bump(),
            Tok::End => {
                return Err(ExprError::UnclosedParenthesis {
                    column: open_column,
                });
            }
            _ => {
                return Err(ExprError::UnexpectedToken {
                    column: next.column,
                    found: describe(next),
                    expected: "',' between the two arguments",
                });
            }
        }
        let (b, hb) = self.sum(level)?;
        self.open -= 1;
        let next = self.peek();
        match next.tok {
            Tok::Close => {
                self.bump();
                Ok((a, b, ha.max(hb)))
            }
            Tok::End => Err(ExprError::UnclosedParenthesis {
                column: open_column,
            }),
            _ => Err(ExprError::UnexpectedToken {
                column: next.column,
                found: describe(next),
                expected: "')' or an operator",
            }),
        }
    }

    /// The inside of a parenthesis opened at `open_column` (already consumed) and its `)`.
    fn group(&mut self, level: usize, open_column: usize) -> Result<Parsed, ExprError> {
        let level = Self::limit(level + 1, open_column)?;
        self.open += 1;
        let inner = self.sum(level)?;
        self.open -= 1;
        let next = self.peek();
        match next.tok {
            Tok::Close => {
                self.bump();
                Ok(inner)
            }
            Tok::End => Err(ExprError::UnclosedParenthesis {
                column: open_column,
            }),
            _ => Err(ExprError::UnexpectedToken {
                column: next.column,
                found: describe(next),
                expected: "')' or an operator",
            }),
        }
    }
}

/// Parse `text` over `variables` (already checked) into a simplified tree.
pub(super) fn parse_tree(text: &str, variables: &[&str]) -> Result<Tree, ExprError> {
    let tokens = lex(text)?;
    let mut parser = Parser {
        tokens,
        pos: 0,
        variables,
        open: 0,
    };
    let (tree, _) = parser.sum(0)?;
    let next = parser.peek();
    match next.tok {
        Tok::End => Ok(tree),
        Tok::Close => Err(ExprError::UnmatchedParenthesis {
            column: next.column,
        }),
        _ => Err(ExprError::TrailingInput {
            column: next.column,
            found: describe(next),
        }),
    }
}
