//! The expression language of user-defined effects: a small arithmetic language compiled once into
//! a flat stack program and evaluated without allocation at every simulator sub-step.
//!
//! ```text
//! expr   := sum
//! sum    := prod (('+' | '-') prod)*
//! prod   := unary (('*' | '/') unary)*
//! unary  := ('-' | '+') unary | power
//! power  := atom ('^' unary)?                 (right-associative, binds tighter than unary minus)
//! atom   := number | name | name '(' expr (',' expr)* ')' | '(' expr ')'
//! ```
//!
//! Names are the signals (`theta_l theta_m omega_l omega_m i_a u t`), the effect's parameters,
//! the constant `pi`, and the functions `sin cos tan exp ln log10 sqrt abs sign tanh atan atan2
//! min max pow`. `-x^2` is `-(x^2)`, as in mathematics.
//!
//! # Why not a crate
//!
//! The maintained evaluators (exmex, evalexpr) report parse errors as a message without a
//! position, and the checks the model file needs (unknown signal, unknown parameter, syntax error
//! at a column) need the position of every token; evalexpr also evaluates through a hash-map
//! context and a dynamically typed value per node, too slow for a call at every 100 us sub-step;
//! fasteval and meval are unmaintained since 2020 and 2017. The language is small (five binary
//! operators and fourteen functions), so a hand-written recursive-descent parser with exact
//! columns, compiled to a flat program over a fixed-size stack, is shorter than the adapter
//! around any of them, and stays `no_std` + `alloc` like the simulator that runs it.

use crate::math;
#[cfg(feature = "alloc")]
use alloc::string::String;
#[cfg(feature = "alloc")]
use alloc::vec::Vec;
#[cfg(feature = "alloc")]
use core::fmt;

/// The signals an expression may read, in the order of the `signals` slice given to
/// [`Program::eval`].
pub const SIGNALS: [&str; 7] = ["theta_l", "theta_m", "omega_l", "omega_m", "i_a", "u", "t"];

/// Units of [`SIGNALS`], in the same order.
pub const SIGNAL_UNITS: [&str; 7] = ["rad", "rad", "rad/s", "rad/s", "A", "V", "s"];

/// Deepest evaluation stack (and nesting) accepted.
pub const MAX_STACK: usize = 64;

/// Longest expression accepted [bytes].
pub const MAX_LEN: usize = 4096;

/// One instruction of a compiled expression.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Op {
    Const(f64),
    /// Signal by index in [`SIGNALS`].
    Signal(u8),
    /// Parameter by index.
    Param(u8),
    Neg,
    Add,
    Sub,
    Mul,
    Div,
    Pow,
    Func1(Func1),
    Func2(Func2),
}

/// One-argument functions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Func1 {
    Sin,
    Cos,
    Tan,
    Exp,
    Ln,
    Log10,
    Sqrt,
    Abs,
    Sign,
    Tanh,
    Atan,
}

/// Two-argument functions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Func2 {
    Atan2,
    Min,
    Max,
    Pow,
}

#[cfg(feature = "alloc")]
const FUNC1: [(&str, Func1); 11] = [
    ("sin", Func1::Sin),
    ("cos", Func1::Cos),
    ("tan", Func1::Tan),
    ("exp", Func1::Exp),
    ("ln", Func1::Ln),
    ("log10", Func1::Log10),
    ("sqrt", Func1::Sqrt),
    ("abs", Func1::Abs),
    ("sign", Func1::Sign),
    ("tanh", Func1::Tanh),
    ("atan", Func1::Atan),
];
#[cfg(feature = "alloc")]
const FUNC2: [(&str, Func2); 4] = [
    ("atan2", Func2::Atan2),
    ("min", Func2::Min),
    ("max", Func2::Max),
    ("pow", Func2::Pow),
];

#[cfg(feature = "alloc")]
/// Why an expression was rejected. `column` counts characters from 1.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum ExprError {
    /// Not valid syntax at `column`: `what` says what was expected or found.
    Syntax { column: usize, what: String },
    /// A name that is neither a signal, a parameter, a function nor `pi`.
    UnknownName { column: usize, name: String },
    /// A function called with the wrong number of arguments.
    Arity {
        column: usize,
        name: String,
        expected: usize,
        got: usize,
    },
    /// A function name used without arguments, or a signal/parameter called like a function.
    NotAFunction { column: usize, name: String },
    /// Nested deeper than [`MAX_STACK`] or longer than [`MAX_LEN`].
    TooComplex { column: usize },
}

#[cfg(feature = "alloc")]
impl fmt::Display for ExprError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ExprError::Syntax { column, what } => write!(f, "syntax error at column {column}: {what}"),
            ExprError::UnknownName { column, name } => write!(
                f,
                "unknown name `{name}` at column {column}: not a signal ({}), a parameter of the effect, a function or `pi`",
                SIGNALS.join(" ")
            ),
            ExprError::Arity {
                column,
                name,
                expected,
                got,
            } => write!(
                f,
                "`{name}` at column {column} takes {expected} argument(s), got {got}"
            ),
            ExprError::NotAFunction { column, name } => write!(
                f,
                "`{name}` at column {column}: a function needs its arguments in parentheses, and only functions take them"
            ),
            ExprError::TooComplex { column } => write!(
                f,
                "expression too long or nested too deeply at column {column} (at most {MAX_LEN} characters and {MAX_STACK} levels)"
            ),
        }
    }
}

#[cfg(feature = "alloc")]
/// A compiled expression: a flat program for a stack machine.
#[derive(Debug, Clone, PartialEq)]
pub struct Program {
    ops: Vec<Op>,
    depth: usize,
}

#[cfg(feature = "alloc")]
#[derive(Debug, Clone, Copy, PartialEq)]
enum Tok<'a> {
    Num(f64),
    Name(&'a str),
    Op(u8),
    LParen,
    RParen,
    Comma,
    End,
}

#[cfg(feature = "alloc")]
struct Lexer<'a> {
    src: &'a str,
    pos: usize,
    /// Byte offset of the current token.
    start: usize,
    tok: Tok<'a>,
}

#[cfg(feature = "alloc")]
impl<'a> Lexer<'a> {
    fn column(&self, byte: usize) -> usize {
        self.src
            .get(..byte)
            .map_or(byte, |s| s.chars().count())
            .saturating_add(1)
    }

    fn err(&self, what: &str) -> ExprError {
        let found = match self.tok {
            Tok::End => String::from("the end of the expression"),
            _ => alloc::format!("`{}`", self.src.get(self.start..self.pos).unwrap_or("?")),
        };
        ExprError::Syntax {
            column: self.column(self.start),
            what: alloc::format!("expected {what}, found {found}"),
        }
    }

    fn next(&mut self) -> Result<(), ExprError> {
        let b = self.src.as_bytes();
        while self.pos < b.len() && b[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        self.start = self.pos;
        let Some(&c) = b.get(self.pos) else {
            self.tok = Tok::End;
            return Ok(());
        };
        if c.is_ascii_digit() || c == b'.' {
            let mut end = self.pos;
            while end < b.len() && (b[end].is_ascii_digit() || b[end] == b'.') {
                end += 1;
            }
            if end < b.len() && (b[end] == b'e' || b[end] == b'E') {
                let mut e = end + 1;
                if e < b.len() && (b[e] == b'+' || b[e] == b'-') {
                    e += 1;
                }
                if e < b.len() && b[e].is_ascii_digit() {
                    while e < b.len() && b[e].is_ascii_digit() {
                        e += 1;
                    }
                    end = e;
                }
            }
            let text = self.src.get(self.pos..end).unwrap_or("");
            let v: f64 = text.parse().map_err(|_| ExprError::Syntax {
                column: self.column(self.pos),
                what: alloc::format!("`{text}` is not a number"),
            })?;
            self.pos = end;
            self.tok = Tok::Num(v);
            return Ok(());
        }
        if c.is_ascii_alphabetic() || c == b'_' {
            let mut end = self.pos;
            while end < b.len() && (b[end].is_ascii_alphanumeric() || b[end] == b'_') {
                end += 1;
            }
            self.tok = Tok::Name(self.src.get(self.pos..end).unwrap_or(""));
            self.pos = end;
            return Ok(());
        }
        self.pos += 1;
        self.tok = match c {
            b'+' | b'-' | b'*' | b'/' | b'^' => Tok::Op(c),
            b'(' => Tok::LParen,
            b')' => Tok::RParen,
            b',' => Tok::Comma,
            _ => {
                // Report the whole (possibly multi-byte) character.
                let ch = self.src.get(self.start..).and_then(|s| s.chars().next());
                return Err(ExprError::Syntax {
                    column: self.column(self.start),
                    what: alloc::format!(
                        "unexpected character `{}`",
                        ch.unwrap_or(char::REPLACEMENT_CHARACTER)
                    ),
                });
            }
        };
        Ok(())
    }
}

#[cfg(feature = "alloc")]
struct Parser<'a, 'p> {
    lx: Lexer<'a>,
    params: &'p [&'p str],
    ops: Vec<Op>,
    nest: usize,
}

#[cfg(feature = "alloc")]
impl Parser<'_, '_> {
    fn enter(&mut self) -> Result<(), ExprError> {
        self.nest += 1;
        if self.nest > MAX_STACK {
            return Err(ExprError::TooComplex {
                column: self.lx.column(self.lx.start),
            });
        }
        Ok(())
    }

    fn sum(&mut self) -> Result<(), ExprError> {
        self.enter()?;
        self.prod()?;
        while let Tok::Op(c @ (b'+' | b'-')) = self.lx.tok {
            self.lx.next()?;
            self.prod()?;
            self.ops.push(if c == b'+' { Op::Add } else { Op::Sub });
        }
        self.nest -= 1;
        Ok(())
    }

    fn prod(&mut self) -> Result<(), ExprError> {
        self.unary()?;
        while let Tok::Op(c @ (b'*' | b'/')) = self.lx.tok {
            self.lx.next()?;
            self.unary()?;
            self.ops.push(if c == b'*' { Op::Mul } else { Op::Div });
        }
        Ok(())
    }

    fn unary(&mut self) -> Result<(), ExprError> {
        self.enter()?;
        match self.lx.tok {
            Tok::Op(b'-') => {
                self.lx.next()?;
                self.unary()?;
                self.ops.push(Op::Neg);
            }
            Tok::Op(b'+') => {
                self.lx.next()?;
                self.unary()?;
            }
            _ => {
                self.atom()?;
                if self.lx.tok == Tok::Op(b'^') {
                    self.lx.next()?;
                    self.unary()?;
                    self.ops.push(Op::Pow);
                }
            }
        }
        self.nest -= 1;
        Ok(())
    }

    fn atom(&mut self) -> Result<(), ExprError> {
        match self.lx.tok {
            Tok::Num(v) => {
                self.ops.push(Op::Const(v));
                self.lx.next()
            }
            Tok::LParen => {
                self.lx.next()?;
                self.sum()?;
                if self.lx.tok != Tok::RParen {
                    return Err(self.lx.err("`)`"));
                }
                self.lx.next()
            }
            Tok::Name(name) => {
                let column = self.lx.column(self.lx.start);
                self.lx.next()?;
                let f1 = FUNC1.iter().find(|(n, _)| *n == name).map(|(_, f)| *f);
                let f2 = FUNC2.iter().find(|(n, _)| *n == name).map(|(_, f)| *f);
                if self.lx.tok == Tok::LParen {
                    if f1.is_none() && f2.is_none() {
                        return Err(self.name_error(name, column, true));
                    }
                    self.lx.next()?;
                    let mut args = 0usize;
                    loop {
                        self.sum()?;
                        args += 1;
                        match self.lx.tok {
                            Tok::Comma => self.lx.next()?,
                            Tok::RParen => break,
                            _ => return Err(self.lx.err("`,` or `)`")),
                        }
                    }
                    self.lx.next()?;
                    let expected = if f1.is_some() { 1 } else { 2 };
                    if args != expected {
                        return Err(ExprError::Arity {
                            column,
                            name: String::from(name),
                            expected,
                            got: args,
                        });
                    }
                    self.ops.push(match (f1, f2) {
                        (Some(f), _) => Op::Func1(f),
                        (None, Some(f)) => Op::Func2(f),
                        (None, None) => return Err(self.name_error(name, column, true)),
                    });
                    return Ok(());
                }
                if f1.is_some() || f2.is_some() {
                    return Err(ExprError::NotAFunction {
                        column,
                        name: String::from(name),
                    });
                }
                if let Some(i) = SIGNALS.iter().position(|s| *s == name) {
                    self.ops.push(Op::Signal(i as u8));
                } else if let Some(i) = self.params.iter().position(|p| *p == name) {
                    self.ops.push(Op::Param(i as u8));
                } else if name == "pi" {
                    self.ops.push(Op::Const(core::f64::consts::PI));
                } else {
                    return Err(self.name_error(name, column, false));
                }
                Ok(())
            }
            _ => Err(self.lx.err("a number, a name or `(`")),
        }
    }

    fn name_error(&self, name: &str, column: usize, called: bool) -> ExprError {
        let known = SIGNALS.contains(&name) || self.params.contains(&name) || name == "pi";
        if called && known {
            ExprError::NotAFunction {
                column,
                name: String::from(name),
            }
        } else {
            ExprError::UnknownName {
                column,
                name: String::from(name),
            }
        }
    }
}

#[cfg(feature = "alloc")]
impl Program {
    /// Compiles `src` with the parameter names `params` (at most 255).
    pub fn compile(src: &str, params: &[&str]) -> Result<Program, ExprError> {
        if src.len() > MAX_LEN || params.len() > u8::MAX as usize {
            return Err(ExprError::TooComplex {
                column: MAX_LEN.min(src.len()) + 1,
            });
        }
        let mut p = Parser {
            lx: Lexer {
                src,
                pos: 0,
                start: 0,
                tok: Tok::End,
            },
            params,
            ops: Vec::new(),
            nest: 0,
        };
        p.lx.next()?;
        if p.lx.tok == Tok::End {
            return Err(ExprError::Syntax {
                column: 1,
                what: String::from("the expression is empty"),
            });
        }
        p.sum()?;
        if p.lx.tok != Tok::End {
            return Err(p.lx.err("an operator or the end of the expression"));
        }
        // Stack depth of the program.
        let (mut d, mut depth) = (0usize, 0usize);
        for op in &p.ops {
            match op {
                Op::Const(_) | Op::Signal(_) | Op::Param(_) => d += 1,
                Op::Neg | Op::Func1(_) => {}
                _ => d = d.saturating_sub(1),
            }
            depth = depth.max(d);
        }
        if depth > MAX_STACK {
            return Err(ExprError::TooComplex { column: 1 });
        }
        Ok(Program { ops: p.ops, depth })
    }

    /// The instructions.
    pub fn ops(&self) -> &[Op] {
        &self.ops
    }

    /// Does the program read signal `i` (index in [`SIGNALS`])?
    pub fn reads_signal(&self, i: usize) -> bool {
        self.ops.contains(&Op::Signal(i as u8))
    }

    /// Does the program read parameter `i`?
    pub fn reads_param(&self, i: usize) -> bool {
        self.ops.contains(&Op::Param(i as u8))
    }

    /// Evaluates with `signals` (in [`SIGNALS`] order) and parameter values `params`. Missing
    /// signals or parameters read as NaN. No allocation.
    #[inline]
    pub fn eval(&self, signals: &[f64; 7], params: &[f64]) -> f64 {
        eval_ops(&self.ops, signals, params)
    }
}

/// Evaluates a compiled program (see [`Program::eval`]); `ops` must come from
/// [`Program::compile`] (stack depth at most [`MAX_STACK`]); a malformed program gives NaN.
#[inline]
pub fn eval_ops(ops: &[Op], signals: &[f64; 7], params: &[f64]) -> f64 {
    let mut st = [0.0f64; MAX_STACK];
    let mut n = 0usize;
    for op in ops {
        match *op {
            Op::Const(_) | Op::Signal(_) | Op::Param(_) => {
                if n >= MAX_STACK {
                    return f64::NAN;
                }
                st[n] = match *op {
                    Op::Const(v) => v,
                    Op::Signal(i) => signals.get(i as usize).copied().unwrap_or(f64::NAN),
                    Op::Param(i) => params.get(i as usize).copied().unwrap_or(f64::NAN),
                    _ => f64::NAN,
                };
                n += 1;
            }
            Op::Neg | Op::Func1(_) => {
                if n == 0 {
                    return f64::NAN;
                }
                let x = st[n - 1];
                st[n - 1] = match *op {
                    Op::Neg => -x,
                    Op::Func1(f) => match f {
                        Func1::Sin => math::sin(x),
                        Func1::Cos => math::cos(x),
                        Func1::Tan => math::tan(x),
                        Func1::Exp => math::exp(x),
                        Func1::Ln => math::ln(x),
                        Func1::Log10 => math::log10(x),
                        Func1::Sqrt => math::sqrt(x),
                        Func1::Abs => x.abs(),
                        Func1::Sign => math::sign(x),
                        Func1::Tanh => math::tanh(x),
                        Func1::Atan => math::atan(x),
                    },
                    _ => x,
                };
            }
            _ => {
                if n < 2 {
                    return f64::NAN;
                }
                let (a, b) = (st[n - 2], st[n - 1]);
                n -= 1;
                st[n - 1] = match *op {
                    Op::Add => a + b,
                    Op::Sub => a - b,
                    Op::Mul => a * b,
                    Op::Div => a / b,
                    Op::Pow | Op::Func2(Func2::Pow) => pow(a, b),
                    Op::Func2(Func2::Atan2) => math::atan2(a, b),
                    Op::Func2(Func2::Min) => a.min(b),
                    Op::Func2(Func2::Max) => a.max(b),
                    _ => f64::NAN,
                };
            }
        }
    }
    if n == 1 {
        st[0]
    } else {
        f64::NAN
    }
}

/// x^y with small integer exponents multiplied out (exact and fast for x^2, x^3).
#[inline]
fn pow(x: f64, y: f64) -> f64 {
    if y == 2.0 {
        x * x
    } else if y == 3.0 {
        x * x * x
    } else if y == 1.0 {
        x
    } else {
        math::pow(x, y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ev(src: &str, params: &[&str], pv: &[f64]) -> f64 {
        let p = Program::compile(src, params).unwrap();
        p.eval(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0], pv)
    }

    #[test]
    fn evaluates_with_precedence() {
        assert_eq!(
            ev("k * (theta_l - theta0)", &["k", "theta0"], &[2.0, 0.5]),
            1.0
        );
        assert_eq!(ev("1 + 2 * 3 ^ 2", &[], &[]), 19.0);
        assert_eq!(ev("-2^2", &[], &[]), -4.0);
        assert_eq!(ev("2^-1", &[], &[]), 0.5);
        assert_eq!(ev("2^3^2", &[], &[]), 512.0);
        assert_eq!(ev("10 - 4 - 3", &[], &[]), 3.0);
        assert_eq!(ev("omega_l * abs(omega_l)", &[], &[]), 9.0);
        assert_eq!(ev("max(u, t) + min(1, 2e0) + sign(-3)", &[], &[]), 7.0);
        assert!((ev("sin(pi / 2) + cos(0)", &[], &[]) - 2.0).abs() < 1e-15);
        assert_eq!(ev("1.5e-3 * 2E3", &[], &[]), 3.0);
    }

    #[test]
    fn errors_carry_the_column() {
        let e = Program::compile("k * (theta_q - 1)", &["k"]).unwrap_err();
        assert_eq!(
            e,
            ExprError::UnknownName {
                column: 6,
                name: "theta_q".into()
            }
        );
        let e = Program::compile("k * (theta_l - 1", &["k"]).unwrap_err();
        assert!(matches!(e, ExprError::Syntax { column: 17, .. }), "{e}");
        let e = Program::compile("k ** theta_l", &["k"]).unwrap_err();
        assert!(matches!(e, ExprError::Syntax { column: 4, .. }), "{e}");
        let e = Program::compile("sin(u, t)", &[]).unwrap_err();
        assert!(matches!(e, ExprError::Arity { column: 1, .. }), "{e}");
        let e = Program::compile("sin + 1", &[]).unwrap_err();
        assert!(
            matches!(e, ExprError::NotAFunction { column: 1, .. }),
            "{e}"
        );
        let e = Program::compile("u # 2", &[]).unwrap_err();
        assert!(matches!(e, ExprError::Syntax { column: 3, .. }), "{e}");
        assert!(Program::compile("", &[]).is_err());
        let deep = "(".repeat(200) + "1" + &")".repeat(200);
        assert!(matches!(
            Program::compile(&deep, &[]),
            Err(ExprError::TooComplex { .. })
        ));
    }
}
