//! Programs that must not load: each error names the right line and column and says why.

mod common;

use agent_brain::{LoadError, Program};
use common::capabilities;

fn error_of(source: &str) -> LoadError {
    match Program::load("bad.tr", source, &capabilities()) {
        Ok(_) => panic!("this program should not load:\n{source}"),
        Err(error) => error,
    }
}

/// Asserts the error's line, a fragment of its message, and its column: `at` is a piece of that line with `^`
/// just before the character the error must point at.
fn expect(source: &str, line: u32, at: &str, fragment: &str) {
    let error = error_of(source);
    let Some(line_text) = source.lines().nth(line as usize - 1) else {
        panic!("no line {line}")
    };
    let (before, after) = at.split_once('^').unwrap_or(("", at));
    let piece = format!("{before}{after}");
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
}

const HEAD: &str = "percept heard(text) event fresh 2s\npercept face(num, dir)\nbelief greeted\n";

fn with_main(rules: &str) -> String {
    format!("{HEAD}procedure main {{\n{rules}\n}}\n")
}

#[test]
fn syntax_errors() {
    // Line 5 is the first rule line after the three declarations and `procedure main {`.
    expect(
        &with_main("  a: heard(T ++ say(T)"),
        5,
        "^++",
        "expected `)` to close the arguments",
    );
    expect(
        &with_main("  a: heard(T) say(T)"),
        5,
        "^say",
        "expected `~>`",
    );
    expect(
        &with_main("  heard(T) ++ say(T)"),
        5,
        "^heard",
        "expected a rule label",
    );
    expect(
        &with_main("  a: heard(T) ++ say(\"hi)"),
        5,
        "^\"hi",
        "string is not closed",
    );
    expect(
        &with_main("  a: face(_, _) for 2x ++ say(\"hi\")"),
        5,
        "^2x",
        "unknown duration unit `x`",
    );
    expect(
        &with_main("  a: face(_, _) within ++ say(\"hi\")"),
        5,
        "^++",
        "expected a duration",
    );
    expect(
        &with_main("  a: true ++ say(\"{time.hhmm\")"),
        5,
        "^{time",
        "no closing `}`",
    );
    expect(
        &with_main("  a: true ++ say(\"It is {time.nope}.\")"),
        5,
        "{^time.nope",
        "unknown field `time.nope`",
    );
    expect(
        "procedure main {\n  a: true ++ say(\"x\")\n",
        1,
        "^procedure",
        "not closed",
    );
    expect(
        "when x",
        1,
        "^when",
        "expected `percept`, `belief`, `tool` or `procedure`",
    );
    expect(
        &with_main("  a: true ++ say(\"x\") $"),
        5,
        "^$",
        "unexpected character `$`",
    );
}

#[test]
fn meaning_errors() {
    expect(
        &with_main("  a: seen(X) ++ say(X)"),
        5,
        "^seen",
        "unknown predicate `seen`",
    );
    expect(
        &with_main("  a: face(N) ++ say(N)"),
        5,
        "^face",
        "`face` takes 2 argument(s) (declared at line 2)",
    );
    expect(
        &with_main("  a: heard(T) ++ say(\"{X}\")"),
        5,
        "{^X}",
        "variable `X` is used before it is bound",
    );
    expect(
        &with_main("  a: T ~ \"hi\" & heard(T) ++ say(T)"),
        5,
        "^T ~",
        "variable `T` is used before it is bound",
    );
    expect(
        &with_main("  a: not heard(T) ++ say(T)"),
        5,
        "say(^T)",
        "variable `T`",
    );
    expect(
        &with_main("  a: true ++ run(\"rm\")"),
        5,
        "^\"rm\"",
        "command `rm` is not on the host's whitelist (whitelisted: hostname, uptime)",
    );
    expect(
        &with_main("  a: heard(T) ++ run(T)"),
        5,
        "run(^T)",
        "plain string",
    );
    expect(
        &with_main("  a: true ~> cancel"),
        5,
        "^cancel",
        "put it after `++`",
    );
    expect(
        &with_main("  a: true ++ remember(heard(\"x\"))"),
        5,
        "^heard(",
        "only beliefs",
    );
    expect(
        &with_main("  a: true ++ shout(\"x\")"),
        5,
        "^shout",
        "unknown action or procedure `shout`",
    );
    expect(
        &with_main("  a: true ++ say(\"x\")\n  a: true ++ say(\"y\")"),
        6,
        "^a:",
        "rule `a` is already defined at line 5",
    );
    expect(
        &with_main("  a: heard(T) & T ~ \"\" ++ say(T)"),
        5,
        "^\"\"",
        "empty phrase",
    );
    expect(
        &with_main("  a: heard(T) & db(T) = 1 ++ say(T)"),
        5,
        "db(^T)",
        "plain string",
    );
    expect(
        &with_main("  a: plural(1) > 0 ++ say(\"x\")"),
        5,
        "^plural",
        "`plural` takes 3 argument(s)",
    );
    expect(
        &format!("{HEAD}percept face(num)\nprocedure main {{ a: true ~> () }}"),
        4,
        "^face",
        "already declared at line 2",
    );
    expect(
        "procedure other { a: true ~> () }",
        1,
        "^procedure",
        "no `procedure main",
    );
    let cycle = "procedure main { a: true ~> b() }\nprocedure b { x: true ~> main() }";
    expect(cycle, 2, "^main()", "would call itself");
    expect(
        "procedure main { a: true ++ b() }\nprocedure b { x: true ~> () }",
        1,
        "^b()",
        "only be called after `~>`",
    );
}

#[test]
fn the_error_display_points_at_the_column() {
    let error = error_of(&with_main("  greet: face(N) ++ say(N)"));
    let shown = error.to_string();
    let lines: Vec<&str> = shown.lines().collect();
    assert_eq!(
        lines[0],
        "bad.tr:5:10: `face` takes 2 argument(s) (declared at line 2), but 1 are given here"
    );
    assert_eq!(lines[1], "  |   greet: face(N) ++ say(N)");
    assert_eq!(lines[2], "  |          ^");
}
