//! What a program may use besides its own declarations: the host's capabilities (the commands it may `run`) and
//! the belief the engine keeps by itself. A leaf that both the checker and the program loader read.

use std::collections::BTreeSet;

use crate::syntax::{ArgType, Decl, DeclKind, Pos};

/// What the host lets programs do beyond speaking and publishing: the names of the commands it may `run`.
#[derive(Debug, Clone, Default)]
pub struct Capabilities {
    /// Whitelisted command names; the host maps each to a fixed command line.
    pub commands: BTreeSet<String>,
}

impl Capabilities {
    pub fn with_commands<I: IntoIterator<Item = S>, S: Into<String>>(commands: I) -> Self {
        Capabilities {
            commands: commands.into_iter().map(Into::into).collect(),
        }
    }
}

/// The belief the engine keeps by itself: the text of the last `say`, for "repeat that".
pub const SAID: &str = "said";

/// The implicit declaration of `said(text)`, added unless the program declares it itself.
pub(crate) fn said_decl() -> Decl {
    Decl {
        name: SAID.to_owned(),
        kind: DeclKind::Belief,
        args: vec![ArgType::Text],
        event: false,
        fresh: None,
        pos: Pos::default(),
    }
}
