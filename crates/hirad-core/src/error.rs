//! Library error type. Every error that comes from input names the file (and line where known).

use std::path::PathBuf;

/// Errors returned by the library.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be read or written.
    /// (The OS error is part of the message and deliberately not a `#[source]`, so that
    /// `{:#}` chains do not print it twice.)
    #[error("{}: {err}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What the OS reported.
        err: std::io::Error,
    },
    /// Malformed or invalid input: names the file and, where there is one, the line.
    #[error("{}{}: {msg}", file.display(), line.map(|l| format!(":{l}")).unwrap_or_default())]
    Input {
        /// The file.
        file: PathBuf,
        /// Line number (1-based), where known.
        line: Option<usize>,
        /// What is wrong.
        msg: String,
    },
    /// Invalid configuration or arguments (unknown scene name, bad parameter value, ...).
    #[error("{0}")]
    Config(String),
    /// A resource budget (memory, links) cannot be met even after coarsening.
    #[error("{0}")]
    Budget(String),
    /// The run was interrupted (Ctrl-C) before it finished.
    #[error("interrupted")]
    Interrupted,
}

impl Error {
    /// Input error without a line number.
    pub fn input(file: impl Into<PathBuf>, msg: impl Into<String>) -> Self {
        Error::Input {
            file: file.into(),
            line: None,
            msg: msg.into(),
        }
    }

    /// Input error at a line (1-based).
    pub fn input_at(file: impl Into<PathBuf>, line: usize, msg: impl Into<String>) -> Self {
        Error::Input {
            file: file.into(),
            line: Some(line),
            msg: msg.into(),
        }
    }

    /// I/O error on a path.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            err: source,
        }
    }

    /// True for errors caused by the user's input files or arguments, a budget too small
    /// for the scene included (CLI exit code 2).
    pub fn is_input(&self) -> bool {
        matches!(
            self,
            Error::Io { .. } | Error::Input { .. } | Error::Config(_) | Error::Budget(_)
        )
    }
}

/// Result alias of the library.
pub type Result<T> = std::result::Result<T, Error>;

/// `a`, `a or b`, `a, b or c` (the choices of [`choice!`]-made `parse` errors).
#[doc(hidden)]
pub fn alternatives(names: &[&str]) -> String {
    match names.split_last() {
        Some((last, [])) => last.to_string(),
        Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
        None => String::new(),
    }
}
