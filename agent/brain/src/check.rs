//! Static checks of a parsed program: declarations, arities, variables bound before use, actions in their place,
//! commands on the host's whitelist, tools declared once and named by `chat`, no recursive procedures. Every error names the line and column.

use std::cell::RefCell;
use std::collections::{BTreeMap, BTreeSet};

use crate::capabilities::{Capabilities, SAID, said_decl};
use crate::clock;
use crate::error::Diagnostic;
use crate::expr::{FUNCTIONS, function_arity};
use crate::parser::Parsed;
use crate::syntax::{
    ActionExpr, CompareOp, Decl, DeclKind, Expr, Guard, Pos, Primitive, Procedure, Rule,
    TemplatePart, ToolDecl,
};
use crate::value::Value;

/// The parts of a program that passed the checks.
pub(crate) struct Checked {
    pub decls: BTreeMap<String, Decl>,
    pub procedures: Vec<Procedure>,
    pub main: usize,
    /// The pair-database keys the program reads with `db("key")`.
    pub db_keys: BTreeSet<String>,
    pub tools: Vec<ToolDecl>,
}

pub(crate) struct Checker<'a> {
    capabilities: &'a Capabilities,
    decls: BTreeMap<String, Decl>,
    /// The declared tools' services, with where each was declared.
    tools: BTreeMap<String, Pos>,
    procedures: BTreeMap<String, (usize, Pos)>,
    /// Filled while expressions are checked (hence a cell: the checks only read everything else).
    db_keys: RefCell<BTreeSet<String>>,
}

type Bound = BTreeSet<String>;

impl<'a> Checker<'a> {
    pub fn new(capabilities: &'a Capabilities) -> Self {
        Checker {
            capabilities,
            decls: BTreeMap::new(),
            tools: BTreeMap::new(),
            procedures: BTreeMap::new(),
            db_keys: RefCell::default(),
        }
    }

    pub fn check(mut self, parsed: Parsed) -> Result<Checked, Diagnostic> {
        for decl in parsed.decls {
            if let Some(first) = self.decls.get(&decl.name) {
                return Err(Diagnostic::new(
                    decl.pos,
                    format!(
                        "`{}` is already declared at line {}",
                        decl.name, first.pos.line
                    ),
                ));
            }
            self.decls.insert(decl.name.clone(), decl);
        }
        self.decls.entry(SAID.to_owned()).or_insert_with(said_decl);

        for tool in &parsed.tools {
            if let Some(first) = self.tools.insert(tool.service.clone(), tool.pos) {
                return Err(Diagnostic::new(
                    tool.pos,
                    format!(
                        "tool `{}` is already declared at line {}",
                        tool.service, first.line
                    ),
                ));
            }
        }

        for procedure in &parsed.procedures {
            if let Some((_, first)) = self.procedures.get(&procedure.name) {
                return Err(Diagnostic::new(
                    procedure.pos,
                    format!(
                        "procedure `{}` is already defined at line {}",
                        procedure.name, first.line
                    ),
                ));
            }
            self.procedures.insert(
                procedure.name.clone(),
                (procedure.params.len(), procedure.pos),
            );
        }
        let Some(main) = parsed.procedures.iter().position(|p| p.name == "main") else {
            return Err(Diagnostic::new(
                Pos { line: 1, col: 1 },
                "the program has no `procedure main { ... }`, where evaluation starts",
            ));
        };

        for procedure in &parsed.procedures {
            self.procedure(procedure)?;
        }
        no_recursion(&parsed.procedures)?;
        Ok(Checked {
            decls: self.decls,
            procedures: parsed.procedures,
            main,
            db_keys: self.db_keys.into_inner(),
            tools: parsed.tools,
        })
    }

    fn procedure(&self, procedure: &Procedure) -> Result<(), Diagnostic> {
        let mut params = Bound::new();
        for param in &procedure.params {
            if !params.insert(param.clone()) {
                return Err(Diagnostic::new(
                    procedure.pos,
                    format!("parameter `{param}` appears twice"),
                ));
            }
        }
        let mut labels: BTreeMap<&str, u32> = BTreeMap::new();
        for rule in &procedure.rules {
            if let Some(line) = labels.insert(&rule.label, rule.pos.line) {
                return Err(Diagnostic::new(
                    rule.pos,
                    format!(
                        "rule `{}` is already defined at line {line} in procedure `{}`",
                        rule.label, procedure.name
                    ),
                ));
            }
            self.rule(rule, params.clone())?;
        }
        Ok(())
    }

    fn rule(&self, rule: &Rule, mut bound: Bound) -> Result<(), Diagnostic> {
        self.guard(&rule.guard, &mut bound)?;
        let mut calls = 0;
        for action in &rule.durative {
            if let ActionExpr::Procedure { pos, .. } = action {
                calls += 1;
                if calls > 1 {
                    return Err(Diagnostic::new(
                        *pos,
                        "a rule can call at most one procedure",
                    ));
                }
            }
            self.action(action, &bound, true)?;
        }
        for action in &rule.discrete {
            self.action(action, &bound, false)?;
        }
        Ok(())
    }

    fn guard(&self, guard: &Guard, bound: &mut Bound) -> Result<(), Diagnostic> {
        match guard {
            Guard::True => Ok(()),
            Guard::Atom(atom) => {
                let decl = self.decl(&atom.name, atom.pos)?;
                if decl.args.len() != atom.args.len() {
                    return Err(Diagnostic::new(
                        atom.pos,
                        format!(
                            "`{}` takes {} argument(s) (declared at line {}), but {} are given here",
                            atom.name,
                            decl.args.len(),
                            decl.pos.line,
                            atom.args.len()
                        ),
                    ));
                }
                for arg in &atom.args {
                    match arg {
                        Expr::Var(name, _) => {
                            bound.insert(name.clone());
                        }
                        Expr::Wild(_) => {}
                        other => self.expr(other, bound)?,
                    }
                }
                Ok(())
            }
            Guard::Not(inner) => {
                // Negation as failure: nothing bound inside escapes.
                let mut inner_bound = bound.clone();
                self.guard(inner, &mut inner_bound)
            }
            Guard::And(parts) => parts.iter().try_for_each(|part| self.guard(part, bound)),
            Guard::Or(alternatives) => {
                let mut common: Option<Bound> = None;
                for alternative in alternatives {
                    let mut alternative_bound = bound.clone();
                    self.guard(alternative, &mut alternative_bound)?;
                    common = Some(match common {
                        None => alternative_bound,
                        Some(common) => common.intersection(&alternative_bound).cloned().collect(),
                    });
                }
                bound.extend(common.unwrap_or_default());
                Ok(())
            }
            Guard::Compare(left, op, right) => {
                if *op == CompareOp::Eq {
                    for (var, other) in [(left, right), (right, left)] {
                        if let Expr::Var(name, _) = var
                            && !bound.contains(name)
                        {
                            self.expr(other, bound)?;
                            bound.insert(name.clone());
                            return Ok(());
                        }
                    }
                }
                self.expr(left, bound)?;
                self.expr(right, bound)?;
                if *op == CompareOp::Like {
                    like_patterns(right)?;
                }
                Ok(())
            }
        }
    }

    fn decl(&self, name: &str, pos: Pos) -> Result<&Decl, Diagnostic> {
        self.decls.get(name).ok_or_else(|| {
            let hint = if function_arity(name).is_some() {
                format!(
                    "; `{name}(...)` is a function and must be compared, as in `{name}(...) > 0`"
                )
            } else {
                format!("; declare it with `percept {name}(...)` or `belief {name}(...)`")
            };
            Diagnostic::new(pos, format!("unknown predicate `{name}`{hint}"))
        })
    }

    /// Checks that an expression can be evaluated: its variables bound, its functions and fields known.
    fn expr(&self, expr: &Expr, bound: &Bound) -> Result<(), Diagnostic> {
        match expr {
            Expr::Var(name, pos) => {
                if bound.contains(name) {
                    Ok(())
                } else {
                    Err(Diagnostic::new(
                        *pos,
                        format!(
                            "variable `{name}` is used before it is bound; bind it earlier in the guard with a \
                             percept such as `heard({name})` or with `{name} = ...`"
                        ),
                    ))
                }
            }
            Expr::Wild(pos) => Err(Diagnostic::new(
                *pos,
                "`_` can only stand for a predicate argument",
            )),
            Expr::Lit(..) => Ok(()),
            Expr::Template(parts, _) => parts.iter().try_for_each(|part| match part {
                TemplatePart::Text(_) => Ok(()),
                TemplatePart::Hole(hole) => self.expr(hole, bound),
            }),
            Expr::Path(path, pos) => {
                let dotted = path.join(".");
                if clock::FIELDS.contains(&dotted.as_str()) {
                    Ok(())
                } else {
                    Err(Diagnostic::new(
                        *pos,
                        format!(
                            "unknown field `{dotted}`; known fields: {}",
                            clock::FIELDS.join(", ")
                        ),
                    ))
                }
            }
            Expr::Call(name, args, pos) => {
                let Some(arity) = function_arity(name) else {
                    let known: Vec<&str> = FUNCTIONS.iter().map(|(name, _)| *name).collect();
                    let hint = if self.decls.contains_key(name) {
                        " (it is a predicate: use it on its own in a guard, not inside an expression)".to_owned()
                    } else {
                        format!("; known functions: {}", known.join(", "))
                    };
                    return Err(Diagnostic::new(
                        *pos,
                        format!("unknown function `{name}`{hint}"),
                    ));
                };
                if args.len() != arity {
                    return Err(Diagnostic::new(
                        *pos,
                        format!(
                            "`{name}` takes {arity} argument(s), but {} are given",
                            args.len()
                        ),
                    ));
                }
                if name == "db" {
                    let Expr::Lit(Value::Text(key), _) = &args[0] else {
                        return Err(Diagnostic::new(
                            args[0].pos(),
                            "`db` takes the key as a plain string, such as `db(\"agent.mode\")`, so that the \
                             host knows which keys to keep up to date",
                        ));
                    };
                    self.db_keys.borrow_mut().insert(key.clone());
                }
                args.iter().try_for_each(|arg| self.expr(arg, bound))
            }
            Expr::List(items, _) => items.iter().try_for_each(|item| self.expr(item, bound)),
            Expr::Map(entries, _) => entries
                .iter()
                .try_for_each(|(_, value)| self.expr(value, bound)),
        }
    }

    fn action(&self, action: &ActionExpr, bound: &Bound, durative: bool) -> Result<(), Diagnostic> {
        match action {
            ActionExpr::Procedure { name, args, pos } => {
                let Some((arity, _)) = self.procedures.get(name) else {
                    return Err(Diagnostic::new(
                        *pos,
                        format!(
                            "unknown action or procedure `{name}`; actions are say, publish, call, run, set, \
                             cancel, remember, forget, chat, forget_conversation and recall"
                        ),
                    ));
                };
                if !durative {
                    return Err(Diagnostic::new(
                        *pos,
                        format!(
                            "procedure `{name}` can only be called after `~>`: it stays active with its rule"
                        ),
                    ));
                }
                if args.len() != *arity {
                    return Err(Diagnostic::new(
                        *pos,
                        format!(
                            "procedure `{name}` takes {arity} argument(s), but {} are given",
                            args.len()
                        ),
                    ));
                }
                args.iter().try_for_each(|arg| self.expr(arg, bound))
            }
            ActionExpr::Primitive {
                primitive,
                args,
                pos,
            } => {
                let primitive = *primitive;
                let (fewest, most) = primitive.arity();
                if !(fewest..=most).contains(&args.len()) {
                    let takes = if fewest == most {
                        fewest.to_string()
                    } else {
                        format!("{fewest} to {most}")
                    };
                    return Err(Diagnostic::new(
                        *pos,
                        format!(
                            "`{}` takes {takes} argument(s), but {} are given",
                            primitive.name(),
                            args.len()
                        ),
                    ));
                }
                if durative && primitive.discrete_only() {
                    return Err(Diagnostic::new(
                        *pos,
                        format!(
                            "`{}` happens once: put it after `++`, not after `~>`",
                            primitive.name()
                        ),
                    ));
                }
                match primitive {
                    Primitive::Run => self.command(&args[0]),
                    Primitive::Remember | Primitive::Forget => {
                        self.belief_update(primitive, &args[0], bound)
                    }
                    Primitive::Chat => {
                        self.expr(&args[0], bound)?;
                        args.get(1).map_or(Ok(()), |tool| self.tool(tool))
                    }
                    _ => args.iter().try_for_each(|arg| self.expr(arg, bound)),
                }
            }
        }
    }

    fn command(&self, arg: &Expr) -> Result<(), Diagnostic> {
        let Expr::Lit(Value::Text(name), pos) = arg else {
            return Err(Diagnostic::new(
                arg.pos(),
                "`run` takes the name of a whitelisted command as a plain string, such as `run(\"uptime\")`",
            ));
        };
        if self.capabilities.commands.contains(name) {
            return Ok(());
        }
        let known: Vec<&str> = self
            .capabilities
            .commands
            .iter()
            .map(String::as_str)
            .collect();
        let known = if known.is_empty() {
            "none".to_owned()
        } else {
            known.join(", ")
        };
        Err(Diagnostic::new(
            *pos,
            format!("command `{name}` is not on the host's whitelist (whitelisted: {known})"),
        ))
    }

    /// The tool `chat` forces the model to call must be a declared one: the host builds the model's grammar from
    /// its declaration.
    fn tool(&self, arg: &Expr) -> Result<(), Diagnostic> {
        let Expr::Lit(Value::Text(service), pos) = arg else {
            return Err(Diagnostic::new(
                arg.pos(),
                "`chat` takes the tool as a plain string naming a declared tool, such as \
                 `chat(T, \"Robot.command\")`",
            ));
        };
        if self.tools.contains_key(service) {
            return Ok(());
        }
        let known: Vec<&str> = self.tools.keys().map(String::as_str).collect();
        let known = if known.is_empty() {
            "none".to_owned()
        } else {
            known.join(", ")
        };
        Err(Diagnostic::new(
            *pos,
            format!(
                "tool `{service}` is not declared; declare it with `tool \"{service}\" \"what it does\" \
                 {{arg: [\"value\", ...]}}` (declared tools: {known})"
            ),
        ))
    }

    fn belief_update(
        &self,
        primitive: Primitive,
        arg: &Expr,
        bound: &Bound,
    ) -> Result<(), Diagnostic> {
        let (name, args, pos, bare) = match arg {
            Expr::Call(name, args, pos) => (name, args.as_slice(), *pos, false),
            Expr::Lit(Value::Text(name), pos) => (name, &[][..], *pos, true),
            other => {
                return Err(Diagnostic::new(
                    other.pos(),
                    format!(
                        "`{}` takes a fact such as `greeted` or `name(N)`",
                        primitive.name()
                    ),
                ));
            }
        };
        let decl = self.decl(name, pos)?;
        if primitive == Primitive::Remember && decl.kind != DeclKind::Belief {
            return Err(Diagnostic::new(
                pos,
                format!(
                    "`{name}` is a percept; only beliefs (declared with `belief`) can be remembered"
                ),
            ));
        }
        // `forget(name)` without arguments forgets every fact of the predicate.
        let forget_all = primitive == Primitive::Forget && bare;
        if !forget_all && decl.args.len() != args.len() {
            return Err(Diagnostic::new(
                pos,
                format!(
                    "`{name}` takes {} argument(s), but {} are given",
                    decl.args.len(),
                    args.len()
                ),
            ));
        }
        for arg in args {
            match arg {
                Expr::Wild(_) if primitive == Primitive::Forget => {}
                other => self.expr(other, bound)?,
            }
        }
        Ok(())
    }
}

/// The right side of `~` must be a phrase or a list of phrases, none of them empty.
fn like_patterns(right: &Expr) -> Result<(), Diagnostic> {
    let empty =
        |expr: &Expr| matches!(expr, Expr::Lit(Value::Text(text), _) if text.trim().is_empty());
    match right {
        Expr::List(items, pos) if items.is_empty() => {
            Err(Diagnostic::new(*pos, "empty list of phrases after `~`"))
        }
        Expr::List(items, _) => match items.iter().find(|item| empty(item)) {
            Some(item) => Err(Diagnostic::new(
                item.pos(),
                "empty phrase after `~` would match nothing",
            )),
            None => Ok(()),
        },
        other if empty(other) => Err(Diagnostic::new(
            other.pos(),
            "empty phrase after `~` would match nothing",
        )),
        _ => Ok(()),
    }
}

/// Rejects procedures that call themselves, directly or through others: a teleo-reactive hierarchy is a tree of
/// sub-goals, and a cycle would descend forever while its guards hold.
fn no_recursion(procedures: &[Procedure]) -> Result<(), Diagnostic> {
    let calls: BTreeMap<&str, Vec<(&str, Pos)>> = procedures
        .iter()
        .map(|procedure| {
            let callees = procedure
                .rules
                .iter()
                .flat_map(|rule| &rule.durative)
                .filter_map(|action| match action {
                    ActionExpr::Procedure { name, pos, .. } => Some((name.as_str(), *pos)),
                    ActionExpr::Primitive { .. } => None,
                })
                .collect();
            (procedure.name.as_str(), callees)
        })
        .collect();
    fn visit<'p>(
        name: &'p str,
        calls: &BTreeMap<&'p str, Vec<(&'p str, Pos)>>,
        path: &mut Vec<&'p str>,
        done: &mut BTreeSet<&'p str>,
    ) -> Result<(), Diagnostic> {
        if done.contains(name) {
            return Ok(());
        }
        path.push(name);
        for (callee, pos) in calls.get(name).into_iter().flatten() {
            if path.contains(callee) {
                return Err(Diagnostic::new(
                    *pos,
                    format!(
                        "procedure `{callee}` would call itself ({} -> {callee})",
                        path.join(" -> ")
                    ),
                ));
            }
            visit(callee, calls, path, done)?;
        }
        path.pop();
        done.insert(name);
        Ok(())
    }
    let mut done = BTreeSet::new();
    for procedure in procedures {
        visit(&procedure.name, &calls, &mut Vec::new(), &mut done)?;
    }
    Ok(())
}
