#![warn(missing_docs)]
//! The foundation every hirad crate stands on: the error type, geometry helpers (boxes),
//! atomic output files, seeded random numbers, Morton codes, a `u64` hasher, the progress hook
//! and the `choice!` macro for command-line choices.

/// `parse` (case-insensitive) and `name` of a command-line choice, from one table of names;
/// the error lists the names ("unknown refinement oracle 'x' (bf or error)").
#[macro_export]
macro_rules! choice {
    ($t:ident, $what:literal, $($v:ident => $s:literal),+ $(,)?) => {
        impl $t {
            /// Parse the name given on the command line (any case).
            pub fn parse(s: &str) -> $crate::Result<$t> {
                match s.to_ascii_lowercase().as_str() {
                    $($s => Ok($t::$v),)+
                    _ => Err($crate::Error::Config(format!(
                        "unknown {} '{s}' ({})",
                        $what,
                        $crate::error::alternatives(&[$($s),+])
                    ))),
                }
            }

            /// Name as on the command line.
            pub fn name(self) -> &'static str {
                match self {
                    $($t::$v => $s,)+
                }
            }
        }
    };
}

pub mod error;
pub mod geom;
pub mod hash;
pub mod io;
pub mod morton;
pub mod progress;
pub mod rng;

pub use error::{Error, Result};

/// Version of the library, recorded in every experiment output.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
