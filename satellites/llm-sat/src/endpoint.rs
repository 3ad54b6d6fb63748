//! The remote generator: an OpenAI-compatible server (llama-server, Ollama, vLLM, llama-cpp-python) streaming
//! `/chat/completions` as server-sent events, for a bigger model on a machine with a GPU. A constraint goes as a
//! JSON-schema `response_format`, in the shape the server takes ([`SchemaFormat`]).

use std::io::{BufRead, BufReader};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use serde_json::{Value, json};

use crate::generator::{
    Constraint, Ended, Flow, GenerateError, Generated, Generator, Limits, Message,
};

/// Where the server is and how to ask it.
#[derive(Debug, Clone)]
pub struct EndpointOptions {
    /// The API's base URL, e.g. `http://gpu-box:8080/v1`.
    pub url: String,
    /// The `model` field of each request.
    pub model: String,
    pub api_key: Option<String>,
    pub temperature: f32,
    pub schema_format: SchemaFormat,
}

/// How a constraint's JSON schema is sent: servers differ.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SchemaFormat {
    /// `{"type": "json_object", "schema": ...}`: llama-server, llama-cpp-python.
    JsonObject,
    /// `{"type": "json_schema", "json_schema": {"name", "schema", "strict"}}`: OpenAI, vLLM, llama-server.
    JsonSchema,
}

/// A client of one OpenAI-compatible server.
#[derive(Debug)]
pub struct Endpoint {
    options: EndpointOptions,
    agent: ureq::Agent,
    shown: String,
}

impl Endpoint {
    pub fn new(options: EndpointOptions) -> Endpoint {
        let agent = ureq::Agent::new_with_config(
            ureq::Agent::config_builder()
                .http_status_as_error(false)
                .build(),
        );
        let shown = format!("{} at {}", options.model, options.url);
        Endpoint {
            options,
            agent,
            shown,
        }
    }

    fn body(&self, chat: &[Message], constraint: Option<&Constraint>, limits: Limits) -> Value {
        let messages: Vec<Value> = chat
            .iter()
            .map(|m| json!({ "role": m.speaker.role(), "content": m.content }))
            .collect();
        let mut body = json!({
            "model": self.options.model,
            "messages": messages,
            "stream": true,
            "max_tokens": limits.max_tokens,
            "temperature": self.options.temperature,
        });
        if let Some(constraint) = constraint {
            body["response_format"] = match self.options.schema_format {
                SchemaFormat::JsonObject => {
                    json!({ "type": "json_object", "schema": constraint.schema })
                }
                SchemaFormat::JsonSchema => json!({
                    "type": "json_schema",
                    "json_schema": { "name": "call", "strict": true, "schema": constraint.schema },
                }),
            };
        }
        body
    }
}

impl Generator for Endpoint {
    fn model(&self) -> &str {
        &self.shown
    }

    fn render(&self, chat: &[Message]) -> Result<String, GenerateError> {
        // The server applies its own template; the trace shows the messages in ChatML-like form.
        Ok(chat
            .iter()
            .map(|m| format!("<|{}|>\n{}\n", m.speaker.role(), m.content))
            .collect())
    }

    fn generate(
        &mut self,
        chat: &[Message],
        constraint: Option<&Constraint>,
        limits: Limits,
        cancel: &AtomicBool,
        on_piece: &mut dyn FnMut(&str) -> Flow,
    ) -> Result<Generated, GenerateError> {
        let started = Instant::now();
        let url = format!(
            "{}/chat/completions",
            self.options.url.trim_end_matches('/')
        );
        let mut request = self
            .agent
            .post(&url)
            .config()
            .timeout_global(Some(limits.deadline.saturating_duration_since(started)))
            .build();
        if let Some(key) = &self.options.api_key {
            request = request.header("Authorization", &format!("Bearer {key}"));
        }
        let response = request
            .send_json(self.body(chat, constraint, limits))
            .map_err(|e| GenerateError::Endpoint(format!("{url}: {e}")))?;
        let status = response.status();
        if !status.is_success() {
            let text = response.into_body().read_to_string().unwrap_or_default();
            return Err(GenerateError::Endpoint(format!(
                "{url}: HTTP {status}: {}",
                text.chars().take(300).collect::<String>()
            )));
        }
        let mut generated = Generated {
            ended: Ended::EndOfText,
            prompt_tokens: 0,
            cached_tokens: 0,
            tokens: 0,
            first_token: None,
        };
        let reader = BufReader::new(response.into_body().into_reader());
        for line in reader.lines() {
            if cancel.load(Ordering::Relaxed) {
                generated.ended = Ended::Cancelled;
                break;
            }
            if Instant::now() >= limits.deadline {
                generated.ended = Ended::Deadline;
                break;
            }
            let line = match line {
                Ok(line) => line,
                // The global timeout cut the stream.
                Err(_) if Instant::now() >= limits.deadline => {
                    generated.ended = Ended::Deadline;
                    break;
                }
                Err(e) => return Err(GenerateError::Endpoint(format!("{url}: {e}"))),
            };
            let Some(data) = line.strip_prefix("data:").map(str::trim) else {
                continue;
            };
            if data == "[DONE]" {
                break;
            }
            let event: Value = serde_json::from_str(data)
                .map_err(|e| GenerateError::Endpoint(format!("{url}: a bad event: {e}")))?;
            if let Some(usage) = event.get("usage").filter(|u| !u.is_null()) {
                generated.prompt_tokens = count(usage, "prompt_tokens");
            }
            let choice = &event["choices"][0];
            if let Some(piece) = choice["delta"]["content"].as_str()
                && !piece.is_empty()
            {
                generated.tokens += 1;
                generated
                    .first_token
                    .get_or_insert_with(|| started.elapsed());
                if on_piece(piece) == Flow::Stop {
                    generated.ended = Ended::Stopped;
                    break;
                }
            }
            if choice["finish_reason"].as_str() == Some("length") {
                generated.ended = Ended::MaxTokens;
            }
        }
        Ok(generated)
    }
}

fn count(usage: &Value, key: &str) -> u32 {
    usage[key].as_u64().map_or(0, |n| n as u32)
}
