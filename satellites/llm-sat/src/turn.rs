//! One chat turn on the generator's thread: the chat built, the reply generated under its limits, split into spoken
//! sentences as it streams (or read as a tool call), each step handed to the hub side as a [`Step`].

use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use agent_contract::chat::{ChatRequest, ChatStats, Finish, ToolCall};

use crate::generator::{Ended, Flow, GenerateError, Generator, Limits};
use crate::grammar;
use crate::prompt;
use crate::spoken::Sentences;

/// The limits every turn runs under (the satellite's flags).
#[derive(Debug, Clone, Copy)]
pub struct TurnLimits {
    pub max_sentences: u32,
    pub max_tokens: u32,
    pub timeout: Duration,
    /// Offer the program's tools to the model on every turn, not only when a rule forces one.
    pub offer_tools: bool,
}

/// What a turn produces, in order.
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    /// The chat as the model sees it.
    Prompt(String),
    Sentence(String),
    Call(ToolCall),
}

/// How a turn ended.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    pub finish: Finish,
    pub sentences: Vec<String>,
    /// The text as the model wrote it.
    pub generated: String,
    pub call: Option<ToolCall>,
    pub stats: ChatStats,
}

/// Why a turn failed.
#[derive(Debug, thiserror::Error)]
pub enum TurnError {
    #[error(transparent)]
    Generate(#[from] GenerateError),
    #[error("the model's call does not fit the tool: {0}")]
    Call(#[from] grammar::GrammarError),
}

/// Runs `request` on `generator`; `step` receives the prompt, each sentence as soon as it is complete, and a call.
/// `renderings` keeps how each question was asked, for the prompts of the turns after it.
pub fn run(
    generator: &mut dyn Generator,
    renderings: &mut prompt::Renderings,
    request: &ChatRequest,
    mut limits: TurnLimits,
    cancel: &AtomicBool,
    step: &mut dyn FnMut(Step),
) -> Result<Outcome, TurnError> {
    let started = Instant::now();
    // The agent's limits for this reply, where they are lower than the satellite's own.
    if let Some(max) = request.max_sentences.filter(|&m| m > 0) {
        limits.max_sentences = limits.max_sentences.min(max);
    }
    if let Some(ms) = request.timeout_ms {
        limits.timeout = limits.timeout.min(Duration::from_millis(ms));
    }
    let chat = prompt::chat(request, limits.offer_tools, renderings);
    step(Step::Prompt(generator.render(&chat)?));
    let forced = request
        .force_tool
        .as_ref()
        .and_then(|service| request.tools.iter().find(|t| &t.service == service));
    let constraint = match forced {
        Some(tool) => Some(grammar::forced_call(tool)),
        None if limits.offer_tools && !request.tools.is_empty() => {
            Some(grammar::reply_or_call(&request.tools))
        }
        None => None,
    };
    let mut sentences = Sentences::new(limits.max_sentences).in_language(&request.language);
    let mut spoken = Vec::new();
    // The reply's text so far, kept whole while it may be a call (a constraint allows one and it began with `{`).
    let mut text = String::new();
    let mut is_call = forced.is_some();
    let mut decided = forced.is_some() || constraint.is_none();
    let mut on_piece = |piece: &str| -> Flow {
        text.push_str(piece);
        if !decided {
            match text.trim_start().chars().next() {
                None => return Flow::Continue,
                Some(first) => {
                    decided = true;
                    is_call = first == '{';
                }
            }
            if !is_call {
                return say(&mut sentences, &text, &mut spoken, step);
            }
        }
        if is_call {
            return Flow::Continue;
        }
        say(&mut sentences, piece, &mut spoken, step)
    };
    let generated = generator.generate(
        &chat,
        constraint.as_ref(),
        Limits {
            // A forced call is short: its JSON needs few tokens.
            max_tokens: if forced.is_some() {
                limits.max_tokens.min(96)
            } else {
                limits.max_tokens
            },
            deadline: started + limits.timeout,
        },
        cancel,
        &mut on_piece,
    )?;
    let mut call = None;
    if is_call {
        let parsed = match forced {
            Some(tool) => grammar::parse_call(std::slice::from_ref(tool), &text)?,
            None => grammar::parse_call(&request.tools, &text)?,
        };
        step(Step::Call(parsed.clone()));
        call = Some(parsed);
    } else if !matches!(generated.ended, Ended::Cancelled)
        && let Some(last) = sentences.finish()
        && !last.trim().is_empty()
    {
        step(Step::Sentence(last.clone()));
        spoken.push(last);
    }
    let finish = match generated.ended {
        _ if call.is_some() => Finish::Call,
        Ended::EndOfText => Finish::Stop,
        Ended::MaxTokens => Finish::Tokens,
        Ended::Deadline => Finish::Timeout,
        Ended::Cancelled => Finish::Cancelled,
        Ended::Stopped => Finish::Sentences,
    };
    Ok(Outcome {
        finish,
        sentences: spoken,
        generated: text,
        call,
        stats: ChatStats {
            prompt_tokens: generated.prompt_tokens,
            cached_tokens: generated.cached_tokens,
            tokens: generated.tokens,
            first_token_ms: generated.first_token.map_or(0, |d| d.as_millis() as u64),
            total_ms: started.elapsed().as_millis() as u64,
            speculated: request.speculative,
            dropped: false,
        },
    })
}

/// Feeds `piece` to the splitter and hands on each sentence it completes; stops the model at the sentence cap.
fn say(
    sentences: &mut Sentences,
    piece: &str,
    spoken: &mut Vec<String>,
    step: &mut dyn FnMut(Step),
) -> Flow {
    // The splitter hands sentences on in spoken form already.
    for sentence in sentences.push(piece) {
        if sentence.trim().is_empty() {
            continue;
        }
        step(Step::Sentence(sentence.clone()));
        spoken.push(sentence);
    }
    if sentences.capped() {
        Flow::Stop
    } else {
        Flow::Continue
    }
}
