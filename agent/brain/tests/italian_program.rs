//! The Italian program `config/brain.it.tr` (`agent.language = "it"`): its answers to Italian phrases as Whisper
//! writes them, with the clock's words in Italian.

mod common;

use agent_brain::{Action, Effect, Language, Value};
use common::{Sim, ms, says, shipped_program};

/// A brain on the Italian program, with the clock at 15:15 on Thursday 29 February and nobody in view.
fn assistente() -> Sim {
    Sim::in_language(shipped_program("brain.it.tr"), Language::It)
}

/// Hears `text` in the given scene and returns the one sentence said.
fn risposta_in(scene: &[(&str, Vec<Value>)], text: &str) -> String {
    let mut sim = assistente();
    for (name, args) in scene {
        sim.perceive(name, args.clone());
    }
    sim.advance(ms(1000));
    let answer = says(&sim.hear(text));
    assert_eq!(answer.len(), 1, "one sentence for {text:?}, got {answer:?}");
    answer[0].clone()
}

fn risposta(text: &str) -> String {
    risposta_in(&[], text)
}

#[test]
fn the_italian_program_loads_with_the_rules_of_the_english_one() {
    let italian = shipped_program("brain.it.tr");
    let english = shipped_program("brain.tr");
    assert!(italian.rule_count() >= english.rule_count());
}

#[test]
fn the_time_and_the_date_are_told_in_italian() {
    for asked in ["Che ore sono?", "che ora è", "Sai l'ora?"] {
        assert_eq!(
            risposta(asked),
            "Sono le 3 e un quarto del pomeriggio.",
            "{asked}"
        );
    }
    assert_eq!(
        risposta("Che giorno è oggi?"),
        "Oggi è giovedì 29 febbraio."
    );
}

#[test]
fn people_codes_greetings_and_the_rest() {
    let face = |n: f64| ("face", vec![Value::Num(n), Value::from("centre")]);
    assert_eq!(
        risposta_in(&[face(2.0)], "Quante persone vedi?"),
        "Vedo 2 persone."
    );
    assert_eq!(
        risposta("Quante persone ci sono?"),
        "Non vedo nessuno in questo momento."
    );
    assert_eq!(
        risposta_in(
            &[("code", vec![Value::from("ciao mondo")])],
            "Leggi il codice"
        ),
        "Il codice dice: ciao mondo."
    );
    assert_eq!(risposta("Ciao"), "Ciao! Come posso aiutarti?");
    assert_eq!(risposta("Grazie mille"), "Prego.");
    assert_eq!(
        assistente().hear("Parlami del tempo"),
        vec![chat("Parlami del tempo", None)]
    );
}

const CONFUSO: &str = "Scusa, non ho capito. Puoi chiedermi l'ora, o cosa vedo.";

/// The effect of handing `text` to the language model, forced to call `tool` if one is given.
fn chat(text: &str, tool: Option<&str>) -> Effect {
    Effect::Fire(Action::Chat {
        text: text.into(),
        tool: tool.map(String::from),
    })
}

#[test]
fn without_a_language_model_the_italian_program_apologises() {
    let mut sim = assistente();
    sim.hear("Parlami del tempo");
    sim.advance(ms(100));
    let failed = sim.perceive("failed", vec![Value::from("chat"), Value::from("gone")]);
    assert_eq!(says(&failed), [CONFUSO]);
}

#[test]
fn dimentica_tutto_forgets_the_conversation_in_italian() {
    for asked in ["Dimentica la nostra conversazione.", "dimentica tutto"] {
        assert_eq!(
            assistente().hear(asked),
            vec![
                Effect::Fire(Action::ForgetConversation),
                Effect::Fire(Action::Say {
                    text: "D'accordo, ho dimenticato la nostra conversazione.".into()
                })
            ],
            "{asked}"
        );
    }
}

#[test]
fn girati_verso_is_a_tool_call_the_model_must_make() {
    for asked in [
        "Girati verso la finestra.",
        "guarda verso la porta",
        "gira la testa",
    ] {
        assert_eq!(
            assistente().hear(asked),
            vec![chat(asked, Some("Robot.command"))],
            "{asked}"
        );
    }
    let italian = shipped_program("brain.it.tr");
    let [tool] = italian.tools() else {
        panic!("one tool expected, got {:?}", italian.tools());
    };
    assert_eq!(
        (tool.service.as_str(), tool.description.as_str()),
        ("Robot.command", "gira la testa del robot")
    );
    assert_eq!(tool.args["direction"], ["left", "right"]);
}

#[test]
fn a_face_is_greeted_once_in_italian() {
    let mut sim = assistente();
    // A face turned to the agent, seen at 5 frames a second for a second (one detection alone is not greeted).
    for _ in 0..5 {
        sim.perceive("face", vec![Value::Num(1.0), Value::from("centre")]);
        sim.perceive("looking", vec![Value::Num(1.0)]);
        sim.advance(ms(200));
    }
    assert_eq!(
        sim.said(),
        ["Buongiorno! Piacere di vederti. Chiedimi pure."]
    );
}

#[test]
fn basta_stops_the_agent() {
    let mut sim = assistente();
    assert_eq!(sim.hear("Basta!"), vec![Effect::Fire(Action::Cancel)]);
}
