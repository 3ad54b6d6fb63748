//! The rule language's hand-over to a language model: `chat(T)`, `chat(T, "Service")`, `forget_conversation`
//! and the `tool` declarations that say which services the model may call.

mod common;

use agent_brain::{Action, Effect, LoadError, Program, ToolDecl, Value};
use common::{Sim, capabilities, load};

const HEAD: &str = "percept heard(text) event fresh 2s\n\
                    tool \"Robot.command\" \"turns the robot's head\" {action: [\"turn\"], direction: [\"left\", \"right\"]}\n";

/// A program whose `main` has the given rules after the declarations (`main` starts on line 3).
fn with_main(rules: &str) -> String {
    format!("{HEAD}procedure main {{\n{rules}\n}}\n")
}

fn error_of(source: &str) -> LoadError {
    match Program::load("bad.tr", source, &capabilities()) {
        Ok(_) => panic!("this program should not load:\n{source}"),
        Err(error) => error,
    }
}

/// Asserts the error's line, column and a message fragment: `at` is a piece of that line, with `^` just before
/// the character the error must point at (at its start without one).
fn expect_error(source: &str, line: u32, at: &str, fragment: &str) {
    let (before, after) = at.split_once('^').unwrap_or(("", at));
    let piece = format!("{before}{after}");
    let error = error_of(source);
    let Some(line_text) = source.lines().nth(line as usize - 1) else {
        panic!("no line {line}")
    };
    let Some(start) = line_text.find(&piece) else {
        panic!("{piece:?} is not on line {line}")
    };
    let col = line_text[..start + before.len()].chars().count() as u32 + 1;
    assert_eq!(
        (error.line, error.col),
        (line, col),
        "wrong place for: {error}"
    );
    assert!(
        error.message.contains(fragment),
        "message {:?} lacks {fragment:?}",
        error.message
    );
    assert!(
        error
            .to_string()
            .starts_with(&format!("bad.tr:{line}:{col}: "))
    );
}

/// What the program does on hearing `text`.
fn on_hearing(rules: &str, text: &str) -> Vec<Effect> {
    Sim::new(load(&with_main(rules))).hear(text)
}

#[test]
fn chat_without_a_tool_hands_the_words_to_the_model() {
    let effects = on_hearing("  c: heard(T) ++ chat(T), forget(heard)", "what is love");
    let chat = Action::Chat {
        text: "what is love".into(),
        tool: None,
    };
    assert_eq!(effects, vec![Effect::Fire(chat.clone())]);
    assert_eq!(chat.to_string(), "chat(\"what is love\")");
}

#[test]
fn chat_with_a_declared_tool_names_the_tool() {
    let effects = on_hearing(
        "  c: heard(T) ++ chat(\"{T}!\", \"Robot.command\"), forget(heard)",
        "face the door",
    );
    let chat = Action::Chat {
        text: "face the door!".into(),
        tool: Some("Robot.command".into()),
    };
    assert_eq!(effects, vec![Effect::Fire(chat.clone())]);
    assert_eq!(
        chat.to_string(),
        "chat(\"face the door!\", \"Robot.command\")"
    );
}

#[test]
fn forget_conversation_fires_once() {
    let effects = on_hearing(
        "  f: heard(T) ++ forget_conversation, forget(heard)",
        "forget it",
    );
    assert_eq!(effects, vec![Effect::Fire(Action::ForgetConversation)]);
    assert_eq!(
        Action::ForgetConversation.to_string(),
        "forget_conversation"
    );
}

#[test]
fn chat_actions_serialise_with_the_action_tag() -> Result<(), serde_json::Error> {
    let chat = Action::Chat {
        text: "hi".into(),
        tool: Some("Robot.command".into()),
    };
    assert_eq!(
        serde_json::to_value(&chat)?,
        serde_json::json!({"action": "chat", "text": "hi", "tool": "Robot.command"})
    );
    assert_eq!(
        serde_json::to_value(Action::ForgetConversation)?,
        serde_json::json!({"action": "forget_conversation"})
    );
    Ok(())
}

#[test]
fn chat_naming_an_undeclared_tool_is_rejected_where_the_tool_is_named() {
    expect_error(
        &with_main("  c: heard(T) ++ chat(T, \"Robot.dance\")"),
        4,
        "\"Robot.dance\"",
        "tool `Robot.dance` is not declared",
    );
    expect_error(
        &with_main("  c: heard(T) ++ chat(T, T)"),
        4,
        "chat(T, ^T)",
        "plain string naming a declared tool",
    );
}

#[test]
fn chat_takes_one_or_two_arguments_and_only_after_the_discrete_arrow() {
    expect_error(
        &with_main("  c: heard(T) ++ chat()"),
        4,
        "chat",
        "`chat` takes 1 to 2 argument(s), but 0 are given",
    );
    expect_error(
        &with_main("  c: heard(T) ~> chat(T)"),
        4,
        "chat",
        "happens once",
    );
    expect_error(
        &with_main("  c: heard(T) ++ forget_conversation(T)"),
        4,
        "forget_conversation",
        "takes 0 argument(s)",
    );
    expect_error(
        &with_main("  c: heard(T) ++ chat(X)"),
        4,
        "X",
        "variable `X` is used before it is bound",
    );
}

#[test]
fn a_tool_argument_with_no_values_is_rejected() {
    expect_error(
        "tool \"Robot.command\" \"turns\" {action: [\"turn\"], direction: []}\nprocedure main { idle: true ~> () }\n",
        1,
        "[]",
        "argument `direction` of tool `Robot.command` needs at least one value",
    );
}

#[test]
fn a_tool_argument_named_twice_is_rejected() {
    expect_error(
        "tool \"Robot.command\" \"turns\" {action: [\"turn\"], action: [\"nod\"]}\nprocedure main { idle: true ~> () }\n",
        1,
        "action: [\"nod\"]",
        "argument `action` of tool `Robot.command` appears twice",
    );
}

#[test]
fn a_tool_declared_twice_is_rejected() {
    expect_error(
        &format!(
            "{HEAD}tool \"Robot.command\" \"again\" {{action: [\"nod\"]}}\nprocedure main {{ idle: true ~> () }}\n"
        ),
        3,
        "tool",
        "tool `Robot.command` is already declared at line 2",
    );
}

#[test]
fn a_tool_declaration_needs_quoted_strings() {
    expect_error(
        "tool Robot \"turns\" {action: [\"turn\"]}\nprocedure main { idle: true ~> () }\n",
        1,
        "Robot",
        "the tool's service as a string",
    );
    expect_error(
        "tool \"Robot.command\" \"turns\" {action: [turn]}\nprocedure main { idle: true ~> () }\n",
        1,
        "turn]",
        "a value as a string",
    );
}

#[test]
fn the_program_lists_its_tools_in_source_order() {
    let program = load(&format!(
        "{HEAD}tool \"Lights.set\" \"switches the lights\" {{}}\n\
         procedure main {{ c: heard(T) ++ chat(T, \"Lights.set\") }}\n"
    ));
    let services: Vec<&str> = program
        .tools()
        .iter()
        .map(|tool: &ToolDecl| tool.service.as_str())
        .collect();
    assert_eq!(services, ["Robot.command", "Lights.set"]);
    let robot = &program.tools()[0];
    assert_eq!(robot.description, "turns the robot's head");
    assert_eq!(
        robot.args.iter().collect::<Vec<_>>(),
        [
            (&"action".to_owned(), &vec!["turn".to_owned()]),
            (
                &"direction".to_owned(),
                &vec!["left".to_owned(), "right".to_owned()]
            ),
        ]
    );
    assert_eq!((robot.pos.line, robot.pos.col), (2, 1));
    assert!(program.tools()[1].args.is_empty());
    // Nothing is lost on the way: the values are plain text the host can offer the model.
    assert!(robot.args["direction"].contains(&Value::from("left").to_string()));
}
