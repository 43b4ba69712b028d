//! MATLAB paths into a MAT-file's variables, as users write them in `--columns`:
//! `thl_u_best.time`, `thl_u_best.signals(1).values(:,1)`, `ia_best.signals.values`,
//! `data{2}(:,3)`. Indices are 1-based, as in MATLAB; `end` names the last one.

use super::mat_read::{numel, MatFile, MatValue};
use std::fmt;

/// One index of `(...)` or `{...}`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Index {
    /// `:`
    All,
    /// A 1-based index.
    At(usize),
    /// `end`
    End,
}

/// One step of a path.
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    Field(String),
    Index(Vec<Index>),
}

/// A parsed path: a variable name and the steps into it.
#[derive(Debug, Clone, PartialEq)]
pub struct MatPath {
    pub variable: String,
    pub steps: Vec<Step>,
}

impl fmt::Display for MatPath {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.variable)?;
        for s in &self.steps {
            match s {
                Step::Field(n) => write!(f, ".{n}")?,
                Step::Index(ix) => {
                    let parts: Vec<String> = ix
                        .iter()
                        .map(|i| match i {
                            Index::All => ":".into(),
                            Index::At(k) => k.to_string(),
                            Index::End => "end".into(),
                        })
                        .collect();
                    write!(f, "({})", parts.join(","))?;
                }
            }
        }
        Ok(())
    }
}

fn is_ident_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

impl MatPath {
    /// Parses `var.field(2).values(:,1)`.
    pub fn parse(text: &str) -> Result<MatPath, String> {
        let t = text.trim();
        let bad = |why: &str| {
            format!("`{t}` is not a MATLAB path ({why}; example: `scope.signals(1).values(:,1)`)")
        };
        let ident_end = |s: &str| s.find(|c: char| !is_ident_char(c)).unwrap_or(s.len());
        let n = ident_end(t);
        if n == 0 || t.starts_with(|c: char| c.is_ascii_digit()) {
            return Err(bad("it must start with a variable name"));
        }
        let variable = t[..n].to_string();
        let mut rest = &t[n..];
        let mut steps = Vec::new();
        while let Some(c) = rest.chars().next() {
            match c {
                '.' => {
                    let r = &rest[1..];
                    let n = ident_end(r);
                    if n == 0 {
                        return Err(bad("a field name must follow `.`"));
                    }
                    steps.push(Step::Field(r[..n].to_string()));
                    rest = &r[n..];
                }
                '(' | '{' => {
                    let close = if c == '(' { ')' } else { '}' };
                    let end = rest
                        .find(close)
                        .ok_or_else(|| bad(&format!("`{c}` is not closed")))?;
                    let mut ix = Vec::new();
                    for part in rest[1..end].split(',') {
                        let p = part.trim();
                        ix.push(match p {
                            ":" => Index::All,
                            "end" => Index::End,
                            _ => match p.parse::<usize>() {
                                Ok(k) if k >= 1 => Index::At(k),
                                _ => {
                                    return Err(bad(&format!(
                                        "index `{p}` is not `:`, `end` or a whole number from 1 (indices are 1-based)"
                                    )))
                                }
                            },
                        });
                    }
                    if ix.len() > 2 {
                        return Err(bad("at most two indices"));
                    }
                    steps.push(Step::Index(ix));
                    rest = &rest[end + 1..];
                }
                _ => return Err(bad(&format!("unexpected `{c}`"))),
            }
        }
        Ok(MatPath { variable, steps })
    }
}

/// A vector taken from a MAT-file, with the time of its Simulink Scope structure, if any.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    pub values: Vec<f64>,
    /// The `time` field of the structure the path starts in (Scope "structure with time"), when
    /// it is a numeric vector.
    pub own_time: Option<(String, Vec<f64>)>,
    /// The label of the Scope signal (`signals(k).label`), if any.
    pub label: Option<String>,
}

/// Resolves an index list to a 0-based linear element of an array of `dims`.
fn linear(ix: &[Index], dims: &[usize], path: &str) -> Result<usize, String> {
    let n = numel(dims);
    let one = |i: Index, len: usize| -> Result<usize, String> {
        match i {
            Index::At(k) if k <= len => Ok(k - 1),
            Index::At(k) => Err(format!("`{path}`: index {k} exceeds the size {len}")),
            Index::End if len > 0 => Ok(len - 1),
            Index::All if len == 1 => Ok(0),
            _ => Err(format!("`{path}`: pick one element with a number, not `:`")),
        }
    };
    match ix {
        [] => one(Index::All, n),
        [i] => one(*i, n),
        [r, c] => {
            let rows = dims.first().copied().unwrap_or(0);
            let cols = n.checked_div(rows).unwrap_or(0);
            Ok(one(*c, cols)? * rows + one(*r, rows)?)
        }
        _ => Err(format!("`{path}`: at most two indices")),
    }
}

/// Follows `path` in `file` to a real numeric vector.
pub fn resolve(file: &MatFile, path: &MatPath) -> Result<Series, String> {
    let text = path.to_string();
    let names = || {
        file.variables
            .iter()
            .map(|v| v.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let root = file.get(&path.variable).ok_or_else(|| {
        format!(
            "`{text}`: no variable `{}`; the file holds {}",
            path.variable,
            names()
        )
    })?;
    let own_time = match root {
        MatValue::Struct(s) if s.len() == 1 => match s.field(0, "time") {
            Some(MatValue::Numeric(t)) if t.real.len() > 1 => {
                Some((format!("{}.time", path.variable), t.real.clone()))
            }
            _ => None,
        },
        _ => None,
    };
    let mut cur = root;
    let mut label = None;
    let mut done = path.variable.clone();
    let mut steps = path.steps.iter().peekable();
    while let Some(step) = steps.next() {
        match (step, cur) {
            (Step::Field(f), MatValue::Struct(s)) => {
                if s.len() != 1 {
                    return Err(format!(
                        "`{text}`: `{done}` is a {} struct array; pick an element first, e.g. `{done}(1).{f}`",
                        super::mat_read::dims_text(&s.dims)
                    ));
                }
                if let Some(l) = s.field(0, "label").and_then(MatValue::as_text) {
                    label = Some(l);
                }
                cur = s.field(0, f).ok_or_else(|| {
                    format!(
                        "`{text}`: `{done}` has no field `{f}`; its fields are {}",
                        s.fields.join(", ")
                    )
                })?;
                done.push('.');
                done.push_str(f);
            }
            (Step::Index(ix), MatValue::Struct(s)) => {
                let e = linear(ix, &s.dims, &text)?;
                // Show element e as a 1x1 struct for the next step.
                if let Some(Step::Field(f)) = steps.peek() {
                    if let Some(l) = s.field(e, "label").and_then(MatValue::as_text) {
                        label = Some(l);
                    }
                    cur = s.field(e, f).ok_or_else(|| {
                        format!(
                            "`{text}`: `{done}` has no field `{f}`; its fields are {}",
                            s.fields.join(", ")
                        )
                    })?;
                    done = format!("{done}({}).{f}", e + 1);
                    steps.next();
                } else {
                    return Err(format!(
                        "`{text}`: `{done}({})` is a struct; name one of its fields: {}",
                        e + 1,
                        s.fields.join(", ")
                    ));
                }
            }
            (Step::Index(ix), MatValue::Cell { dims, items }) => {
                let e = linear(ix, dims, &text)?;
                cur = items
                    .get(e)
                    .ok_or_else(|| format!("`{text}`: cell index out of range"))?;
                done = format!("{done}{{{}}}", e + 1);
            }
            (Step::Index(ix), MatValue::Numeric(a)) => {
                if steps.peek().is_some() {
                    return Err(format!(
                        "`{text}`: nothing can follow an index into numbers"
                    ));
                }
                let rows = a.dims.first().copied().unwrap_or(0);
                let cols = numel(&a.dims).checked_div(rows).unwrap_or(0);
                let pick = |i: Index, len: usize, what: &str| -> Result<Vec<usize>, String> {
                    match i {
                        Index::All => Ok((0..len).collect()),
                        Index::At(k) if k <= len => Ok(vec![k - 1]),
                        Index::End if len > 0 => Ok(vec![len - 1]),
                        Index::At(k) => Err(format!(
                            "`{text}`: {what} {k} exceeds the size of `{done}` ({rows}x{cols})"
                        )),
                        Index::End => Err(format!("`{text}`: `{done}` is empty")),
                    }
                };
                let values: Vec<f64> = match ix.as_slice() {
                    [Index::All] => a.real.clone(),
                    [i] => pick(*i, a.real.len(), "index")?
                        .into_iter()
                        .map(|k| a.real[k])
                        .collect(),
                    [r, c] => {
                        let (rs, cs) = (pick(*r, rows, "row")?, pick(*c, cols, "column")?);
                        if rs.len() > 1 && cs.len() > 1 {
                            return Err(format!(
                                "`{text}` selects a {}x{} matrix; select one column, e.g. `{done}(:,1)`",
                                rs.len(),
                                cs.len()
                            ));
                        }
                        cs.iter()
                            .flat_map(|&c| rs.iter().map(move |&r| c * rows + r))
                            .filter_map(|k| a.real.get(k).copied())
                            .collect()
                    }
                    _ => return Err(format!("`{text}`: empty index `()`")),
                };
                return Ok(Series {
                    values,
                    own_time,
                    label,
                });
            }
            (step, v) => {
                let what = match step {
                    Step::Field(f) => format!("field `.{f}`"),
                    Step::Index(_) => "an index".into(),
                };
                return Err(format!(
                    "`{text}`: `{done}` is a {} {}, which has no {what}",
                    super::mat_read::dims_text(v.dims()),
                    v.class()
                ));
            }
        }
    }
    match cur {
        MatValue::Numeric(a) => {
            let rows = a.dims.first().copied().unwrap_or(0);
            let cols = numel(&a.dims).checked_div(rows).unwrap_or(0);
            if rows > 1 && cols > 1 {
                return Err(format!(
                    "`{text}` is a {rows}x{cols} matrix; select one column, e.g. `{text}(:,1)` .. `{text}(:,{cols})`"
                ));
            }
            Ok(Series {
                values: a.real.clone(),
                own_time,
                label,
            })
        }
        v => Err(format!(
            "`{text}` is a {} {}, not numbers{}",
            super::mat_read::dims_text(v.dims()),
            v.class(),
            match v {
                MatValue::Struct(s) => format!("; its fields are {}", s.fields.join(", ")),
                _ => String::new(),
            }
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_prints() {
        for t in [
            "thl_u_best.time",
            "thl_u_best.signals(1).values(:,1)",
            "a.b(end).c(2,:)",
            "x",
        ] {
            assert_eq!(MatPath::parse(t).unwrap().to_string(), t);
        }
        assert_eq!(
            MatPath::parse("c{2}").unwrap().steps,
            vec![Step::Index(vec![Index::At(2)])]
        );
        for (bad, needle) in [
            ("a.signals(0)", "1-based"),
            ("a.(1)", "field name"),
            ("a(1", "not closed"),
            ("1a", "variable name"),
            ("a b", "unexpected"),
        ] {
            let e = MatPath::parse(bad).unwrap_err();
            assert!(e.contains(needle), "{bad}: {e}");
        }
    }
}
