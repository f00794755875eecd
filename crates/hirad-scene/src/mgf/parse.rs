//! MGF text to statements: backslash continuation lines joined, words split at white space,
//! each statement with the line it starts on; [`At`] turns that line into error messages and
//! checks numbers and argument counts; [`match_xf`] pairs the `xf` blocks of a file.

use hirad_core::{Error, Result};
use std::path::Path;

/// One statement: 1-based line of its first physical line and its words.
pub(super) struct Stmt {
    pub(super) line: usize,
    pub(super) words: Vec<String>,
}

/// Split a file into statements (backslash continuations joined, blank lines dropped).
pub(super) fn statements(text: &str) -> Vec<Stmt> {
    let mut out = Vec::new();
    let mut pending: Option<(usize, String)> = None;
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim_end_matches('\r');
        let (cont, body) = match line.trim_end().strip_suffix('\\') {
            Some(b) => (true, b),
            None => (false, line),
        };
        let (start, mut acc) = pending.take().unwrap_or((i + 1, String::new()));
        acc.push(' ');
        acc.push_str(body);
        if cont {
            pending = Some((start, acc));
            continue;
        }
        push_statement(&mut out, start, &acc);
    }
    if let Some((start, acc)) = pending {
        push_statement(&mut out, start, &acc);
    }
    out
}

/// Append the statement of `text` (starting on line `line`) unless it is blank.
fn push_statement(out: &mut Vec<Stmt>, line: usize, text: &str) {
    let words: Vec<String> = text.split_whitespace().map(str::to_string).collect();
    if !words.is_empty() {
        out.push(Stmt { line, words });
    }
}

/// Where a statement is, for messages.
#[derive(Clone, Copy)]
pub(super) struct At<'a> {
    pub(super) file: &'a Path,
    pub(super) line: usize,
}

impl At<'_> {
    /// An input error at this file and line.
    pub(super) fn err(&self, msg: impl Into<String>) -> Error {
        Error::input_at(self.file, self.line, msg)
    }
    /// A finite number.
    pub(super) fn num(&self, s: &str) -> Result<f64> {
        match s.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(self.err(format!("bad number '{s}'"))),
        }
    }
    /// A count (integer >= 0).
    pub(super) fn int(&self, s: &str) -> Result<u64> {
        s.parse::<u64>()
            .map_err(|_| self.err(format!("bad count '{s}' (expected an integer >= 0)")))
    }
    /// An error naming the entity `w[0]` and its `usage` unless `ok`.
    pub(super) fn argc(&self, w: &[String], ok: bool, usage: &str) -> Result<()> {
        if ok {
            Ok(())
        } else {
            Err(self.err(format!(
                "'{}': wrong number of arguments (expected {usage})",
                w[0]
            )))
        }
    }
}

/// The kind of context an entity names, for messages.
pub(super) fn kind(entity: &str) -> &'static str {
    match entity {
        "c" => "colour",
        "m" => "material",
        _ => "vertex",
    }
}

/// For every opening `xf` (with arguments) the index of its matching bare `xf`; errors on
/// unbalanced blocks.
pub(super) fn match_xf(file: &Path, stmts: &[Stmt]) -> Result<Vec<usize>> {
    let mut close = vec![usize::MAX; stmts.len()];
    let mut open: Vec<usize> = Vec::new();
    for (i, s) in stmts.iter().enumerate() {
        if s.words[0] != "xf" {
            continue;
        }
        if s.words.len() > 1 {
            open.push(i);
        } else {
            match open.pop() {
                Some(o) => close[o] = i,
                None => {
                    return Err(Error::input_at(
                        file,
                        s.line,
                        "'xf' without a matching opening 'xf'",
                    ))
                }
            }
        }
    }
    if let Some(&o) = open.last() {
        return Err(Error::input_at(
            file,
            stmts[o].line,
            "'xf' block not closed by a bare 'xf' before the end of the file",
        ));
    }
    Ok(close)
}
