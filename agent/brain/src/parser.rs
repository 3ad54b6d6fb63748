//! Reads program text into the syntax tree (recursive descent over the tokens; grammar in docs/brain.md).

use std::collections::BTreeMap;

use crate::error::Diagnostic;
use crate::lexer::{Tok, Token, tokenize};
use crate::syntax::{
    ActionExpr, ArgType, AtomExpr, CompareOp, Decl, DeclKind, Expr, Guard, Pos, Primitive,
    Procedure, Rule, TemplatePart, Temporal, ToolDecl,
};
use crate::value::Value;

/// The declarations and procedures of a program, in source order, before checking.
#[derive(Debug, Default)]
pub(crate) struct Parsed {
    pub decls: Vec<Decl>,
    pub procedures: Vec<Procedure>,
    pub tools: Vec<ToolDecl>,
}

pub(crate) fn parse(source: &str) -> Result<Parsed, Diagnostic> {
    let tokens = tokenize(source, Pos { line: 1, col: 1 })?;
    let mut parser = Parser { tokens, at: 0 };
    let mut parsed = Parsed::default();
    loop {
        let token = parser.peek().clone();
        match &token.tok {
            Tok::Eof => return Ok(parsed),
            Tok::Ident(word) if word == "percept" || word == "belief" => {
                let kind = if word == "percept" {
                    DeclKind::Percept
                } else {
                    DeclKind::Belief
                };
                parser.next();
                parser.declarations(kind, &mut parsed.decls)?;
            }
            Tok::Ident(word) if word == "tool" => {
                parser.next();
                parsed.tools.push(parser.tool(token.pos)?);
            }
            Tok::Ident(word) if word == "procedure" => {
                parser.next();
                parsed.procedures.push(parser.procedure(token.pos)?);
            }
            other => {
                return Err(Diagnostic::new(
                    token.pos,
                    format!(
                        "expected `percept`, `belief`, `tool` or `procedure`, found {}",
                        other.describe()
                    ),
                ));
            }
        }
    }
}

struct Parser {
    tokens: Vec<Token>,
    at: usize,
}

impl Parser {
    fn peek(&self) -> &Token {
        // The token list always ends with Eof, and `next` never moves past it.
        &self.tokens[self.at.min(self.tokens.len() - 1)]
    }

    fn peek_nth(&self, n: usize) -> &Tok {
        &self.tokens[(self.at + n).min(self.tokens.len() - 1)].tok
    }

    fn next(&mut self) -> Token {
        let token = self.peek().clone();
        if token.tok != Tok::Eof {
            self.at += 1;
        }
        token
    }

    fn eat(&mut self, tok: &Tok) -> bool {
        if &self.peek().tok == tok {
            self.next();
            true
        } else {
            false
        }
    }

    fn is_word(&self, word: &str) -> bool {
        matches!(&self.peek().tok, Tok::Ident(w) if w == word)
    }

    fn expect(&mut self, tok: &Tok, context: &str) -> Result<Pos, Diagnostic> {
        let token = self.peek().clone();
        if &token.tok == tok {
            self.next();
            Ok(token.pos)
        } else {
            Err(self.unexpected(&format!("{} {context}", tok.describe())))
        }
    }

    fn unexpected(&self, expected: &str) -> Diagnostic {
        let token = self.peek();
        Diagnostic::new(
            token.pos,
            format!("expected {expected}, found {}", token.tok.describe()),
        )
    }

    fn ident(&mut self, what: &str) -> Result<(String, Pos), Diagnostic> {
        let token = self.peek().clone();
        match token.tok {
            Tok::Ident(name) => {
                self.next();
                Ok((name, token.pos))
            }
            _ => Err(self.unexpected(what)),
        }
    }

    fn declarations(&mut self, kind: DeclKind, decls: &mut Vec<Decl>) -> Result<(), Diagnostic> {
        loop {
            let (name, pos) = self.ident("a predicate name")?;
            let mut args = Vec::new();
            if self.eat(&Tok::LParen) && !self.eat(&Tok::RParen) {
                loop {
                    let (type_name, type_pos) =
                        self.ident("an argument type (text, num, bool or any)")?;
                    args.push(match type_name.as_str() {
                        "text" | "dir" => ArgType::Text,
                        "num" => ArgType::Num,
                        "bool" => ArgType::Bool,
                        "any" => ArgType::Any,
                        other => {
                            return Err(Diagnostic::new(
                                type_pos,
                                format!(
                                    "unknown argument type `{other}` (use text, num, bool or any)"
                                ),
                            ));
                        }
                    });
                    if !self.eat(&Tok::Comma) {
                        self.expect(&Tok::RParen, "to close the argument types")?;
                        break;
                    }
                }
            }
            let mut decl = Decl {
                name,
                kind,
                args,
                event: false,
                fresh: None,
                pos,
            };
            loop {
                if self.is_word("event") {
                    self.next();
                    decl.event = true;
                } else if self.is_word("fresh") {
                    self.next();
                    let token = self.next();
                    match token.tok {
                        Tok::Duration(duration) => decl.fresh = Some(duration),
                        other => {
                            return Err(Diagnostic::new(
                                token.pos,
                                format!(
                                    "expected a duration such as `4s` after `fresh`, found {}",
                                    other.describe()
                                ),
                            ));
                        }
                    }
                } else {
                    break;
                }
            }
            decls.push(decl);
            if !self.eat(&Tok::Comma) {
                return Ok(());
            }
        }
    }

    fn string(&mut self, what: &str) -> Result<(String, Pos), Diagnostic> {
        let token = self.peek().clone();
        match token.tok {
            Tok::Str(text) => {
                self.next();
                Ok((text, token.pos))
            }
            _ => Err(self.unexpected(what)),
        }
    }

    /// `"Service.name" "what it does" { arg: ["value", ...], ... }`, after the `tool` keyword.
    fn tool(&mut self, pos: Pos) -> Result<ToolDecl, Diagnostic> {
        let (service, service_pos) =
            self.string("the tool's service as a string, such as \"Robot.command\"")?;
        if service.trim().is_empty() {
            return Err(Diagnostic::new(service_pos, "a tool needs a service name"));
        }
        let (description, _) = self.string("a description of what the tool does, as a string")?;
        self.expect(&Tok::LBrace, "to open the tool's arguments")?;
        let mut args: BTreeMap<String, Vec<String>> = BTreeMap::new();
        if !self.eat(&Tok::RBrace) {
            loop {
                let key_token = self.next();
                let arg = match key_token.tok {
                    Tok::Ident(arg) | Tok::Str(arg) => arg,
                    other => {
                        return Err(Diagnostic::new(
                            key_token.pos,
                            format!(
                                "expected an argument name of tool `{service}`, found {}",
                                other.describe()
                            ),
                        ));
                    }
                };
                if args.contains_key(&arg) {
                    return Err(Diagnostic::new(
                        key_token.pos,
                        format!("argument `{arg}` of tool `{service}` appears twice"),
                    ));
                }
                self.expect(&Tok::Colon, "after the argument name")?;
                let list_pos = self.expect(&Tok::LBracket, "to open the argument's values")?;
                let mut values = Vec::new();
                if !self.eat(&Tok::RBracket) {
                    loop {
                        values.push(self.string("a value as a string, such as \"left\"")?.0);
                        if !self.eat(&Tok::Comma) {
                            self.expect(&Tok::RBracket, "to close the values")?;
                            break;
                        }
                    }
                }
                if values.is_empty() {
                    // The model's answer is constrained to these values: none would leave it nothing to say.
                    return Err(Diagnostic::new(
                        list_pos,
                        format!(
                            "argument `{arg}` of tool `{service}` needs at least one value it may take"
                        ),
                    ));
                }
                args.insert(arg, values);
                if !self.eat(&Tok::Comma) {
                    self.expect(&Tok::RBrace, "to close the tool's arguments")?;
                    break;
                }
            }
        }
        Ok(ToolDecl {
            service,
            description,
            args,
            pos,
        })
    }

    fn procedure(&mut self, pos: Pos) -> Result<Procedure, Diagnostic> {
        let (name, _) = self.ident("a procedure name")?;
        let mut params = Vec::new();
        if self.eat(&Tok::LParen) && !self.eat(&Tok::RParen) {
            loop {
                let token = self.next();
                match token.tok {
                    Tok::Var(var) if var != "_" => params.push(var),
                    other => {
                        return Err(Diagnostic::new(
                            token.pos,
                            format!(
                                "expected a parameter variable such as `Text`, found {}",
                                other.describe()
                            ),
                        ));
                    }
                }
                if !self.eat(&Tok::Comma) {
                    self.expect(&Tok::RParen, "to close the parameters")?;
                    break;
                }
            }
        }
        self.expect(&Tok::LBrace, "to open the procedure's rules")?;
        let mut rules = Vec::new();
        while !self.eat(&Tok::RBrace) {
            if self.peek().tok == Tok::Eof {
                return Err(Diagnostic::new(
                    pos,
                    format!("procedure `{name}` is not closed with `}}`"),
                ));
            }
            rules.push(self.rule()?);
        }
        Ok(Procedure {
            name,
            params,
            rules,
            pos,
        })
    }

    fn rule(&mut self) -> Result<Rule, Diagnostic> {
        if !matches!(self.peek_nth(1), Tok::Colon) || !matches!(self.peek().tok, Tok::Ident(_)) {
            return Err(
                self.unexpected("a rule label such as `greet:` (or `}` to end the procedure)")
            );
        }
        let (label, pos) = self.ident("a rule label")?;
        self.next();
        let guard = self.guard()?;
        let mut durative = Vec::new();
        let mut discrete = Vec::new();
        let mut has_arrow = false;
        if self.eat(&Tok::Durative) {
            has_arrow = true;
            durative = self.actions()?;
        }
        if self.eat(&Tok::Discrete) {
            has_arrow = true;
            discrete = self.actions()?;
        }
        if !has_arrow {
            return Err(
                self.unexpected("`~>` (durative actions), `++` (discrete actions), `&` or `or`")
            );
        }
        Ok(Rule {
            label,
            guard,
            durative,
            discrete,
            pos,
        })
    }

    fn actions(&mut self) -> Result<Vec<ActionExpr>, Diagnostic> {
        if self.peek().tok == Tok::LParen && *self.peek_nth(1) == Tok::RParen {
            self.next();
            self.next();
            return Ok(Vec::new());
        }
        let mut actions = Vec::new();
        loop {
            let (name, pos) = self.ident("an action such as `say(...)`, or `()` for none")?;
            let args = if self.eat(&Tok::LParen) {
                self.arguments()?
            } else {
                Vec::new()
            };
            actions.push(match Primitive::from_name(&name) {
                Some(primitive) => ActionExpr::Primitive {
                    primitive,
                    args,
                    pos,
                },
                None => ActionExpr::Procedure { name, args, pos },
            });
            if !self.eat(&Tok::Comma) {
                return Ok(actions);
            }
        }
    }

    /// Arguments after an opening parenthesis, up to and including the closing one.
    fn arguments(&mut self) -> Result<Vec<Expr>, Diagnostic> {
        let mut args = Vec::new();
        if self.eat(&Tok::RParen) {
            return Ok(args);
        }
        loop {
            args.push(self.expr()?);
            if !self.eat(&Tok::Comma) {
                self.expect(&Tok::RParen, "to close the arguments")?;
                return Ok(args);
            }
        }
    }

    fn guard(&mut self) -> Result<Guard, Diagnostic> {
        let mut alternatives = vec![self.conjunction()?];
        while self.is_word("or") {
            self.next();
            alternatives.push(self.conjunction()?);
        }
        Ok(if alternatives.len() == 1 {
            alternatives.remove(0)
        } else {
            Guard::Or(alternatives)
        })
    }

    fn conjunction(&mut self) -> Result<Guard, Diagnostic> {
        let mut parts = vec![self.literal()?];
        while self.eat(&Tok::Amp) {
            parts.push(self.literal()?);
        }
        Ok(if parts.len() == 1 {
            parts.remove(0)
        } else {
            Guard::And(parts)
        })
    }

    fn literal(&mut self) -> Result<Guard, Diagnostic> {
        if self.is_word("not") {
            self.next();
            return Ok(Guard::Not(Box::new(self.literal()?)));
        }
        if self.eat(&Tok::LParen) {
            let inner = self.guard()?;
            self.expect(&Tok::RParen, "to close the parenthesised guard")?;
            return Ok(inner);
        }
        let token = self.peek().clone();
        if let Tok::Ident(name) = &token.tok {
            let is_literal_word = matches!(name.as_str(), "true" | "false");
            if !is_literal_word && *self.peek_nth(1) != Tok::Dot {
                // A predicate, unless a comparison operator follows, in which case it was a function call.
                self.next();
                let args = if self.eat(&Tok::LParen) {
                    self.arguments()?
                } else {
                    Vec::new()
                };
                if let Some(op) = self.compare_op() {
                    let left = Expr::Call(name.clone(), args, token.pos);
                    let right = self.expr()?;
                    return Ok(Guard::Compare(left, op, right));
                }
                let temporal = self.temporal()?;
                return Ok(Guard::Atom(AtomExpr {
                    name: name.clone(),
                    args,
                    temporal,
                    pos: token.pos,
                }));
            }
            if name == "true" && self.compare_op_at(1).is_none() {
                self.next();
                return Ok(Guard::True);
            }
        }
        let left = self.expr()?;
        let Some(op) = self.compare_op() else {
            return Err(self.unexpected("a comparison (`=`, `!=`, `<`, `<=`, `>`, `>=` or `~`)"));
        };
        let right = self.expr()?;
        Ok(Guard::Compare(left, op, right))
    }

    fn compare_op_at(&self, n: usize) -> Option<CompareOp> {
        Some(match self.peek_nth(n) {
            Tok::Eq => CompareOp::Eq,
            Tok::Ne => CompareOp::Ne,
            Tok::Lt => CompareOp::Lt,
            Tok::Le => CompareOp::Le,
            Tok::Gt => CompareOp::Gt,
            Tok::Ge => CompareOp::Ge,
            Tok::Tilde => CompareOp::Like,
            _ => return None,
        })
    }

    fn compare_op(&mut self) -> Option<CompareOp> {
        let op = self.compare_op_at(0)?;
        self.next();
        Some(op)
    }

    fn temporal(&mut self) -> Result<Option<Temporal>, Diagnostic> {
        let make: fn(std::time::Duration) -> Temporal = if self.is_word("within") {
            Temporal::Within
        } else if self.is_word("for") {
            Temporal::For
        } else {
            return Ok(None);
        };
        let keyword = self.next();
        let token = self.next();
        match token.tok {
            Tok::Duration(duration) => Ok(Some(make(duration))),
            other => Err(Diagnostic::new(
                token.pos,
                format!(
                    "expected a duration such as `10s` after {}, found {}",
                    keyword.tok.describe(),
                    other.describe()
                ),
            )),
        }
    }

    fn expr(&mut self) -> Result<Expr, Diagnostic> {
        let token = self.next();
        let pos = token.pos;
        Ok(match token.tok {
            Tok::Var(name) if name == "_" => Expr::Wild(pos),
            Tok::Var(name) => Expr::Var(name, pos),
            Tok::Num(n) => Expr::Lit(Value::Num(n), pos),
            Tok::Str(text) => template(&text, pos)?,
            Tok::LBracket => {
                let mut items = Vec::new();
                if !self.eat(&Tok::RBracket) {
                    loop {
                        items.push(self.expr()?);
                        if !self.eat(&Tok::Comma) {
                            self.expect(&Tok::RBracket, "to close the list")?;
                            break;
                        }
                    }
                }
                Expr::List(items, pos)
            }
            Tok::LBrace => {
                let mut entries = Vec::new();
                if !self.eat(&Tok::RBrace) {
                    loop {
                        let key_token = self.next();
                        let key = match key_token.tok {
                            Tok::Ident(key) | Tok::Str(key) => key,
                            other => {
                                return Err(Diagnostic::new(
                                    key_token.pos,
                                    format!(
                                        "expected a key (a name or a string), found {}",
                                        other.describe()
                                    ),
                                ));
                            }
                        };
                        self.expect(&Tok::Colon, "after the key")?;
                        entries.push((key, self.expr()?));
                        if !self.eat(&Tok::Comma) {
                            self.expect(&Tok::RBrace, "to close the object")?;
                            break;
                        }
                    }
                }
                Expr::Map(entries, pos)
            }
            Tok::Ident(name) if name == "true" => Expr::Lit(Value::Bool(true), pos),
            Tok::Ident(name) if name == "false" => Expr::Lit(Value::Bool(false), pos),
            Tok::Ident(name) => {
                if self.eat(&Tok::LParen) {
                    Expr::Call(name, self.arguments()?, pos)
                } else if self.peek().tok == Tok::Dot {
                    let mut path = vec![name];
                    while self.eat(&Tok::Dot) {
                        path.push(self.ident("a field name after `.`")?.0);
                    }
                    Expr::Path(path, pos)
                } else {
                    // A bare lower-case word is a symbol, as in TeleoR's `left | centre | right`.
                    Expr::Lit(Value::Text(name), pos)
                }
            }
            Tok::Duration(_) => {
                return Err(Diagnostic::new(
                    pos,
                    "a duration is only allowed after `fresh`, `within` or `for`",
                ));
            }
            other => {
                return Err(Diagnostic::new(
                    pos,
                    format!("expected a value or a variable, found {}", other.describe()),
                ));
            }
        })
    }
}

/// Parses a string literal into plain text or a template with `{expression}` holes (`{{` and `}}` escape braces).
fn template(text: &str, pos: Pos) -> Result<Expr, Diagnostic> {
    if !text.contains(['{', '}']) {
        return Ok(Expr::Lit(Value::Text(text.to_owned()), pos));
    }
    let chars: Vec<char> = text.chars().collect();
    // Hole positions assume no escapes before them; they are exact for ordinary templates.
    let at = |index: usize| Pos {
        line: pos.line,
        col: pos.col + 1 + index as u32,
    };
    let mut parts = Vec::new();
    let mut literal = String::new();
    let mut i = 0;
    while i < chars.len() {
        match (chars[i], chars.get(i + 1)) {
            ('{', Some('{')) | ('}', Some('}')) => {
                literal.push(chars[i]);
                i += 2;
            }
            ('{', _) => {
                let start = i + 1;
                let Some(len) = chars[start..].iter().position(|&c| c == '}') else {
                    return Err(Diagnostic::new(
                        at(i),
                        "this `{` has no closing `}` (write `{{` for a brace)",
                    ));
                };
                let hole: String = chars[start..start + len].iter().collect();
                if !literal.is_empty() {
                    parts.push(TemplatePart::Text(std::mem::take(&mut literal)));
                }
                let tokens = tokenize(&hole, at(start))?;
                let mut parser = Parser { tokens, at: 0 };
                if parser.peek().tok == Tok::Eof {
                    return Err(Diagnostic::new(at(i), "empty `{}` in a template"));
                }
                let expr = parser.expr()?;
                if parser.peek().tok != Tok::Eof {
                    return Err(parser.unexpected("`}` after the template expression"));
                }
                parts.push(TemplatePart::Hole(expr));
                i = start + len + 1;
            }
            ('}', _) => {
                return Err(Diagnostic::new(
                    at(i),
                    "unmatched `}` in a string (write `}}` for a brace)",
                ));
            }
            (c, _) => {
                literal.push(c);
                i += 1;
            }
        }
    }
    if !literal.is_empty() {
        parts.push(TemplatePart::Text(literal));
    }
    Ok(Expr::Template(parts, pos))
}
