//! The belief store: the facts sensed (percepts) and remembered (beliefs), each with when it was first and last
//! sensed, so that guards can ask whether a fact is fresh, was seen recently, or has held for a while.

use std::time::{Duration, Instant};

use crate::value::Value;

/// One fact: `face(2, "left")`.
#[derive(Debug, Clone, PartialEq)]
pub struct Fact {
    pub name: String,
    pub args: Vec<Value>,
    /// Changes whenever this is a new event or a new value; a refresh of the same state keeps it.
    pub id: u64,
    /// When the predicate started to hold continuously (kept across value changes while it stays fresh).
    pub since: Instant,
    /// When the fact was last sensed or remembered.
    pub last_seen: Instant,
    /// Whether this is an event (every assertion a new occurrence) rather than a state.
    pub event: bool,
}

impl Fact {
    /// Whether the fact is still believed at `now`, given its predicate's freshness (`None`: until retracted).
    pub fn is_fresh(&self, now: Instant, fresh: Option<Duration>) -> bool {
        fresh.is_none_or(|window| now.saturating_duration_since(self.last_seen) <= window)
    }

    /// How long the predicate has held, for `for` qualifiers. A sensed percept (one with a freshness window) has
    /// held over the span it was actually sensed, so a single detection never counts as a long presence; a fact
    /// kept until retracted has held since it started.
    pub fn held(&self, now: Instant, fresh: Option<Duration>) -> Duration {
        match fresh {
            Some(_) => self.last_seen.saturating_duration_since(self.since),
            None => now.saturating_duration_since(self.since),
        }
    }
}

/// The facts, at most one per predicate name unless the host asserts a whole set (`assert_set`).
///
/// Facts are few (a handful of percepts and beliefs), so a vector scanned linearly is both the simplest and the
/// fastest structure here.
#[derive(Debug, Default, Clone)]
pub struct BeliefStore {
    facts: Vec<Fact>,
    next_id: u64,
}

impl BeliefStore {
    pub fn new() -> Self {
        Self::default()
    }

    /// All facts named `name`, fresh or stale.
    pub fn named<'a>(&'a self, name: &'a str) -> impl Iterator<Item = &'a Fact> + 'a {
        self.facts.iter().filter(move |fact| fact.name == name)
    }

    pub fn facts(&self) -> &[Fact] {
        &self.facts
    }

    pub fn fact(&self, id: u64) -> Option<&Fact> {
        self.facts.iter().find(|fact| fact.id == id)
    }

    fn fresh_id(&mut self) -> u64 {
        self.next_id += 1;
        self.next_id
    }

    /// Asserts the single current fact of a predicate: a state refreshes an equal fresh fact (same id) or replaces
    /// it with a new value (new id, continuous `since`); an event always becomes a new occurrence.
    pub fn assert(
        &mut self,
        at: Instant,
        name: &str,
        args: Vec<Value>,
        event: bool,
        fresh: Option<Duration>,
    ) {
        let previous = self.facts.iter().position(|fact| fact.name == name);
        let still_fresh = previous.filter(|&i| self.facts[i].is_fresh(at, fresh));
        if let Some(i) = still_fresh
            && !event
            && self.facts[i].args == args
        {
            self.facts[i].last_seen = at;
            return;
        }
        let since = still_fresh.map_or(at, |i| self.facts[i].since);
        self.facts.retain(|fact| fact.name != name);
        let id = self.fresh_id();
        self.facts.push(Fact {
            name: name.to_owned(),
            args,
            id,
            since,
            last_seen: at,
            event,
        });
    }

    /// Replaces every fact of a predicate by `sets` (for predicates with several facts at once, such as codes in
    /// view); members equal to a fresh existing fact keep their identity and `since`.
    pub fn assert_set(
        &mut self,
        at: Instant,
        name: &str,
        sets: Vec<Vec<Value>>,
        event: bool,
        fresh: Option<Duration>,
    ) {
        let mut kept = Vec::new();
        for args in sets {
            let existing = self.facts.iter().position(|fact| {
                fact.name == name && fact.args == args && fact.is_fresh(at, fresh)
            });
            match existing {
                Some(i) if !event => {
                    let mut fact = self.facts.swap_remove(i);
                    fact.last_seen = at;
                    kept.push(fact);
                }
                _ => {
                    let id = self.fresh_id();
                    kept.push(Fact {
                        name: name.to_owned(),
                        args,
                        id,
                        since: at,
                        last_seen: at,
                        event,
                    });
                }
            }
        }
        self.facts.retain(|fact| fact.name != name);
        self.facts.extend(kept);
    }

    /// Removes every fact of a predicate.
    pub fn retract(&mut self, name: &str) {
        self.facts.retain(|fact| fact.name != name);
    }

    /// Removes the facts of a predicate whose arguments match `pattern` (`None` matches any argument).
    pub fn retract_matching(&mut self, name: &str, pattern: &[Option<Value>]) {
        self.facts.retain(|fact| {
            fact.name != name
                || fact.args.len() != pattern.len()
                || !fact
                    .args
                    .iter()
                    .zip(pattern)
                    .all(|(arg, want)| want.as_ref().is_none_or(|want| want == arg))
        });
    }

    /// Drops facts that are no longer fresh and that no `within` window can still see; `keep` tells, per predicate
    /// name, its freshness and the longest `within` window the program uses on it.
    pub fn prune(&mut self, now: Instant, keep: impl Fn(&str) -> (Option<Duration>, Duration)) {
        self.facts.retain(|fact| {
            let (fresh, history) = keep(&fact.name);
            fact.is_fresh(now, fresh) || now.saturating_duration_since(fact.last_seen) <= history
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FRESH: Option<Duration> = Some(Duration::from_secs(2));

    #[test]
    fn a_state_refresh_keeps_its_identity() {
        let t0 = Instant::now();
        let mut store = BeliefStore::new();
        store.assert(t0, "face", vec![Value::Num(1.0)], false, FRESH);
        let id = store.named("face").map(|f| f.id).next();
        store.assert(
            t0 + Duration::from_secs(1),
            "face",
            vec![Value::Num(1.0)],
            false,
            FRESH,
        );
        assert_eq!(store.named("face").map(|f| f.id).next(), id);
        // A new value is a new fact, but the predicate has held continuously since t0.
        store.assert(
            t0 + Duration::from_millis(1500),
            "face",
            vec![Value::Num(2.0)],
            false,
            FRESH,
        );
        let fact = store.named("face").next().cloned();
        assert_ne!(fact.as_ref().map(|f| f.id), id);
        assert_eq!(fact.map(|f| f.since), Some(t0));
    }

    #[test]
    fn a_reappearance_after_expiry_starts_anew() {
        let t0 = Instant::now();
        let mut store = BeliefStore::new();
        store.assert(t0, "face", vec![Value::Num(1.0)], false, FRESH);
        let later = t0 + Duration::from_secs(5);
        store.assert(later, "face", vec![Value::Num(1.0)], false, FRESH);
        assert_eq!(store.named("face").map(|f| f.since).next(), Some(later));
    }

    #[test]
    fn every_event_is_a_new_occurrence() {
        let t0 = Instant::now();
        let mut store = BeliefStore::new();
        store.assert(t0, "heard", vec![Value::from("hi")], true, FRESH);
        let first = store.named("heard").map(|f| f.id).next();
        store.assert(t0, "heard", vec![Value::from("hi")], true, FRESH);
        assert_ne!(store.named("heard").map(|f| f.id).next(), first);
        assert_eq!(store.named("heard").count(), 1);
    }

    #[test]
    fn sets_keep_members_and_drop_the_rest() {
        let t0 = Instant::now();
        let mut store = BeliefStore::new();
        store.assert_set(
            t0,
            "code",
            vec![vec![Value::from("a")], vec![Value::from("b")]],
            false,
            FRESH,
        );
        let a = store
            .named("code")
            .find(|f| f.args[0] == Value::from("a"))
            .map(|f| f.id);
        store.assert_set(
            t0,
            "code",
            vec![vec![Value::from("a")], vec![Value::from("c")]],
            false,
            FRESH,
        );
        assert_eq!(store.named("code").count(), 2);
        assert_eq!(
            store
                .named("code")
                .find(|f| f.args[0] == Value::from("a"))
                .map(|f| f.id),
            a
        );
        assert!(store.named("code").all(|f| f.args[0] != Value::from("b")));
    }

    #[test]
    fn prune_keeps_history_for_within_windows() {
        let t0 = Instant::now();
        let mut store = BeliefStore::new();
        store.assert(t0, "face", vec![], false, FRESH);
        store.prune(t0 + Duration::from_secs(5), |_| {
            (FRESH, Duration::from_secs(10))
        });
        assert_eq!(store.facts().len(), 1);
        store.prune(t0 + Duration::from_secs(11), |_| {
            (FRESH, Duration::from_secs(10))
        });
        assert!(store.facts().is_empty());
    }
}
