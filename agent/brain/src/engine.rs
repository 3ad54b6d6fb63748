//! The teleo-reactive evaluator: finds the active rule path, diffs it against the previous one, and turns the
//! difference into effects (start/stop durative actions, fire discrete ones) and trace entries.

use std::time::{Duration, Instant};

use crate::action::{Action, Effect};
use crate::clock::WallClock;
use crate::error::PerceptError;
use crate::expr::{Env, PairDb, Scope, eval};
use crate::program::{Program, SAID};
use crate::solve::{Proof, Solver};
use crate::store::BeliefStore;
use crate::syntax::{ActionExpr, DeclKind, Expr, Primitive};
use crate::trace::{Binding, Evidence, RuleRef, Trace};
use crate::value::{Quoted, Value};

/// Belief updates can change which rule is active, which can update beliefs again; a program that never settles
/// is cut off after this many rounds in one step (and the step says so).
const MAX_ROUNDS: usize = 8;

/// The moment a step happens: a monotonic instant for freshness, and the wall clock for `time.*` fields.
#[derive(Debug, Clone, Copy)]
pub struct Now {
    pub at: Instant,
    pub clock: WallClock,
}

/// What one evaluation step asks of the host.
#[derive(Debug, Default, Clone)]
pub struct Step {
    /// Effects in the order to perform them: stops, then starts, then discrete actions.
    pub effects: Vec<Effect>,
    /// One entry per change of the active rule path.
    pub traces: Vec<Trace>,
    /// Problems found while running (an action whose argument had no value, a program that never settles).
    pub warnings: Vec<String>,
}

/// One level of the active path: which rule of which procedure, and which event occurrences it was entered for.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Level {
    procedure: String,
    rule: String,
    line: u32,
    events: Vec<u64>,
}

/// A rule chosen during evaluation, with the proof of its guard.
struct Chosen {
    procedure: usize,
    rule: usize,
    proof: Proof,
}

/// What an action expression becomes once instantiated.
enum Deed {
    Act(Action),
    Remember(String, Vec<Value>),
    Forget(String, Option<Vec<Option<Value>>>),
}

/// A running teleo-reactive program: the program, its belief store and the active rule path. A clone is a trial
/// run: what the program would do on a percept, without doing it (the server's preemptive replies).
#[derive(Debug, Clone)]
pub struct Brain {
    program: Program,
    store: BeliefStore,
    active: Vec<Level>,
    durative: Vec<Action>,
    last_step: Option<Now>,
}

impl Brain {
    pub fn new(program: Program) -> Self {
        Brain {
            program,
            store: BeliefStore::new(),
            active: Vec::new(),
            durative: Vec::new(),
            last_step: None,
        }
    }

    pub fn program(&self) -> &Program {
        &self.program
    }

    pub fn store(&self) -> &BeliefStore {
        &self.store
    }

    /// The active rule path, outermost first.
    pub fn active(&self) -> Vec<RuleRef> {
        self.active.iter().map(Level::rule_ref).collect()
    }

    /// The durative actions currently running.
    pub fn running(&self) -> &[Action] {
        &self.durative
    }

    /// Swaps in a new program, keeping the belief store and the active path: if the same rule (by procedure and
    /// label) is still active after the next step, its discrete actions do not fire again and its durative
    /// actions keep running.
    pub fn reload(&mut self, program: Program) {
        self.program = program;
    }

    /// Records a percept sensed at `at`. Returns whether the store changed in a way guards can see (a new fact or
    /// value); refreshing an unchanged state returns false, and the host may skip the step.
    pub fn perceive(
        &mut self,
        at: Instant,
        name: &str,
        args: Vec<Value>,
    ) -> Result<bool, PerceptError> {
        let (event, fresh) = self.admit(name, &args)?;
        let before = self
            .store
            .named(name)
            .map(|fact| fact.id)
            .collect::<Vec<_>>();
        self.store.assert(at, name, args, event, fresh);
        Ok(self
            .store
            .named(name)
            .map(|fact| fact.id)
            .collect::<Vec<_>>()
            != before)
    }

    /// Records every current fact of a predicate at once (several codes in view); facts not in `sets` go.
    pub fn perceive_set(
        &mut self,
        at: Instant,
        name: &str,
        sets: Vec<Vec<Value>>,
    ) -> Result<bool, PerceptError> {
        let mut checked = None;
        for args in &sets {
            checked = Some(self.admit(name, args)?);
        }
        let (event, fresh) = checked.unwrap_or_else(|| self.kind_of(name));
        let mut before = self
            .store
            .named(name)
            .map(|fact| fact.id)
            .collect::<Vec<_>>();
        self.store.assert_set(at, name, sets, event, fresh);
        let mut after = self
            .store
            .named(name)
            .map(|fact| fact.id)
            .collect::<Vec<_>>();
        before.sort_unstable();
        after.sort_unstable();
        Ok(before != after)
    }

    /// Records `text` as what the agent said last (`said`), for what the host says outside the rules' `say`: a
    /// language model's reply, a recalled passage. "Say that again" then repeats it.
    pub fn said(&mut self, at: Instant, text: &str) {
        let fresh = self.program.fresh(SAID);
        self.store
            .assert(at, SAID, vec![Value::Text(text.to_owned())], false, fresh);
    }

    /// Removes every fact of a percept (the agent stopped speaking).
    pub fn retract(&mut self, name: &str) -> bool {
        let had = self.store.named(name).next().is_some();
        self.store.retract(name);
        had
    }

    fn kind_of(&self, name: &str) -> (bool, Option<Duration>) {
        self.program
            .decl(name)
            .map_or((false, None), |decl| (decl.event, decl.fresh))
    }

    /// Checks a percept against its declaration; undeclared percepts are kept as states the program ignores.
    fn admit(&self, name: &str, args: &[Value]) -> Result<(bool, Option<Duration>), PerceptError> {
        let Some(decl) = self.program.decl(name) else {
            return Ok((false, None));
        };
        if decl.kind == DeclKind::Belief {
            return Err(PerceptError::NotPercept {
                name: name.to_owned(),
            });
        }
        if decl.args.len() != args.len() {
            return Err(PerceptError::Arity {
                name: name.to_owned(),
                expected: decl.args.len(),
                got: args.len(),
            });
        }
        for (index, (ty, value)) in decl.args.iter().zip(args).enumerate() {
            if !ty.admits(value) {
                return Err(PerceptError::Type {
                    name: name.to_owned(),
                    index: index + 1,
                    expected: ty.name(),
                    got: value.type_name(),
                });
            }
        }
        Ok((decl.event, decl.fresh))
    }

    /// When the host should step again if no percept arrives before: the next instant at which a fact expires,
    /// leaves a `within` window, completes a `for` duration (facts kept until retracted), or (for guards reading
    /// the clock) the minute changes.
    pub fn next_wakeup(&self, now: Instant) -> Option<Instant> {
        // Freshness and windows are inclusive, so a fact stops counting just after its limit.
        let just_after = Duration::from_millis(1);
        let mut candidates = Vec::new();
        for fact in self.store.facts() {
            if let Some(fresh) = self.program.fresh(&fact.name) {
                candidates.push(fact.last_seen + fresh + just_after);
            }
            for window in self.program.windows.get(&fact.name).into_iter().flatten() {
                candidates.push(fact.last_seen + *window + just_after);
            }
            // Only facts kept until retracted satisfy a `for` by time alone; sensed ones need new percepts.
            if self.program.fresh(&fact.name).is_none() {
                for hold in self.program.holds.get(&fact.name).into_iter().flatten() {
                    candidates.push(fact.since + *hold);
                }
            }
        }
        if self.program.reads_clock
            && let Some(last) = &self.last_step
        {
            let to_next_minute = Duration::from_secs(u64::from(60 - last.clock.second.min(59)));
            candidates.push(last.at + to_next_minute);
        }
        candidates.into_iter().filter(|at| *at > now).min()
    }

    /// Re-evaluates the program at `now` and returns what changed.
    pub fn step(&mut self, now: &Now, db: &dyn PairDb) -> Step {
        self.last_step = Some(*now);
        let program = &self.program;
        self.store
            .prune(now.at, |name| (program.fresh(name), program.history(name)));
        let mut step = Step::default();
        for _ in 0..MAX_ROUNDS {
            if !self.round(now, db, &mut step) {
                return step;
            }
        }
        step.warnings.push(format!(
            "the rules kept changing beliefs for {MAX_ROUNDS} rounds; stopped re-evaluating until the next percept"
        ));
        step
    }

    /// One evaluation round; returns whether it updated beliefs (so that another round is needed).
    fn round(&mut self, now: &Now, db: &dyn PairDb, step: &mut Step) -> bool {
        let chosen = self.choose(now, db);
        let levels: Vec<Level> = chosen.iter().map(|c| self.level(c)).collect();
        let first_changed = (0..levels.len().max(self.active.len()))
            .find(|&i| levels.get(i) != self.active.get(i))
            .filter(|_| levels != self.active);
        // The trace is taken before any belief update, so that it shows the facts the guards matched even when
        // the rule then forgets them (`forget(heard)`).
        let trace = first_changed.map(|_| self.trace(now, &chosen, &levels));

        let mut new_durative = Vec::new();
        let mut discrete = Vec::new();
        for (depth, chosen) in chosen.iter().enumerate() {
            let rule = &self.program.procedures[chosen.procedure].rules[chosen.rule];
            let scope = Scope {
                env: &chosen.proof.env,
                clock: &now.clock,
                db,
            };
            for action in &rule.durative {
                match instantiate(action, &scope) {
                    Ok(Some(Deed::Act(action))) => new_durative.push(action),
                    Ok(_) => {}
                    Err(warning) => step.warnings.push(warning),
                }
            }
            if first_changed.is_some_and(|first| depth >= first) {
                for action in &rule.discrete {
                    match instantiate(action, &scope) {
                        Ok(Some(deed)) => discrete.push(deed),
                        Ok(None) => {}
                        Err(warning) => step.warnings.push(warning),
                    }
                }
            }
        }

        let mut effects = Vec::new();
        for action in &self.durative {
            if !new_durative.contains(action) {
                effects.push(Effect::Stop(action.clone()));
            }
        }
        for action in &new_durative {
            if !self.durative.contains(action) {
                effects.push(Effect::Start(action.clone()));
            }
        }
        let mut updates = Vec::new();
        for deed in discrete {
            match deed {
                Deed::Act(action) => effects.push(Effect::Fire(action)),
                Deed::Remember(name, args) => {
                    updates.push(format!("remember({})", render_fact(&name, &args)));
                    let fresh = self.program.fresh(&name);
                    self.store.assert(now.at, &name, args, false, fresh);
                }
                Deed::Forget(name, pattern) => {
                    match &pattern {
                        Some(pattern) => self.store.retract_matching(&name, pattern),
                        None => self.store.retract(&name),
                    }
                    updates.push(format!("forget({name})"));
                }
            }
        }
        // The engine remembers what it last said, for "repeat that".
        let said_fresh = self.program.fresh(SAID);
        for effect in &effects {
            if let Effect::Start(Action::Say { text }) | Effect::Fire(Action::Say { text }) = effect
            {
                self.store.assert(
                    now.at,
                    SAID,
                    vec![Value::Text(text.clone())],
                    false,
                    said_fresh,
                );
            }
        }
        let said_changed = effects.iter().any(|e| {
            matches!(
                e,
                Effect::Start(Action::Say { .. }) | Effect::Fire(Action::Say { .. })
            )
        });

        if let Some(mut trace) = trace {
            trace.effects = effects.clone();
            trace.updates = updates.clone();
            step.traces.push(trace);
        }
        step.effects.extend(effects);
        self.active = levels;
        self.durative = new_durative;
        !updates.is_empty() || said_changed
    }

    /// Walks down from `main`: the first rule whose guard holds in each procedure, descending into the procedure
    /// its durative actions call.
    fn choose(&self, now: &Now, db: &dyn PairDb) -> Vec<Chosen> {
        let solver = Solver {
            program: &self.program,
            store: &self.store,
            now: now.at,
            clock: &now.clock,
            db,
        };
        let mut path: Vec<Chosen> = Vec::new();
        let mut procedure = self.program.main;
        let mut env = Env::new();
        // The checker rejects recursive procedures, so a path is never longer than the number of procedures.
        while path.len() < self.program.procedures.len() {
            let rules = &self.program.procedures[procedure].rules;
            let Some((rule, proof)) = rules
                .iter()
                .enumerate()
                .find_map(|(i, rule)| solver.prove(&rule.guard, env.clone()).map(|p| (i, p)))
            else {
                break;
            };
            let call = rules[rule].durative.iter().find_map(|action| match action {
                ActionExpr::Procedure { name, args, .. } => Some((name, args)),
                ActionExpr::Primitive { .. } => None,
            });
            let next = call.and_then(|(name, args)| {
                let callee = self
                    .program
                    .procedures
                    .iter()
                    .position(|p| &p.name == name)?;
                let scope = Scope {
                    env: &proof.env,
                    clock: &now.clock,
                    db,
                };
                let values: Option<Vec<Value>> = args.iter().map(|arg| eval(arg, &scope)).collect();
                let params = &self.program.procedures[callee].params;
                Some((callee, params.iter().cloned().zip(values?).collect::<Env>()))
            });
            path.push(Chosen {
                procedure,
                rule,
                proof,
            });
            match next {
                Some((callee, callee_env)) => {
                    procedure = callee;
                    env = callee_env;
                }
                None => break,
            }
        }
        path
    }

    fn level(&self, chosen: &Chosen) -> Level {
        let procedure = &self.program.procedures[chosen.procedure];
        let rule = &procedure.rules[chosen.rule];
        let events = chosen
            .proof
            .support
            .iter()
            .filter(|id| self.store.fact(**id).is_some_and(|fact| fact.event))
            .copied()
            .collect();
        Level {
            procedure: procedure.name.clone(),
            rule: rule.label.clone(),
            line: rule.pos.line,
            events,
        }
    }

    /// The trace of a change of path, without its effects and updates yet.
    fn trace(&self, now: &Now, chosen: &[Chosen], levels: &[Level]) -> Trace {
        let mut because = Vec::new();
        for id in chosen.iter().flat_map(|c| &c.proof.support) {
            if let Some(fact) = self.store.fact(*id) {
                because.push(Evidence {
                    fact: render_fact(&fact.name, &fact.args),
                    age_ms: now.at.saturating_duration_since(fact.last_seen).as_millis() as u64,
                });
            }
        }
        let bindings = chosen
            .last()
            .map(|c| {
                c.proof
                    .env
                    .iter()
                    .map(|(name, value)| Binding {
                        name: name.clone(),
                        value: value.clone(),
                    })
                    .collect()
            })
            .unwrap_or_default();
        let reentered = !levels.is_empty()
            && levels.len() == self.active.len()
            && levels
                .iter()
                .zip(&self.active)
                .all(|(a, b)| a.procedure == b.procedure && a.rule == b.rule);
        Trace {
            unix_ms: now.clock.unix_ms,
            path: levels.iter().map(Level::rule_ref).collect(),
            previous: self.active.iter().map(Level::rule_ref).collect(),
            reentered,
            because,
            bindings,
            effects: Vec::new(),
            updates: Vec::new(),
        }
    }
}

impl Level {
    fn rule_ref(&self) -> RuleRef {
        RuleRef {
            procedure: self.procedure.clone(),
            rule: self.rule.clone(),
            line: self.line,
        }
    }
}

/// `face(2, "left")`, or `greeted` for a fact without arguments.
fn render_fact(name: &str, args: &[Value]) -> String {
    if args.is_empty() {
        return name.to_owned();
    }
    let args: Vec<String> = args.iter().map(|arg| Quoted(arg).to_string()).collect();
    format!("{name}({})", args.join(", "))
}

/// Turns an action expression into a deed with the rule's bindings; `Ok(None)` for a procedure call (not an
/// action), `Err` when an argument has no value (a pair-database key that is not set).
fn instantiate(action: &ActionExpr, scope: &Scope<'_>) -> Result<Option<Deed>, String> {
    let ActionExpr::Primitive {
        primitive,
        args,
        pos,
    } = action
    else {
        return Ok(None);
    };
    let value = |index: usize| {
        eval(&args[index], scope).ok_or_else(|| {
            format!(
                "line {}: an argument of `{}` has no value; the action was skipped",
                pos.line,
                primitive.name()
            )
        })
    };
    let text = |index: usize| value(index).map(|value| value.to_string());
    let deed = match primitive {
        Primitive::Say => Deed::Act(Action::Say { text: text(0)? }),
        Primitive::Publish => Deed::Act(Action::Publish {
            channel: text(0)?,
            payload: value(1)?,
        }),
        Primitive::Call => Deed::Act(Action::Call {
            service: text(0)?,
            payload: value(1)?,
        }),
        Primitive::Run => Deed::Act(Action::Run { command: text(0)? }),
        Primitive::Set => Deed::Act(Action::Set {
            key: text(0)?,
            value: value(1)?,
        }),
        Primitive::Cancel => Deed::Act(Action::Cancel),
        Primitive::Chat => Deed::Act(Action::Chat {
            text: text(0)?,
            tool: if args.len() > 1 { Some(text(1)?) } else { None },
        }),
        Primitive::ForgetConversation => Deed::Act(Action::ForgetConversation),
        Primitive::Recall => Deed::Act(Action::Recall { text: text(0)? }),
        Primitive::LearnFace => Deed::Act(Action::LearnFace { name: text(0)? }),
        Primitive::ForgetFace => Deed::Act(Action::ForgetFace),
        Primitive::Mood => Deed::Act(Action::Mood { mood: text(0)? }),
        Primitive::Remember | Primitive::Forget => {
            let (name, fact_args) = match &args[0] {
                Expr::Call(name, fact_args, _) => (name.clone(), Some(fact_args)),
                Expr::Lit(Value::Text(name), _) => (name.clone(), None),
                _ => {
                    return Err(format!(
                        "line {}: `{}` needs a fact",
                        pos.line,
                        primitive.name()
                    ));
                }
            };
            if *primitive == Primitive::Remember {
                let values = fact_args
                    .into_iter()
                    .flatten()
                    .map(|arg| eval(arg, scope))
                    .collect::<Option<Vec<_>>>();
                let values = values.ok_or_else(|| {
                    format!("line {}: an argument of `remember` has no value", pos.line)
                })?;
                Deed::Remember(name, values)
            } else {
                let pattern = fact_args.map(|fact_args| {
                    fact_args
                        .iter()
                        .map(|arg| {
                            if matches!(arg, Expr::Wild(_)) {
                                None
                            } else {
                                eval(arg, scope)
                            }
                        })
                        .collect::<Vec<_>>()
                });
                Deed::Forget(name, pattern)
            }
        }
    };
    Ok(Some(deed))
}
