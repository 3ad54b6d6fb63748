//! A loaded program: parsed, checked against its declarations and the host's capabilities, and indexed for the
//! evaluator (which `within`/`for` windows each predicate uses, whether guards read the clock).

use std::collections::{BTreeMap, BTreeSet};
use std::time::Duration;

use crate::check::Checker;
use crate::error::LoadError;
use crate::parser::parse;
use crate::syntax::{
    ActionExpr, Decl, Expr, Guard, Primitive, Procedure, TemplatePart, Temporal, ToolDecl,
};
use crate::value::Value;

pub use crate::capabilities::{Capabilities, SAID};

/// A checked program, ready to run.
#[derive(Debug, Clone)]
pub struct Program {
    pub(crate) origin: String,
    pub(crate) decls: BTreeMap<String, Decl>,
    pub(crate) procedures: Vec<Procedure>,
    pub(crate) main: usize,
    /// Per predicate, the `within` windows and `for` durations guards use, for wake-up times and pruning.
    pub(crate) windows: BTreeMap<String, Vec<Duration>>,
    pub(crate) holds: BTreeMap<String, Vec<Duration>>,
    /// Whether any guard reads `time.*` or `date.*`, which then needs a re-evaluation each minute.
    pub(crate) reads_clock: bool,
    db_keys: BTreeSet<String>,
    tools: Vec<ToolDecl>,
}

impl Program {
    /// Parses and checks `source`; `origin` (usually the file name) labels error messages.
    pub fn load(
        origin: &str,
        source: &str,
        capabilities: &Capabilities,
    ) -> Result<Program, LoadError> {
        let parsed = parse(source).map_err(|d| LoadError::locate(origin, source, d))?;
        let checked = Checker::new(capabilities)
            .check(parsed)
            .map_err(|d| LoadError::locate(origin, source, d))?;
        let mut program = Program {
            origin: origin.to_owned(),
            decls: checked.decls,
            procedures: checked.procedures,
            main: checked.main,
            windows: BTreeMap::new(),
            holds: BTreeMap::new(),
            reads_clock: false,
            db_keys: checked.db_keys,
            tools: checked.tools,
        };
        program.index();
        Ok(program)
    }

    /// Where the program came from, as given to `load`.
    pub fn origin(&self) -> &str {
        &self.origin
    }

    /// The declaration of a predicate (including the implicit `said(text)` belief).
    pub fn decl(&self, name: &str) -> Option<&Decl> {
        self.decls.get(name)
    }

    /// The pair-database keys the program reads (`db("key")`), which the host keeps up to date.
    pub fn db_keys(&self) -> impl Iterator<Item = &str> {
        self.db_keys.iter().map(String::as_str)
    }

    /// The services the language model may call (`tool` declarations), in source order.
    pub fn tools(&self) -> &[ToolDecl] {
        &self.tools
    }

    /// What the program says word for word (`say("...")` without holes), each text once in source order: the replies
    /// a voice with a cache can synthesise before they are first asked for (docs/voice.md, "The cache").
    pub fn fixed_sayings(&self) -> Vec<String> {
        let mut sayings: Vec<String> = Vec::new();
        let actions = self
            .procedures
            .iter()
            .flat_map(|p| &p.rules)
            .flat_map(|r| r.durative.iter().chain(&r.discrete));
        for action in actions {
            let ActionExpr::Primitive {
                primitive: Primitive::Say,
                args,
                ..
            } = action
            else {
                continue;
            };
            let text = match args.first() {
                Some(Expr::Lit(Value::Text(text), _)) => Some(text.clone()),
                Some(Expr::Template(parts, _)) => parts
                    .iter()
                    .map(|part| match part {
                        TemplatePart::Text(text) => Some(text.as_str()),
                        TemplatePart::Hole(_) => None,
                    })
                    .collect::<Option<String>>(),
                _ => None,
            };
            if let Some(text) = text.filter(|t| !t.trim().is_empty())
                && !sayings.contains(&text)
            {
                sayings.push(text);
            }
        }
        sayings
    }

    /// How many rules the program has, over all procedures.
    pub fn rule_count(&self) -> usize {
        self.procedures.iter().map(|p| p.rules.len()).sum()
    }

    pub(crate) fn fresh(&self, name: &str) -> Option<Duration> {
        self.decls.get(name).and_then(|decl| decl.fresh)
    }

    /// The longest `within` window used on a predicate: how long a stale fact must be kept.
    pub(crate) fn history(&self, name: &str) -> Duration {
        self.windows
            .get(name)
            .and_then(|w| w.iter().max().copied())
            .unwrap_or_default()
    }

    fn index(&mut self) {
        let mut windows: BTreeMap<String, Vec<Duration>> = BTreeMap::new();
        let mut holds: BTreeMap<String, Vec<Duration>> = BTreeMap::new();
        let mut reads_clock = false;
        for procedure in &self.procedures {
            for rule in &procedure.rules {
                visit_guard(&rule.guard, &mut |guard| match guard {
                    Guard::Atom(atom) => match atom.temporal {
                        Some(Temporal::Within(d)) => {
                            windows.entry(atom.name.clone()).or_default().push(d)
                        }
                        Some(Temporal::For(d)) => {
                            holds.entry(atom.name.clone()).or_default().push(d)
                        }
                        None => {}
                    },
                    Guard::Compare(left, _, right) => {
                        reads_clock |= reads_path(left) || reads_path(right)
                    }
                    _ => {}
                });
            }
        }
        self.windows = windows;
        self.holds = holds;
        self.reads_clock = reads_clock;
    }
}

fn visit_guard(guard: &Guard, visit: &mut dyn FnMut(&Guard)) {
    visit(guard);
    match guard {
        Guard::Not(inner) => visit_guard(inner, visit),
        Guard::And(parts) | Guard::Or(parts) => {
            parts.iter().for_each(|part| visit_guard(part, visit))
        }
        Guard::True | Guard::Atom(_) | Guard::Compare(..) => {}
    }
}

fn reads_path(expr: &Expr) -> bool {
    match expr {
        Expr::Path(..) => true,
        Expr::Call(_, args, _) | Expr::List(args, _) => args.iter().any(reads_path),
        Expr::Map(entries, _) => entries.iter().any(|(_, value)| reads_path(value)),
        Expr::Template(parts, _) => parts.iter().any(|part| match part {
            crate::syntax::TemplatePart::Hole(hole) => reads_path(hole),
            crate::syntax::TemplatePart::Text(_) => false,
        }),
        Expr::Var(..) | Expr::Wild(_) | Expr::Lit(..) => false,
    }
}
