//! Teleo-reactive rule programs: grammar, parser, belief store and evaluator.
//!
//! A program (grammar in `docs/brain.md`) is an ordered list of `guard ~> durative ++ discrete` rules grouped in
//! procedures, in the spirit of Nilsson's teleo-reactive programs and Clark and Robinson's TeleoR. The host feeds
//! percepts into a [`Brain`] and calls [`Brain::step`] whenever one changes (or at [`Brain::next_wakeup`]); the
//! first rule whose guard holds is active, and the step returns the [`Effect`]s to perform (start or stop durative
//! actions, fire discrete ones) and a [`Trace`] of every change of the active rule. The engine performs no I/O and
//! never reads a clock: time comes in with each call, which keeps it deterministic and testable.

mod action;
mod capabilities;
mod check;
mod clock;
mod clock_it;
mod echo;
mod engine;
mod error;
mod expr;
mod language;
mod lexer;
mod parser;
pub mod phrase;
mod program;
mod solve;
mod store;
mod syntax;
mod trace;
mod value;

pub use action::{Action, Effect};
pub use clock::WallClock;
pub use echo::EchoFilter;
pub use engine::{Brain, Now, Step};
pub use error::{LoadError, PerceptError};
pub use expr::{NoPairDb, PairDb};
pub use language::{Language, UnknownLanguage};
pub use program::{Capabilities, Program, SAID};
pub use store::{BeliefStore, Fact};
pub use syntax::ToolDecl;
pub use trace::{Binding, Evidence, RuleRef, Trace};
pub use value::{Quoted, Value};
