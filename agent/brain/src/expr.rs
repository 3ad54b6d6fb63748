//! Evaluation of expressions (variables, literals, templates, clock fields, built-in functions) against variable
//! bindings, the wall clock and the pair database.

use std::collections::BTreeMap;

use crate::clock::WallClock;
use crate::phrase;
use crate::syntax::{Expr, TemplatePart};
use crate::value::Value;

/// Read access to the hub's pair database (`db("key")` in programs); the host keeps the values it needs at hand.
pub trait PairDb {
    fn lookup(&self, key: &str) -> Option<Value>;
}

/// No pair database: every key is missing.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoPairDb;

impl PairDb for NoPairDb {
    fn lookup(&self, _key: &str) -> Option<Value> {
        None
    }
}

impl PairDb for BTreeMap<String, Value> {
    fn lookup(&self, key: &str) -> Option<Value> {
        self.get(key).cloned()
    }
}

/// Built-in functions and how many arguments each takes.
pub(crate) const FUNCTIONS: [(&str, usize); 6] = [
    ("plural", 3),
    ("words", 1),
    ("after", 2),
    ("lower", 1),
    ("upper", 1),
    ("db", 1),
];

pub(crate) fn function_arity(name: &str) -> Option<usize> {
    FUNCTIONS
        .iter()
        .find(|(known, _)| *known == name)
        .map(|(_, arity)| *arity)
}

/// Variable bindings, innermost last; small enough that a vector beats a map.
pub(crate) type Env = Vec<(String, Value)>;

pub(crate) fn lookup<'a>(env: &'a Env, name: &str) -> Option<&'a Value> {
    env.iter()
        .rev()
        .find(|(bound, _)| bound == name)
        .map(|(_, value)| value)
}

/// What an expression is evaluated against.
pub(crate) struct Scope<'a> {
    pub env: &'a Env,
    pub clock: &'a WallClock,
    pub db: &'a dyn PairDb,
}

/// Evaluates an expression; `None` when it has no value (a missing pair-database key, `_`), which makes a
/// comparison false and renders as nothing in a template.
pub(crate) fn eval(expr: &Expr, scope: &Scope<'_>) -> Option<Value> {
    match expr {
        Expr::Var(name, _) => lookup(scope.env, name).cloned(),
        Expr::Wild(_) => None,
        Expr::Lit(value, _) => Some(value.clone()),
        Expr::Template(parts, _) => {
            let mut text = String::new();
            for part in parts {
                match part {
                    TemplatePart::Text(literal) => text.push_str(literal),
                    TemplatePart::Hole(hole) => {
                        if let Some(value) = eval(hole, scope) {
                            text.push_str(&value.to_string());
                        }
                    }
                }
            }
            Some(Value::Text(text))
        }
        Expr::Path(path, _) => scope.clock.field(path),
        Expr::List(items, _) => items
            .iter()
            .map(|item| eval(item, scope))
            .collect::<Option<Vec<_>>>()
            .map(Value::List),
        Expr::Map(entries, _) => entries
            .iter()
            .map(|(key, value)| eval(value, scope).map(|value| (key.clone(), value)))
            .collect::<Option<Vec<_>>>()
            .map(Value::Map),
        Expr::Call(name, args, _) => {
            let args: Vec<Value> = args
                .iter()
                .map(|arg| eval(arg, scope))
                .collect::<Option<_>>()?;
            call(name, &args, scope.db)
        }
    }
}

fn call(name: &str, args: &[Value], db: &dyn PairDb) -> Option<Value> {
    match (name, args) {
        ("plural", [count, one, many]) => {
            let n = count.as_num()?;
            let noun = if n == 1.0 { one } else { many };
            Some(Value::Text(format!("{count} {noun}")))
        }
        ("words", [text]) => Some(Value::Num(phrase::normalise(&text.to_string()).len() as f64)),
        ("after", [text, phrase]) => {
            phrase::after(&text.to_string(), &phrase.to_string()).map(Value::Text)
        }
        ("lower", [text]) => Some(Value::Text(text.to_string().to_lowercase())),
        ("upper", [text]) => Some(Value::Text(text.to_string().to_uppercase())),
        ("db", [key]) => db.lookup(&key.to_string()),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::syntax::Pos;

    fn lit(value: Value) -> Expr {
        Expr::Lit(value, Pos::default())
    }

    #[test]
    fn builtins() {
        let clock = WallClock::from_unix_ms(0, 0);
        let mut db = BTreeMap::new();
        db.insert("door".to_owned(), Value::from("open"));
        let env: Env = vec![("N".into(), Value::Num(2.0))];
        let scope = Scope {
            env: &env,
            clock: &clock,
            db: &db,
        };
        let plural = Expr::Call(
            "plural".into(),
            vec![
                Expr::Var("N".into(), Pos::default()),
                lit("person".into()),
                lit("people".into()),
            ],
            Pos::default(),
        );
        assert_eq!(eval(&plural, &scope), Some(Value::from("2 people")));
        let door = Expr::Call("db".into(), vec![lit("door".into())], Pos::default());
        assert_eq!(eval(&door, &scope), Some(Value::from("open")));
        let missing = Expr::Call("db".into(), vec![lit("window".into())], Pos::default());
        assert_eq!(eval(&missing, &scope), None);
        let words = Expr::Call(
            "words".into(),
            vec![lit("[BLANK_AUDIO]".into())],
            Pos::default(),
        );
        assert_eq!(eval(&words, &scope), Some(Value::Num(0.0)));
        let after = |text: &str| {
            eval(
                &Expr::Call(
                    "after".into(),
                    vec![lit(text.into()), lit("my name is".into())],
                    Pos::default(),
                ),
                &scope,
            )
        };
        assert_eq!(after("Hi, my name is Anna."), Some(Value::from("anna")));
        assert_eq!(after("My name is"), None);
        assert_eq!(after("What is your name?"), None);
    }
}
