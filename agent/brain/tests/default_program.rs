//! The default program `config/brain.tr`: its answers to each phrase (as ASR writes them, in several wordings),
//! greeting once per appearance, commands and service calls, and hot reload of the real file.

mod common;

use std::time::Duration;

use agent_brain::{Action, Effect, Value};
use common::{Sim, default_program, default_program_source, load, ms, says};

/// A brain on the default program, with the clock at 15:15 and nobody in view.
fn assistant() -> Sim {
    Sim::new(default_program())
}

/// Hears `text` on a fresh assistant in the given scene, and returns the one sentence it says.
fn answer_in(scene: &[(&str, Vec<Value>)], text: &str) -> String {
    let mut sim = assistant();
    for (name, args) in scene {
        sim.perceive(name, args.clone());
    }
    // Let any greeting for the scene happen first, so that only the answer is left.
    sim.advance(ms(1000));
    let answer = says(&sim.hear(text));
    assert_eq!(
        answer.len(),
        1,
        "expected one sentence for {text:?}, got {answer:?}"
    );
    answer[0].clone()
}

fn answer(text: &str) -> String {
    answer_in(&[], text)
}

fn face(n: f64) -> (&'static str, Vec<Value>) {
    ("face", vec![Value::Num(n), Value::from("centre")])
}

fn code(text: &str) -> (&'static str, Vec<Value>) {
    ("code", vec![Value::from(text)])
}

#[test]
fn the_default_program_loads() {
    let program = default_program();
    assert!(program.rule_count() > 20);
}

#[test]
fn what_time_is_it_in_several_wordings() {
    for asked in [
        "What time is it?",
        "what's the time",
        "What's the time, please?",
        " what time is it",
        "Tell me the time.",
    ] {
        assert_eq!(
            answer(asked),
            "It is quarter past 3 in the afternoon.",
            "asked {asked:?}"
        );
    }
}

#[test]
fn how_many_people() {
    for asked in [
        "How many people do you see?",
        "how many persons are there",
        "How many faces can you see",
    ] {
        assert_eq!(
            answer_in(&[face(2.0)], asked),
            "I can see 2 people.",
            "asked {asked:?}"
        );
        assert_eq!(answer_in(&[face(1.0)], asked), "I can see 1 person.");
        assert_eq!(answer(asked), "I can't see anyone right now.");
    }
}

#[test]
fn what_do_you_see() {
    for asked in [
        "What do you see?",
        "what can you see",
        "What do you see right now?",
    ] {
        assert_eq!(
            answer_in(&[face(1.0)], asked),
            "I see 1 person in front of me."
        );
        assert_eq!(
            answer_in(&[face(3.0), code("https://example.org")], asked),
            "I see 3 people and a code that says: https://example.org."
        );
        assert_eq!(
            answer_in(&[code("ABC-123")], asked),
            "I see a code that says: ABC-123."
        );
        assert_eq!(
            answer_in(&[("motion", vec![Value::from("left")])], asked),
            "Nobody is here, but something is moving on the left."
        );
        assert_eq!(
            answer_in(&[("motion", vec![Value::from("centre")])], asked),
            "Nobody is here, but something is moving in front of me."
        );
        assert_eq!(answer(asked), "I don't see anything special right now.");
    }
}

#[test]
fn read_the_code() {
    for asked in [
        "Read the code.",
        "can you read this QR code",
        "What does the code say?",
    ] {
        assert_eq!(
            answer_in(&[code("HELLO 42")], asked),
            "The code says: HELLO 42."
        );
        assert_eq!(
            answer(asked),
            "I don't see any code. Hold it up to the camera, please."
        );
    }
}

#[test]
fn a_code_seen_a_few_seconds_ago_can_still_be_read() {
    let mut sim = assistant();
    sim.perceive("code", vec![Value::from("LATE")]);
    sim.advance(Duration::from_secs(6));
    assert_eq!(says(&sim.hear("read the code")), ["The code says: LATE."]);
    sim.advance(Duration::from_secs(6));
    assert_eq!(
        says(&sim.hear("read the code")),
        ["I don't see any code. Hold it up to the camera, please."]
    );
}

#[test]
fn repeat_that() {
    assert_eq!(answer("Repeat that."), "I haven't said anything yet.");
    let mut sim = assistant();
    sim.hear("what time is it");
    sim.advance(ms(3000));
    for asked in ["Can you repeat that?", "say that again", "Pardon?"] {
        assert_eq!(
            says(&sim.hear(asked)),
            ["It is quarter past 3 in the afternoon."],
            "asked {asked:?}"
        );
        sim.advance(ms(3000));
    }
}

#[test]
fn stop_cancels_speech() {
    for asked in [
        "Stop!",
        "stop talking",
        "Please stop.",
        "be quiet",
        "Shut up.",
    ] {
        let mut sim = assistant();
        sim.hear("what time is it");
        sim.perceive("speaking", vec![]);
        assert_eq!(
            sim.hear(asked),
            vec![Effect::Fire(Action::Cancel)],
            "asked {asked:?}"
        );
    }
    // "stop" inside another request is not a command to stop.
    assert_eq!(
        assistant().hear("don't stop me now"),
        vec![chat("don't stop me now", None)]
    );
}

/// The effect of handing `text` to the language model, forced to call `tool` if one is given.
fn chat(text: &str, tool: Option<&str>) -> Effect {
    Effect::Fire(Action::Chat {
        text: text.into(),
        tool: tool.map(String::from),
    })
}

#[test]
fn anything_else_is_handed_to_the_language_model() {
    for asked in [
        "Blue elephants are dancing.",
        "what is the capital of France",
    ] {
        assert_eq!(assistant().hear(asked), vec![chat(asked, None)]);
    }
    // Transcripts of silence or noise get no answer at all.
    let mut sim = assistant();
    assert!(sim.hear("[BLANK_AUDIO]").is_empty());
    assert!(sim.hear(" (music) ").is_empty());
}

#[test]
fn whitelisted_commands_run_and_their_output_is_spoken() {
    let mut sim = assistant();
    let effects = sim.hear("How long have you been running?");
    assert_eq!(
        effects,
        vec![
            Effect::Fire(Action::Say {
                text: "Let me check.".into()
            }),
            Effect::Fire(Action::Run {
                command: "uptime".into()
            })
        ]
    );
    sim.advance(ms(300));
    let told = sim.perceive(
        "output",
        vec![Value::from("uptime"), Value::from("up 2 hours, 5 minutes")],
    );
    assert_eq!(says(&told), ["up 2 hours, 5 minutes"]);
    sim.advance(ms(3000));
    assert_eq!(
        sim.hear("what machine are you on"),
        vec![Effect::Fire(Action::Run {
            command: "hostname".into()
        })]
    );
    let failed = sim.perceive(
        "failed",
        vec![Value::from("hostname"), Value::from("it timed out")],
    );
    assert_eq!(
        says(&failed),
        ["Sorry, hostname did not work: it timed out."]
    );
}

#[test]
fn remote_satellite_services_are_called_and_their_reply_spoken() {
    let mut sim = assistant();
    let effects = sim.hear("Turn left, please.");
    let payload = Value::Map(vec![
        ("action".into(), Value::from("turn")),
        ("direction".into(), Value::from("left")),
    ]);
    assert_eq!(
        effects,
        vec![Effect::Fire(Action::Call {
            service: "Robot.command".into(),
            payload
        })]
    );
    sim.advance(ms(200));
    let replied = sim.perceive(
        "reply",
        vec![Value::from("Robot.command"), Value::from("Turning left.")],
    );
    assert_eq!(says(&replied), ["Turning left."]);
}

#[test]
fn when_no_language_model_serves_the_agent_apologises_as_before() {
    let mut sim = assistant();
    sim.hear("what is the capital of France");
    sim.advance(ms(100));
    let failed = sim.perceive("failed", vec![Value::from("chat"), Value::from("gone")]);
    assert_eq!(says(&failed), [CONFUSED]);
    // The failure is dealt with once.
    sim.advance(ms(3000));
    assert_eq!(sim.said(), [CONFUSED]);
}

#[test]
fn forget_our_conversation_forgets_the_chat_memory() {
    for asked in [
        "Forget our conversation.",
        "please forget what we said",
        "Forget everything!",
    ] {
        assert_eq!(
            assistant().hear(asked),
            vec![
                Effect::Fire(Action::ForgetConversation),
                Effect::Fire(Action::Say {
                    text: "All right, I have forgotten our conversation.".into()
                })
            ],
            "asked {asked:?}"
        );
    }
}

#[test]
fn turning_towards_something_is_a_tool_call_the_model_must_make() {
    for asked in [
        "Face the window.",
        "look towards the door",
        "turn your head to the left a bit",
    ] {
        assert_eq!(
            assistant().hear(asked),
            vec![chat(asked, Some("Robot.command"))],
            "asked {asked:?}"
        );
    }
    // The exact phrases stay on the rule path.
    assert!(matches!(
        assistant().hear("turn left").as_slice(),
        [Effect::Fire(Action::Call { .. })]
    ));
}

#[test]
fn the_default_program_declares_the_robot_command_tool() {
    let program = default_program();
    let [tool] = program.tools() else {
        panic!("one tool expected, got {:?}", program.tools());
    };
    assert_eq!(tool.service, "Robot.command");
    assert_eq!(tool.description, "turns the robot's head");
    assert_eq!(tool.args["action"], ["turn"]);
    assert_eq!(tool.args["direction"], ["left", "right"]);
}

/// Face frames at 15 fps for `seconds`, of a person turned to the agent.
fn person_in_view(sim: &mut Sim, seconds: u64) {
    for _ in 0..seconds * 15 {
        sim.perceive("face", vec![Value::Num(1.0), Value::from("centre")]);
        sim.perceive("looking", vec![Value::Num(1.0)]);
        sim.advance(ms(66));
    }
}

#[test]
fn a_person_who_looks_elsewhere_is_not_greeted_until_they_look() {
    let mut sim = assistant();
    for _ in 0..45 {
        sim.perceive("face", vec![Value::Num(1.0), Value::from("left")]);
        sim.advance(ms(66));
    }
    assert!(sim.said().is_empty(), "{:?}", sim.said());
    person_in_view(&mut sim, 2);
    assert_eq!(sim.said(), [GREETING]);
}

#[test]
fn a_smile_is_smiled_back_once_a_visit() {
    let mut sim = assistant();
    person_in_view(&mut sim, 2);
    for _ in 0..60 {
        sim.perceive("face", vec![Value::Num(1.0), Value::from("centre")]);
        sim.perceive("looking", vec![Value::Num(1.0)]);
        sim.perceive("smiling", vec![]);
        sim.advance(ms(66));
    }
    let moods: Vec<Effect> = sim
        .effects
        .iter()
        .map(|(_, e)| e.clone())
        .filter(|e| matches!(e.action(), Action::Mood { .. }))
        .collect();
    assert_eq!(
        moods,
        vec![Effect::Fire(Action::Mood {
            mood: "happy".into()
        })]
    );
}

#[test]
fn a_known_face_is_greeted_by_name() {
    let mut sim = assistant();
    for _ in 0..30 {
        sim.perceive("face", vec![Value::Num(1.0), Value::from("centre")]);
        sim.perceive("looking", vec![Value::Num(1.0)]);
        sim.perceive("acquaintance", vec![Value::from("Anna")]);
        sim.advance(ms(66));
    }
    assert_eq!(sim.said(), ["Good afternoon, Anna! Nice to see you again."]);
    assert_eq!(says(&sim.hear("Do you know me?")), ["You are Anna."]);
}

#[test]
fn my_name_is_learns_the_face_and_forget_me_forgets_it() {
    let mut sim = assistant();
    let effects = sim.hear("Hi, my name is Anna.");
    assert_eq!(
        effects,
        vec![Effect::Fire(Action::LearnFace {
            name: "anna".into()
        })]
    );
    sim.advance(ms(200));
    let replied = sim.perceive(
        "reply",
        vec![Value::from("learn_face"), Value::from("Anna")],
    );
    assert_eq!(
        says(&replied),
        ["Nice to meet you, Anna. I will remember your face."]
    );
    sim.advance(ms(3000));
    assert_eq!(
        sim.hear("Please forget me."),
        vec![Effect::Fire(Action::ForgetFace)]
    );
    sim.advance(ms(200));
    let failed = sim.perceive(
        "failed",
        vec![Value::from("forget_face"), Value::from("not known")],
    );
    assert_eq!(says(&failed), ["I have not stored your face."]);
    // Nothing is learned without being asked.
    sim.advance(ms(3000));
    let asked = sim.hear("What is my name?");
    assert_eq!(
        says(&asked),
        ["I don't know you yet. Tell me your name, and I will remember your face."]
    );
}

const CONFUSED: &str = "Sorry, I did not understand. You can ask me the time, or what I see.";

const GREETING: &str = "Good afternoon! Nice to see you. Ask me anything.";

#[test]
fn greets_a_person_once_per_appearance() {
    let mut sim = assistant();
    person_in_view(&mut sim, 10);
    assert_eq!(sim.said(), [GREETING]);
    // A detection dropout of a few seconds is the same visit.
    sim.advance(Duration::from_secs(4));
    person_in_view(&mut sim, 3);
    assert_eq!(sim.said(), [GREETING]);
    // After leaving for a while, coming back is a new appearance.
    sim.advance(Duration::from_secs(30));
    person_in_view(&mut sim, 3);
    assert_eq!(sim.said(), [GREETING, GREETING]);
}

#[test]
fn a_single_false_detection_is_not_greeted() {
    let mut sim = assistant();
    sim.perceive("face", vec![Value::Num(1.0), Value::from("left")]);
    sim.advance(Duration::from_secs(5));
    assert!(sim.said().is_empty());
}

#[test]
fn does_not_greet_while_speaking_or_someone_who_already_talks() {
    let mut sim = assistant();
    sim.perceive("speaking", vec![]);
    person_in_view(&mut sim, 2);
    assert!(sim.said().is_empty());
    sim.retract("speaking");
    assert_eq!(sim.said(), [GREETING]);

    let mut sim = assistant();
    sim.hear("what time is it");
    person_in_view(&mut sim, 5);
    assert_eq!(sim.said(), ["It is quarter past 3 in the afternoon."]);
}

#[test]
fn questions_are_answered_while_a_person_is_in_view() {
    let mut sim = assistant();
    person_in_view(&mut sim, 2);
    sim.hear("how many people do you see");
    person_in_view(&mut sim, 3);
    sim.hear("what's the time");
    person_in_view(&mut sim, 3);
    assert_eq!(
        sim.said(),
        [
            GREETING,
            "I can see 1 person.",
            "It is quarter past 3 in the afternoon."
        ]
    );
}

#[test]
fn hot_reload_of_the_file_keeps_state() {
    let mut sim = assistant();
    person_in_view(&mut sim, 2);
    sim.hear("what time is it");
    let active = sim.brain.active();
    // The edited file: a new wording for the greeting and for the time.
    let edited = default_program_source()
        .replace("Nice to see you. Ask me anything.", "Welcome back.")
        .replace("It is {time.spoken}.", "The time is {time.spoken}.");
    sim.brain.reload(load(&edited));
    assert!(
        sim.step().effects.is_empty(),
        "a reload must not fire the active rule again"
    );
    assert_eq!(sim.brain.active(), active);
    // The person is still greeted (no second greeting); new questions use the new wording.
    person_in_view(&mut sim, 3);
    sim.hear("what time is it");
    assert_eq!(
        sim.said(),
        [
            GREETING,
            "It is quarter past 3 in the afternoon.",
            "The time is quarter past 3 in the afternoon."
        ]
    );
}

#[test]
fn the_trace_names_the_transcript_even_though_the_rule_forgets_it() {
    let mut sim = assistant();
    sim.hear("What time is it?");
    let Some(trace) = sim.traces.iter().find(|t| t.path.len() == 2) else {
        panic!("no trace into `answer`")
    };
    let path: Vec<String> = trace.path.iter().map(ToString::to_string).collect();
    assert_eq!(path, ["main.converse", "answer.time"]);
    assert_eq!(trace.because[0].fact, r#"heard("What time is it?")"#);
    assert_eq!(
        trace.updates,
        [
            "remember(greeted)",
            "forget(asked)",
            r#"remember(asked("What time is it?"))"#,
            "forget(heard)"
        ]
    );
}

#[test]
fn what_was_asked_is_answered_from_the_last_question() {
    let mut sim = assistant();
    sim.advance(ms(1000));
    assert_eq!(
        says(&sim.hear("What did I just ask you?")),
        ["You haven't asked me anything yet."]
    );
    sim.hear("What time is it?");
    sim.advance(ms(1000));
    assert_eq!(
        says(&sim.hear("What did I just ask?")),
        ["You asked: What time is it?"]
    );
    // The follow-up itself is not a question to remember.
    assert_eq!(
        says(&sim.hear("What was my question?")),
        ["You asked: What time is it?"]
    );
}

#[test]
fn the_fixed_sayings_are_the_replies_said_word_for_word_each_once() {
    let sayings = default_program().fixed_sayings();
    for fixed in [
        "Hello! How can I help you?",
        "You're welcome.",
        "Let me think.",
        "I can't see anyone right now.",
    ] {
        assert!(
            sayings.iter().any(|s| s == fixed),
            "{fixed:?} not in {sayings:?}"
        );
    }
    // Replies with holes are made when they are said.
    assert!(sayings.iter().all(|s| !s.contains('{')), "{sayings:?}");
    assert!(
        !sayings.iter().any(|s| s.starts_with("It is ")),
        "{sayings:?}"
    );
    let mut unique = sayings.clone();
    unique.sort();
    unique.dedup();
    assert_eq!(unique.len(), sayings.len(), "{sayings:?}");
    // And they are the answers the brain gives: "thank you" is answered with one of them.
    assert!(sayings.contains(&answer("thank you")), "{sayings:?}");
}
