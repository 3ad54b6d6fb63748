//! Proves a guard against the belief store: a small backtracking search (as in Prolog) that returns the first
//! variable bindings that make the guard true, together with the facts that supported it.

use std::time::Instant;

use crate::clock::WallClock;
use crate::expr::{Env, PairDb, Scope, eval, lookup};
use crate::phrase::{Pattern, normalise};
use crate::program::Program;
use crate::store::{BeliefStore, Fact};
use crate::syntax::{AtomExpr, CompareOp, Expr, Guard, Temporal};
use crate::value::Value;

/// A proof of a guard: the bindings it made and the ids of the facts its positive atoms matched.
#[derive(Debug, Clone, Default)]
pub(crate) struct Proof {
    pub env: Env,
    pub support: Vec<u64>,
}

pub(crate) struct Solver<'a> {
    pub program: &'a Program,
    pub store: &'a BeliefStore,
    pub now: Instant,
    pub clock: &'a WallClock,
    pub db: &'a dyn PairDb,
}

impl Solver<'_> {
    /// The first proof of `guard` starting from `env` (a procedure's parameters), if the guard holds.
    pub fn prove(&self, guard: &Guard, env: Env) -> Option<Proof> {
        let mut proof = Proof {
            env,
            support: Vec::new(),
        };
        self.prove_goals(&[guard], &mut proof).then_some(proof)
    }

    /// Proves the goals left to right; on failure the proof is left as it was found.
    fn prove_goals(&self, goals: &[&Guard], proof: &mut Proof) -> bool {
        let Some((first, rest)) = goals.split_first() else {
            return true;
        };
        let mark = (proof.env.len(), proof.support.len());
        let undo = |proof: &mut Proof| {
            proof.env.truncate(mark.0);
            proof.support.truncate(mark.1);
        };
        match first {
            Guard::True => self.prove_goals(rest, proof),
            Guard::And(parts) => {
                let goals: Vec<&Guard> = parts.iter().chain(rest.iter().copied()).collect();
                self.prove_goals(&goals, proof)
            }
            Guard::Or(alternatives) => alternatives.iter().any(|alternative| {
                let goals: Vec<&Guard> = std::iter::once(alternative)
                    .chain(rest.iter().copied())
                    .collect();
                let proved = self.prove_goals(&goals, proof);
                if !proved {
                    undo(proof);
                }
                proved
            }),
            Guard::Not(inner) => {
                let holds = self.prove_goals(&[inner], proof);
                undo(proof);
                !holds && self.prove_goals(rest, proof)
            }
            Guard::Atom(atom) => {
                for fact in self.store.named(&atom.name) {
                    if !self.in_time(fact, atom) {
                        continue;
                    }
                    if self.unify(atom, fact, proof) {
                        proof.support.push(fact.id);
                        if self.prove_goals(rest, proof) {
                            return true;
                        }
                    }
                    undo(proof);
                }
                false
            }
            Guard::Compare(left, op, right) => {
                if self.compare(left, *op, right, proof) && self.prove_goals(rest, proof) {
                    return true;
                }
                undo(proof);
                false
            }
        }
    }

    fn in_time(&self, fact: &Fact, atom: &AtomExpr) -> bool {
        let fresh = self.program.fresh(&atom.name);
        match atom.temporal {
            None => fact.is_fresh(self.now, fresh),
            Some(Temporal::Within(window)) => {
                self.now.saturating_duration_since(fact.last_seen) <= window
            }
            Some(Temporal::For(hold)) => {
                fact.is_fresh(self.now, fresh) && fact.held(self.now, fresh) >= hold
            }
        }
    }

    fn unify(&self, atom: &AtomExpr, fact: &Fact, proof: &mut Proof) -> bool {
        if atom.args.len() != fact.args.len() {
            return false;
        }
        for (pattern, value) in atom.args.iter().zip(&fact.args) {
            match pattern {
                Expr::Wild(_) => {}
                Expr::Var(name, _) => match lookup(&proof.env, name) {
                    Some(bound) if bound != value => return false,
                    Some(_) => {}
                    None => proof.env.push((name.clone(), value.clone())),
                },
                other => {
                    if self.value(other, proof).as_ref() != Some(value) {
                        return false;
                    }
                }
            }
        }
        true
    }

    fn value(&self, expr: &Expr, proof: &Proof) -> Option<Value> {
        eval(
            expr,
            &Scope {
                env: &proof.env,
                clock: self.clock,
                db: self.db,
            },
        )
    }

    fn compare(&self, left: &Expr, op: CompareOp, right: &Expr, proof: &mut Proof) -> bool {
        if op == CompareOp::Eq {
            // `X = expr` binds X when it is still free (the checker guarantees the other side is evaluable).
            for (var, other) in [(left, right), (right, left)] {
                if let Expr::Var(name, _) = var
                    && lookup(&proof.env, name).is_none()
                {
                    let Some(value) = self.value(other, proof) else {
                        return false;
                    };
                    proof.env.push((name.clone(), value));
                    return true;
                }
            }
        }
        let (Some(a), Some(b)) = (self.value(left, proof), self.value(right, proof)) else {
            return false;
        };
        match op {
            CompareOp::Eq => a == b,
            CompareOp::Ne => a != b,
            CompareOp::Lt => a.compare(&b).is_some_and(|o| o.is_lt()),
            CompareOp::Le => a.compare(&b).is_some_and(|o| o.is_le()),
            CompareOp::Gt => a.compare(&b).is_some_and(|o| o.is_gt()),
            CompareOp::Ge => a.compare(&b).is_some_and(|o| o.is_ge()),
            CompareOp::Like => like(&a, &b),
        }
    }
}

/// `text ~ "phrase"` or `text ~ ["phrase", ...]`: any of the phrases occurs in the text (see `phrase`).
fn like(text: &Value, patterns: &Value) -> bool {
    let words = normalise(&text.to_string());
    let matches = |pattern: &Value| match pattern {
        Value::Text(pattern) => Pattern::new(pattern).matches_words(&words),
        _ => false,
    };
    match patterns {
        Value::List(items) => items.iter().any(matches),
        single => matches(single),
    }
}
