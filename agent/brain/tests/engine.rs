//! Semantics of the evaluator: rule order, re-evaluation as percepts change, durative and discrete actions,
//! time qualifiers and wake-ups, procedures, traces, belief updates and hot reload.

mod common;

use std::collections::BTreeMap;

use agent_brain::{Action, Brain, Effect, PerceptError, Value};
use common::{Sim, load, ms, says};

fn say(text: &str) -> Action {
    Action::Say { text: text.into() }
}

const TWO_RULES: &str = r#"
percept a, b
procedure main {
    first:  a ++ say("first")
    second: b ++ say("second")
    idle:   true ~> ()
}
"#;

#[test]
fn the_first_rule_whose_guard_holds_is_active() {
    let mut sim = Sim::new(load(TWO_RULES));
    assert_eq!(sim.brain.active()[0].rule, "idle");
    assert_eq!(says(&sim.perceive("b", vec![])), ["second"]);
    // `a` is higher up: it takes over although `b` still holds.
    assert_eq!(says(&sim.perceive("a", vec![])), ["first"]);
    assert_eq!(sim.brain.active()[0].rule, "first");
    // Retracting `a` hands back to `second`, which is entered again and fires again.
    assert_eq!(says(&sim.retract("a")), ["second"]);
}

#[test]
fn order_decides_between_rules_that_both_hold() {
    let swapped = TWO_RULES
        .replace("first:  a", "first:  b")
        .replace("second: b", "second: a");
    let mut sim = Sim::new(load(&swapped));
    sim.perceive("a", vec![]);
    sim.perceive("b", vec![]);
    assert_eq!(sim.brain.active()[0].rule, "first");
    assert_eq!(sim.said(), ["second", "first"]);
}

#[test]
fn expiry_of_a_percept_re_evaluates_without_new_input() {
    let program = r#"
        percept face(num, dir) fresh 1s
        procedure main {
            watch: face(N, _) ~> publish("Robot.face", {watch: N})
            idle:  true ~> ()
        }
    "#;
    let mut sim = Sim::new(load(program));
    sim.perceive("face", vec![Value::Num(1.0), Value::from("left")]);
    assert_eq!(sim.brain.active()[0].rule, "watch");
    // The brain asks to be woken just after the face goes stale, and then leaves the rule.
    let wake = sim.brain.next_wakeup(sim.start);
    assert_eq!(wake, Some(sim.start + ms(1001)));
    sim.advance(ms(1500));
    assert_eq!(sim.brain.active()[0].rule, "idle");
    assert_eq!(sim.times_of(|e| matches!(e, Effect::Stop(_))), [ms(1001)]);
}

#[test]
fn durative_actions_run_while_active_and_discrete_fire_once_on_entry() {
    let program = r#"
        percept listening, ping
        procedure main {
            attend: listening ~> publish("Robot.face", {attend: true}) ++ say("mm-hm")
            idle:   true ~> ()
        }
    "#;
    let mut sim = Sim::new(load(program));
    let attend = Action::Publish {
        channel: "Robot.face".into(),
        payload: Value::Map(vec![("attend".into(), Value::Bool(true))]),
    };
    let entry = sim.perceive("listening", vec![]);
    assert_eq!(
        entry,
        vec![Effect::Start(attend.clone()), Effect::Fire(say("mm-hm"))]
    );
    // Other percepts and later steps while the rule stays active change nothing.
    assert!(sim.perceive("ping", vec![]).is_empty());
    assert!(sim.perceive("listening", vec![]).is_empty());
    sim.advance(ms(5000));
    assert_eq!(sim.brain.running(), std::slice::from_ref(&attend));
    // Leaving the rule stops the durative action; the discrete one has nothing to stop.
    assert_eq!(sim.retract("listening"), vec![Effect::Stop(attend)]);
    assert!(sim.brain.running().is_empty());
}

#[test]
fn a_durative_action_shared_by_two_rules_keeps_running_across_them() {
    let program = r#"
        percept a, b
        procedure main {
            one:  a ~> say("humming"), publish("x", 1)
            two:  b ~> say("humming"), publish("x", 2)
            idle: true ~> ()
        }
    "#;
    let mut sim = Sim::new(load(program));
    sim.perceive("b", vec![]);
    let effects = sim.perceive("a", vec![]);
    let publish = |n: f64| Action::Publish {
        channel: "x".into(),
        payload: Value::Num(n),
    };
    assert_eq!(
        effects,
        vec![Effect::Stop(publish(2.0)), Effect::Start(publish(1.0))]
    );
}

#[test]
fn changed_bindings_restart_durative_actions_without_re_entering() {
    let program = r#"
        percept face(num, dir) fresh 2s
        procedure main {
            look: face(_, D) ~> publish("Robot.face", {gaze: D}) ++ say("I see you")
            idle: true ~> ()
        }
    "#;
    let mut sim = Sim::new(load(program));
    let gaze = |d: &str| Action::Publish {
        channel: "Robot.face".into(),
        payload: Value::Map(vec![("gaze".into(), Value::from(d))]),
    };
    let entry = sim.perceive("face", vec![Value::Num(1.0), Value::from("left")]);
    assert_eq!(
        entry,
        vec![Effect::Start(gaze("left")), Effect::Fire(say("I see you"))]
    );
    sim.advance(ms(100));
    // The face moves: the gaze follows, but the greeting-like discrete action does not fire again.
    let moved = sim.perceive("face", vec![Value::Num(1.0), Value::from("right")]);
    assert_eq!(
        moved,
        vec![Effect::Stop(gaze("left")), Effect::Start(gaze("right"))]
    );
    assert!(
        sim.traces
            .last()
            .is_some_and(|t| t.path[0].rule == "look" && t.previous[0].rule == "idle")
    );
}

#[test]
fn a_new_event_re_enters_the_rule_but_a_state_refresh_does_not() {
    let program = r#"
        percept heard(text) event fresh 3s
        percept face(num, dir) fresh 3s
        procedure main {
            echo:  heard(T) ++ say("you said {T}")
            seen:  face(N, _) ++ say("{N} here")
            idle:  true ~> ()
        }
    "#;
    let mut sim = Sim::new(load(program));
    assert_eq!(says(&sim.hear("hello")), ["you said hello"]);
    sim.advance(ms(500));
    // The same words again are a new utterance, answered again.
    assert_eq!(says(&sim.hear("hello")), ["you said hello"]);
    assert!(sim.traces.last().is_some_and(|t| t.reentered));
    sim.advance(ms(3500));
    assert_eq!(
        says(&sim.perceive("face", vec![Value::Num(1.0), Value::from("left")])),
        ["1 here"]
    );
    sim.advance(ms(100));
    assert!(
        sim.perceive("face", vec![Value::Num(1.0), Value::from("left")])
            .is_empty()
    );
}

#[test]
fn for_waits_until_a_percept_has_held_long_enough() {
    let program = r#"
        percept face(num, dir) fresh 1s
        procedure main {
            steady: face(_, _) for 2s ++ say("steady")
            idle:   true ~> ()
        }
    "#;
    let mut sim = Sim::new(load(program));
    // Frames every 100 ms for 3 s: the rule becomes active at 2 s, once.
    for _ in 0..30 {
        sim.perceive("face", vec![Value::Num(1.0), Value::from("centre")]);
        sim.advance(ms(100));
    }
    assert_eq!(
        sim.times_of(|e| says(std::slice::from_ref(e)) == ["steady"]),
        [ms(2000)]
    );
}

#[test]
fn for_needs_a_sensed_percept_to_be_sensed_over_the_whole_span() {
    let program = r#"
        percept face(num, dir) fresh 5s
        procedure main {
            steady: face(_, _) for 1s ++ say("steady")
            idle:   true ~> ()
        }
    "#;
    let mut sim = Sim::new(load(program));
    // One detection stays fresh for 5 s, but it is no evidence of a presence lasting a second.
    sim.perceive("face", vec![Value::Num(1.0), Value::from("centre")]);
    sim.advance(ms(3000));
    assert!(sim.said().is_empty());
    sim.perceive("face", vec![Value::Num(1.0), Value::from("centre")]);
    assert_eq!(sim.said(), ["steady"]);
}

#[test]
fn for_on_a_fact_kept_until_retracted_counts_time_alone() {
    let program = r#"
        percept speaking
        procedure main {
            long: speaking for 3s ++ say("I talk too much")
            idle: true ~> ()
        }
    "#;
    let mut sim = Sim::new(load(program));
    sim.perceive("speaking", vec![]);
    assert_eq!(sim.brain.next_wakeup(sim.start), Some(sim.start + ms(3000)));
    sim.advance(ms(5000));
    assert_eq!(
        sim.times_of(|e| !says(std::slice::from_ref(e)).is_empty()),
        [ms(3000)]
    );
}

#[test]
fn within_sees_a_stale_percept_for_a_while() {
    let program = r#"
        percept code(text) fresh 500ms
        procedure main {
            fresh_code:  code(C) ~> ()
            recent_code: code(C) within 5s ~> ()
            idle:        true ~> ()
        }
    "#;
    let mut sim = Sim::new(load(program));
    sim.perceive("code", vec![Value::from("HELLO")]);
    assert_eq!(sim.brain.active()[0].rule, "fresh_code");
    sim.advance(ms(1000));
    assert_eq!(sim.brain.active()[0].rule, "recent_code");
    sim.advance(ms(5000));
    assert_eq!(sim.brain.active()[0].rule, "idle");
    // The stale fact is pruned once no window can see it.
    assert!(sim.brain.store().facts().is_empty());
}

#[test]
fn procedures_form_a_path_and_their_rules_are_traced() {
    let program = r#"
        percept heard(text) event fresh 2s
        procedure main {
            converse: heard(T) ~> answer(T)
            idle:     true ~> ()
        }
        procedure answer(Text) {
            time:  Text ~ "what time" ++ say("It is {time.hhmm}.")
            other: true ++ say("Pardon?")
        }
    "#;
    let mut sim = Sim::new(load(program));
    assert_eq!(says(&sim.hear("What time is it?")), ["It is 15:15."]);
    let path: Vec<String> = sim.brain.active().iter().map(ToString::to_string).collect();
    assert_eq!(path, ["main.converse", "answer.time"]);
    let trace = sim.traces.last().cloned();
    let Some(trace) = trace else {
        panic!("no trace")
    };
    assert_eq!(trace.previous.len(), 1);
    assert_eq!(trace.previous[0].rule, "idle");
    assert_eq!(trace.because.len(), 1);
    assert_eq!(trace.because[0].fact, r#"heard("What time is it?")"#);
    assert!(
        trace
            .bindings
            .iter()
            .any(|b| b.name == "Text" && b.value == Value::from("What time is it?"))
    );
    assert!(trace.path[1].line > trace.path[0].line);
    assert_eq!(trace.effects, vec![Effect::Fire(say("It is 15:15."))]);
    assert_eq!(says(&sim.hear("blah")), ["Pardon?"]);
}

#[test]
fn a_trace_serialises_for_agent_rules() -> Result<(), serde_json::Error> {
    let mut sim = Sim::new(load(TWO_RULES));
    sim.perceive("a", vec![]);
    let Some(trace) = sim.traces.last() else {
        panic!("no trace")
    };
    let json = serde_json::to_value(trace)?;
    assert_eq!(json["path"][0]["rule"], "first");
    assert_eq!(json["because"][0]["fact"], "a");
    assert_eq!(json["effects"][0]["effect"], "fire");
    assert_eq!(json["effects"][0]["do"]["action"], "say");
    assert_eq!(json["effects"][0]["do"]["text"], "first");
    assert!(
        trace
            .to_string()
            .contains("main.idle -> main.first because a")
    );
    Ok(())
}

#[test]
fn remembered_beliefs_greet_once_per_appearance() {
    let program = r#"
        percept face(num, dir) fresh 1s
        belief greeted
        procedure main {
            greet:    face(_, _) & not greeted ++ say("hello"), remember(greeted)
            farewell: greeted & not face(_, _) within 5s ++ forget(greeted)
            idle:     true ~> ()
        }
    "#;
    let mut sim = Sim::new(load(program));
    let frames = |sim: &mut Sim, n: usize| {
        for _ in 0..n {
            sim.perceive("face", vec![Value::Num(1.0), Value::from("centre")]);
            sim.advance(ms(66));
        }
    };
    frames(&mut sim, 60);
    assert_eq!(sim.said(), ["hello"]);
    // Looking away briefly (under the window) is still the same appearance.
    sim.advance(ms(3000));
    frames(&mut sim, 30);
    assert_eq!(sim.said(), ["hello"]);
    // Leaving for longer forgets the greeting, and the next appearance is greeted again.
    sim.advance(ms(8000));
    frames(&mut sim, 30);
    assert_eq!(sim.said(), ["hello", "hello"]);
    assert!(sim.traces.iter().any(|t| t.updates == ["forget(greeted)"]));
}

#[test]
fn a_program_that_never_settles_is_cut_off_with_a_warning() {
    let program = r#"
        belief x
        procedure main {
            set:   not x ++ remember(x)
            unset: x ++ forget(x)
        }
    "#;
    let sim = Sim::new(load(program));
    assert_eq!(sim.warnings.len(), 1);
    assert!(sim.warnings[0].contains("kept changing beliefs"));
}

#[test]
fn pair_database_values_are_read_through_the_lookup() {
    let program = r#"
        procedure main {
            quiet: db("agent.mode") = "quiet" ~> ()
            talk:  true ~> say("chatty")
        }
    "#;
    let mut brain = Brain::new(load(program));
    let mut db = BTreeMap::new();
    let sim = Sim::new(load(program));
    let now = sim.now();
    assert_eq!(
        brain.step(&now, &db).effects,
        vec![Effect::Start(say("chatty"))]
    );
    assert_eq!(
        brain.program().db_keys().collect::<Vec<_>>(),
        ["agent.mode"]
    );
    db.insert("agent.mode".to_owned(), Value::from("quiet"));
    assert_eq!(
        brain.step(&now, &db).effects,
        vec![Effect::Stop(say("chatty"))]
    );
    assert_eq!(brain.active()[0].rule, "quiet");
}

#[test]
fn percepts_that_do_not_fit_their_declaration_are_rejected() {
    let mut sim = Sim::new(load(
        "percept face(num, text)\nbelief greeted\nprocedure main { idle: true ~> () }",
    ));
    let at = sim.start;
    assert_eq!(
        sim.brain.perceive(at, "face", vec![Value::Num(1.0)]),
        Err(PerceptError::Arity {
            name: "face".into(),
            expected: 2,
            got: 1
        })
    );
    assert_eq!(
        sim.brain
            .perceive(at, "face", vec![Value::from("one"), Value::from("left")]),
        Err(PerceptError::Type {
            name: "face".into(),
            index: 1,
            expected: "num",
            got: "text"
        })
    );
    assert_eq!(
        sim.brain.perceive(at, "greeted", vec![]),
        Err(PerceptError::NotPercept {
            name: "greeted".into()
        })
    );
    // A percept the program does not declare is harmless and simply unused.
    assert_eq!(
        sim.brain.perceive(at, "weather", vec![Value::from("rain")]),
        Ok(true)
    );
    assert!(sim.step().effects.is_empty());
}

#[test]
fn reload_keeps_beliefs_and_the_active_rule() {
    let before = r#"
        percept face(num, dir) fresh 5s
        belief greeted
        procedure main {
            greet: face(_, _) & not greeted ++ say("hello"), remember(greeted)
            watch: face(_, D) ~> publish("gaze", D)
            idle:  true ~> ()
        }
    "#;
    let mut sim = Sim::new(load(before));
    sim.perceive("face", vec![Value::Num(1.0), Value::from("left")]);
    assert_eq!(sim.said(), ["hello"]);
    assert_eq!(sim.brain.active()[0].rule, "watch");
    let running = sim.brain.running().to_vec();

    // A new version of the program: a different greeting and an extra rule below.
    let after = before
        .replace("say(\"hello\")", "say(\"hi there\")")
        .replace(
            "idle:  true ~> ()",
            "bored: true ~> say(\"la la\")\n            idle:  true ~> ()",
        );
    sim.brain.reload(load(&after));
    let effects = sim.step().effects;
    // Still greeted (the belief survived), still watching: nothing restarts or fires again.
    assert!(
        effects.is_empty(),
        "unexpected effects after reload: {effects:?}"
    );
    assert_eq!(sim.brain.running(), running.as_slice());
    assert_eq!(sim.said(), ["hello"]);

    // A version without the active rule moves on to the next one that holds.
    sim.brain.reload(load(
        &after.replace("watch: face(_, D) ~> publish(\"gaze\", D)\n", ""),
    ));
    let effects = sim.step().effects;
    assert_eq!(
        effects,
        vec![
            Effect::Stop(running[0].clone()),
            Effect::Start(say("la la"))
        ]
    );
}
