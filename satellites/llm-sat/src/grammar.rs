//! Constrained decoding so that every tool call the model writes parses: the grammar (llama.cpp's GBNF) and the
//! JSON schema (an OpenAI-compatible endpoint's `response_format`) of a call, and the call read back and checked.
//!
//! Two shapes of call: a forced call is the arguments object alone (`{"action": "turn"}`, the rule named the
//! tool); an offered call is `{"tool": "<service>", "args": {...}}` beside a free spoken reply. An endpoint takes a
//! JSON schema, which cannot say "text or an object", so the endpoint generator offers tools only when one is forced
//! (the schema of [`reply_or_call`] describes its call objects alone).

use agent_contract::chat::{Tool, ToolCall};
use serde_json::{Map, Value, json};

use crate::generator::Constraint;

/// Optional single spaces between JSON tokens, as llama.cpp's JSON grammars allow (kept to one, so that a model
/// cannot spend its tokens on whitespace).
const WS: &str = "ws ::= [ ]?";
/// Any JSON string, for an argument whose values are not listed (as llama.cpp's `json.gbnf` writes it).
const STRING: &str = r#"string ::= "\"" ( [^"\\\x7F\x00-\x1F] | "\\" ( ["\\/bfnrt] | "u" [0-9a-fA-F] [0-9a-fA-F] [0-9a-fA-F] [0-9a-fA-F] ) )* "\"""#;

/// Why the model's text is not a call of the tools offered.
#[derive(Debug, thiserror::Error)]
pub enum GrammarError {
    #[error("the call is not JSON: {0}")]
    NotJson(#[from] serde_json::Error),
    #[error("the call is not a JSON object")]
    NotObject,
    #[error("no tool was offered")]
    NoTools,
    #[error("no tool {0:?} was offered")]
    UnknownTool(String),
    #[error("the call of {tool} lacks the argument {arg:?}")]
    MissingArg { tool: String, arg: String },
    #[error("{tool} has no argument {arg:?}")]
    ExtraArg { tool: String, arg: String },
    #[error("the argument {arg:?} of {tool} is not text")]
    NotText { tool: String, arg: String },
    #[error("{value:?} is not one of the values of the argument {arg:?} of {tool}")]
    NotAllowed {
        tool: String,
        arg: String,
        value: String,
    },
}

/// The constraint of a forced call of `tool`: exactly its arguments object, every argument in the tool's order,
/// each value one of those listed (any text where none are).
pub fn forced_call(tool: &Tool) -> Constraint {
    let mut values = Vec::new();
    let object = args_object(tool, "a", &mut values);
    let mut rules = vec![format!("root ::= {object}")];
    rules.extend(values);
    rules.push(WS.to_owned());
    if needs_string(tool) {
        rules.push(STRING.to_owned());
    }
    Constraint {
        gbnf: rules.join("\n") + "\n",
        schema: args_schema(tool),
    }
}

/// The constraint of a turn with tools offered: a spoken reply (one line that starts with neither `{` nor a space)
/// or a call object `{"tool": "<service>", "args": {...}}` of one of `tools`.
pub fn reply_or_call(tools: &[Tool]) -> Constraint {
    let mut rules = Vec::new();
    let mut calls = Vec::new();
    for (n, tool) in tools.iter().enumerate() {
        let name = format!("t{n}");
        let object = args_object(tool, &name, &mut rules);
        rules.push(format!(
            r#"{name} ::= {} ws "," ws "\"args\"" ws ":" ws {object}"#,
            literal(&json_text(&tool.service))
        ));
        calls.push(name);
    }
    let mut head = vec![
        r"root ::= reply | call".to_owned(),
        r"reply ::= [^{ \t\r\n] [^\r\n]*".to_owned(),
    ];
    if calls.is_empty() {
        head[0] = "root ::= reply".to_owned();
    } else {
        head.push(format!(
            r#"call ::= "{{" ws "\"tool\"" ws ":" ws ( {} ) ws "}}""#,
            calls.join(" | ")
        ));
    }
    head.extend(rules);
    head.push(WS.to_owned());
    if tools.iter().any(needs_string) {
        head.push(STRING.to_owned());
    }
    let schemas: Vec<Value> = tools
        .iter()
        .map(|tool| {
            json!({
                "type": "object",
                "properties": {"tool": {"type": "string", "enum": [tool.service]}, "args": args_schema(tool)},
                "required": ["tool", "args"],
                "additionalProperties": false,
            })
        })
        .collect();
    Constraint {
        gbnf: head.join("\n") + "\n",
        schema: json!({ "anyOf": schemas }),
    }
}

/// Reads the model's `text` as a call of one of `tools`: the `{"tool": ..., "args": {...}}` object, or, when one
/// tool alone is given (a forced call), its arguments object. Every argument must be there, with a listed value,
/// and no other.
pub fn parse_call(tools: &[Tool], text: &str) -> Result<ToolCall, GrammarError> {
    let value: Value = serde_json::from_str(text.trim())?;
    let Value::Object(object) = value else {
        return Err(GrammarError::NotObject);
    };
    let wrapped = object.len() == 2
        && object.get("tool").is_some_and(Value::is_string)
        && object.get("args").is_some_and(Value::is_object);
    let offered_by_name = |name: &str| tools.iter().find(|t| t.service == name);
    let (tool, args) = match (wrapped, tools) {
        (_, []) => return Err(GrammarError::NoTools),
        (true, _) => {
            let name = object
                .get("tool")
                .and_then(Value::as_str)
                .unwrap_or_default();
            // A lone tool whose own arguments are `tool` and `args` is called with its arguments object.
            match offered_by_name(name) {
                Some(tool) => (
                    tool,
                    object
                        .get("args")
                        .and_then(Value::as_object)
                        .cloned()
                        .unwrap_or_default(),
                ),
                None if tools.len() == 1 && is_args_of(&tools[0], &object) => (&tools[0], object),
                None => return Err(GrammarError::UnknownTool(name.to_owned())),
            }
        }
        (false, [tool]) => (tool, object),
        (false, _) => return Err(GrammarError::UnknownTool(String::new())),
    };
    check_args(tool, &args)?;
    Ok(ToolCall {
        service: tool.service.clone(),
        payload: Value::Object(args),
    })
}

fn is_args_of(tool: &Tool, object: &Map<String, Value>) -> bool {
    object.keys().all(|k| tool.args.contains_key(k))
}

fn check_args(tool: &Tool, args: &Map<String, Value>) -> Result<(), GrammarError> {
    let named = |arg: &str| (tool.service.clone(), arg.to_owned());
    if let Some(extra) = args.keys().find(|k| !tool.args.contains_key(*k)) {
        let (tool, arg) = named(extra);
        return Err(GrammarError::ExtraArg { tool, arg });
    }
    for (arg, allowed) in &tool.args {
        let (tool_name, arg_name) = named(arg);
        let value = match args.get(arg) {
            None => {
                return Err(GrammarError::MissingArg {
                    tool: tool_name,
                    arg: arg_name,
                });
            }
            Some(Value::String(value)) => value,
            Some(_) => {
                return Err(GrammarError::NotText {
                    tool: tool_name,
                    arg: arg_name,
                });
            }
        };
        if !allowed.is_empty() && !allowed.contains(value) {
            return Err(GrammarError::NotAllowed {
                tool: tool_name,
                arg: arg_name,
                value: value.clone(),
            });
        }
    }
    Ok(())
}

/// The GBNF of `tool`'s arguments object; the rule of each argument's values is added to `rules`, named after
/// `prefix`.
fn args_object(tool: &Tool, prefix: &str, rules: &mut Vec<String>) -> String {
    if tool.args.is_empty() {
        return r#""{" ws "}""#.to_owned();
    }
    let mut members = Vec::new();
    for (n, (arg, allowed)) in tool.args.iter().enumerate() {
        let rule = format!("{prefix}-v{n}");
        let values = if allowed.is_empty() {
            "string".to_owned()
        } else {
            let alternatives: Vec<String> =
                allowed.iter().map(|v| literal(&json_text(v))).collect();
            alternatives.join(" | ")
        };
        rules.push(format!("{rule} ::= {values}"));
        members.push(format!(r#"{} ws ":" ws {rule}"#, literal(&json_text(arg))));
    }
    format!(r#""{{" ws {} ws "}}""#, members.join(r#" ws "," ws "#))
}

fn needs_string(tool: &Tool) -> bool {
    tool.args.values().any(Vec::is_empty)
}

/// The JSON schema of `tool`'s arguments object.
fn args_schema(tool: &Tool) -> Value {
    let properties: Map<String, Value> = tool
        .args
        .iter()
        .map(|(arg, allowed)| {
            let schema = if allowed.is_empty() {
                json!({"type": "string"})
            } else {
                json!({"type": "string", "enum": allowed})
            };
            (arg.clone(), schema)
        })
        .collect();
    json!({
        "type": "object",
        "properties": properties,
        "required": tool.args.keys().collect::<Vec<_>>(),
        "additionalProperties": false,
    })
}

/// `text` as a JSON string literal, quotes included.
fn json_text(text: &str) -> String {
    Value::String(text.to_owned()).to_string()
}

/// `text` as a GBNF string literal that matches it exactly.
fn literal(text: &str) -> String {
    let mut out = String::with_capacity(text.len() + 2);
    out.push('"');
    for c in text.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if (c as u32) < 0x20 => out.push_str(&format!("\\x{:02X}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;

    fn tool(service: &str, args: &[(&str, &[&str])]) -> Tool {
        Tool {
            service: service.to_owned(),
            description: format!("calls {service}"),
            args: args
                .iter()
                .map(|(arg, values)| {
                    (
                        (*arg).to_owned(),
                        values.iter().map(|v| (*v).to_owned()).collect(),
                    )
                })
                .collect::<BTreeMap<_, _>>(),
        }
    }

    fn robot() -> Tool {
        tool(
            "Robot.command",
            &[("speed", &["slow", "fast"]), ("action", &["turn", "stop"])],
        )
    }

    fn lamp() -> Tool {
        tool(
            "Lamp.set",
            &[("colour", &["red", "say \"hi\"", r"back\slash"])],
        )
    }

    #[test]
    fn a_forced_call_grammar_lists_the_args_in_order_with_their_values() {
        let constraint = forced_call(&robot());
        assert_eq!(
            constraint.gbnf,
            concat!(
                r#"root ::= "{" ws "\"action\"" ws ":" ws a-v0 ws "," ws "\"speed\"" ws ":" ws a-v1 ws "}""#,
                "\n",
                r#"a-v0 ::= "\"turn\"" | "\"stop\"""#,
                "\n",
                r#"a-v1 ::= "\"slow\"" | "\"fast\"""#,
                "\n",
                "ws ::= [ ]?\n",
            )
        );
    }

    #[test]
    fn values_with_quotes_and_backslashes_are_escaped_twice() {
        let gbnf = forced_call(&lamp()).gbnf;
        // JSON writes `say "hi"` as "say \"hi\"", and GBNF escapes each quote and backslash of that again.
        assert!(
            gbnf.contains(r#"a-v0 ::= "\"red\"" | "\"say \\\"hi\\\"\"" | "\"back\\\\slash\"""#),
            "{gbnf}"
        );
    }

    #[test]
    fn a_forced_call_schema_is_a_closed_object_of_enums() {
        assert_eq!(
            forced_call(&robot()).schema,
            json!({
                "type": "object",
                "properties": {
                    "action": {"type": "string", "enum": ["turn", "stop"]},
                    "speed": {"type": "string", "enum": ["slow", "fast"]},
                },
                "required": ["action", "speed"],
                "additionalProperties": false,
            })
        );
    }

    #[test]
    fn a_tool_without_args_takes_an_empty_object_and_one_without_values_any_text() {
        let none = forced_call(&tool("Body.wave", &[]));
        assert!(
            none.gbnf.starts_with(r#"root ::= "{" ws "}""#),
            "{}",
            none.gbnf
        );
        let free = forced_call(&tool("Body.say", &[("text", &[])]));
        assert!(
            free.gbnf.contains("a-v0 ::= string\n") && free.gbnf.contains("string ::="),
            "{}",
            free.gbnf
        );
        assert_eq!(free.schema["properties"]["text"], json!({"type": "string"}));
    }

    #[test]
    fn reply_or_call_offers_a_line_of_text_or_each_tool() {
        let constraint = reply_or_call(&[robot(), lamp()]);
        let gbnf = &constraint.gbnf;
        assert!(
            gbnf.starts_with("root ::= reply | call\nreply ::= [^{ \\t\\r\\n] [^\\r\\n]*\n"),
            "{gbnf}"
        );
        assert!(
            gbnf.contains(r#"call ::= "{" ws "\"tool\"" ws ":" ws ( t0 | t1 ) ws "}""#),
            "{gbnf}"
        );
        assert!(gbnf.contains(r#"t1 ::= "\"Lamp.set\"" ws "," ws "\"args\"" ws ":" ws "{" ws "\"colour\"" ws ":" ws t1-v0 ws "}""#), "{gbnf}");
        assert_eq!(
            constraint.schema["anyOf"][1]["properties"]["tool"]["enum"],
            json!(["Lamp.set"])
        );
        assert_eq!(
            constraint.schema["anyOf"][0]["required"],
            json!(["tool", "args"])
        );
    }

    #[test]
    fn a_forced_call_parses_to_its_tool_call() {
        let call =
            parse_call(&[robot()], r#" {"action": "turn", "speed":"fast"} "#).expect("parses");
        assert_eq!(call.service, "Robot.command");
        assert_eq!(call.payload, json!({"action": "turn", "speed": "fast"}));
        let escaped = parse_call(&[lamp()], r#"{"colour": "say \"hi\""}"#).expect("parses");
        assert_eq!(escaped.payload, json!({"colour": "say \"hi\""}));
    }

    #[test]
    fn an_offered_call_names_its_tool() {
        let text = r#"{"tool": "Lamp.set", "args": {"colour": "back\\slash"}}"#;
        let call = parse_call(&[robot(), lamp()], text).expect("parses");
        assert_eq!(call.service, "Lamp.set");
        assert_eq!(call.payload, json!({"colour": r"back\slash"}));
        let forced_in_call_shape = parse_call(
            &[robot()],
            r#"{"tool": "Robot.command", "args": {"action": "stop", "speed": "slow"}}"#,
        );
        assert_eq!(
            forced_in_call_shape.expect("parses").payload,
            json!({"action": "stop", "speed": "slow"})
        );
    }

    #[test]
    fn wrong_calls_are_refused_with_the_reason() {
        let tools = [robot(), lamp()];
        let refused = |tools: &[Tool], text: &str| parse_call(tools, text).expect_err("refused");
        assert!(
            matches!(refused(&tools[..1], r#"{"action": "jump", "speed": "fast"}"#),
            GrammarError::NotAllowed { ref arg, ref value, .. } if arg == "action" && value == "jump")
        );
        assert!(matches!(refused(&tools[..1], r#"{"action": "turn"}"#),
            GrammarError::MissingArg { ref arg, .. } if arg == "speed"));
        assert!(
            matches!(refused(&tools[..1], r#"{"action": "turn", "speed": "fast", "x": "y"}"#),
            GrammarError::ExtraArg { ref arg, .. } if arg == "x")
        );
        assert!(matches!(
            refused(&tools[..1], r#"{"action": 1, "speed": "fast"}"#),
            GrammarError::NotText { .. }
        ));
        assert!(
            matches!(refused(&tools, r#"{"tool": "Door.open", "args": {}}"#),
            GrammarError::UnknownTool(ref name) if name == "Door.open")
        );
        assert!(
            matches!(
                refused(&tools, r#"{"action": "turn", "speed": "fast"}"#),
                GrammarError::UnknownTool(_)
            ),
            "with several tools the call must name one"
        );
        assert!(matches!(
            refused(&tools, "Hello there"),
            GrammarError::NotJson(_)
        ));
        assert!(matches!(
            refused(&tools, r#"["turn"]"#),
            GrammarError::NotObject
        ));
        assert!(matches!(refused(&[], "{}"), GrammarError::NoTools));
        assert!(matches!(
            refused(
                &tools,
                r#"{"tool": "Lamp.set", "args": {"colour": "blue"}}"#
            ),
            GrammarError::NotAllowed { .. }
        ));
    }

    #[test]
    fn a_lone_tool_with_args_named_tool_and_args_reads_its_own_arguments() {
        let odd = tool("Odd.call", &[("tool", &["hammer"]), ("args", &[])]);
        assert!(
            parse_call(
                std::slice::from_ref(&odd),
                r#"{"tool": "hammer", "args": "many"}"#
            )
            .is_ok()
        );
    }

    /// The GBNF is checked by llama.cpp's own parser, with the vocabulary of the default model (the model's
    /// weights are not loaded). Skipped, saying why, where `make model-llm` has not provisioned the model.
    #[test]
    fn llama_cpp_accepts_the_grammars_and_they_admit_the_calls() {
        use llama_cpp_2::model::LlamaModel;
        use llama_cpp_2::model::params::LlamaModelParams;
        use llama_cpp_2::sampling::LlamaSampler;
        use llama_cpp_2::token::data::LlamaTokenData;
        use llama_cpp_2::token::data_array::LlamaTokenDataArray;

        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../models/llm/SmolLM2-135M-Instruct.Q4_1.gguf");
        assert!(
            path.exists(),
            "no model at {} (make model-llm provisions it)",
            path.display()
        );
        let backend = crate::engine::backend().expect("llama.cpp's backend starts");
        let params = LlamaModelParams::default().with_vocab_only(true);
        let model = LlamaModel::load_from_file(backend, &path, &params)
            .expect("the model's vocabulary loads");
        let vocab = model.vocab();
        let n_tokens = vocab.n_tokens();
        // Walks `text` token by token through the grammar; false as soon as the grammar forbids a token.
        let admits = |constraint: &Constraint, text: &str| {
            let mut sampler = LlamaSampler::grammar(&model, &constraint.gbnf, "root")
                .expect("llama.cpp parses it");
            for token in vocab.tokenize(text.as_bytes(), false, false) {
                let mut candidates = LlamaTokenDataArray::from_iter(
                    (0..n_tokens).map(|id| {
                        LlamaTokenData::new(llama_cpp_2::token::LlamaToken(id), 0.0, 0.0)
                    }),
                    false,
                );
                sampler.apply(&mut candidates);
                let allowed = candidates
                    .data
                    .iter()
                    .any(|d| d.id() == token && d.logit() > f32::NEG_INFINITY);
                if !allowed {
                    return false;
                }
                sampler.accept(token);
            }
            true
        };
        let forced = forced_call(&lamp());
        assert!(admits(&forced, r#"{"colour": "say \"hi\""}"#));
        assert!(admits(&forced, r#"{"colour":"back\\slash"}"#));
        assert!(!admits(&forced, r#"{"colour": "blue"}"#));
        let offered = reply_or_call(&[robot(), lamp(), tool("Body.say", &[("text", &[])])]);
        assert!(admits(&offered, "Hello there, how are you?"));
        assert!(admits(
            &offered,
            r#"{"tool": "Robot.command", "args": {"action": "turn", "speed": "slow"}}"#
        ));
        assert!(admits(
            &offered,
            r#"{"tool":"Body.say","args":{"text":"any \"words\" at all"}}"#
        ));
        assert!(!admits(&offered, r#"{"tool": "Door.open""#));
        assert!(!admits(&offered, "Two\nlines"));
        assert!(admits(&forced_call(&tool("Body.wave", &[])), "{}"));
    }
}
