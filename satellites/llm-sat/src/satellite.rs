//! The satellite on the hub: serves `Agent.chat`, runs one turn at a time on the generator's thread and publishes
//! each turn's prompt, sentences, call and end on `Agent.chat.reply`. A newer turn or a cancel stops the running one
//! within one token. A speculative turn is generated but held back until the same turn is asked for for real (then
//! what it has is published at once and the rest as it comes) or dropped when another turn comes instead.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use agent_contract::channels::{CHAT, CHAT_REPLY, headers};
use agent_contract::chat::{ChatAnswer, ChatCall, ChatEvent, ChatRequest, ChatStats, Finish};
use bytes::Bytes;
use flow::client::ServiceCall;
use flow::{Client, Publisher};
use tokio::sync::{mpsc, watch};
use tracing::{debug, info, warn};

use flow_telemetry::{SpanRecord, Telemetry, TraceContext, now_us};

use crate::generator::Generator;
use crate::turn::{self, Outcome, Step, TurnLimits};

/// Steps of the turn in progress waiting for the hub side; the generator's thread waits when it is this far ahead
/// (a turn has a few sentences, so it never does in practice).
const STEP_QUEUE: usize = 64;

/// Who the satellite is and how it answers.
#[derive(Debug, Clone)]
pub struct Settings {
    pub name: String,
    pub limits: TurnLimits,
    /// Where the spans of each turn's generation go (docs/telemetry.md); off unless a collector is named.
    pub telemetry: Telemetry,
}

/// One turn handed to the generator's thread.
struct Job {
    id: u64,
    request: ChatRequest,
    cancel: Arc<AtomicBool>,
}

/// What the generator's thread reports.
enum Report {
    Step(u64, Step),
    Done(u64, Result<Outcome, String>),
}

/// The turn in progress, as the hub side follows it.
struct Running {
    id: u64,
    request: ChatRequest,
    cancel: Arc<AtomicBool>,
    /// The call to answer when it ends; none while it is speculative.
    call: Option<ServiceCall>,
    /// The turn number its events carry once published.
    turn: u64,
    /// Held back while speculative: the steps so far, and the end if it came.
    held: Vec<Step>,
    ended: Option<Result<Outcome, String>>,
    /// Sentences published so far.
    published: u32,
    /// Started speculatively and adopted by the real turn.
    adopted: bool,
    /// When the request came (µs, Unix clock), and when each sentence was generated: the spans of the turn.
    received_us: u64,
    sentences_us: Vec<u64>,
}

/// Serves chat turns until the hub connection closes or `stop` is set.
pub async fn run(
    client: Client,
    generator: Box<dyn Generator>,
    settings: Settings,
    mut stop: watch::Receiver<bool>,
) -> anyhow::Result<()> {
    let model = generator.model().to_owned();
    let mut service = client.serve(CHAT.name, headers::CHAT).await?;
    let reply = client
        .publisher(CHAT_REPLY.name, headers::CHAT_REPLY)
        .await?;
    let (jobs_tx, jobs_rx) = std::sync::mpsc::channel::<Job>();
    let (reports_tx, mut reports) = mpsc::channel(STEP_QUEUE);
    let limits = settings.limits;
    let worker = std::thread::Builder::new()
        .name("llm-generate".into())
        .spawn(move || generate_loop(generator, limits, &jobs_rx, &reports_tx))?;
    info!(name = %settings.name, %model, "llm satellite serving {}", CHAT.name);

    let mut hub = Hub {
        reply,
        satellite: settings.name.clone(),
        model,
        running: None,
        next_id: 0,
        jobs: jobs_tx,
        telemetry: settings.telemetry.clone(),
        dropped: Vec::new(),
    };
    loop {
        tokio::select! {
            _ = stop.changed() => break,
            call = service.next() => match call {
                Some(call) => hub.call(call).await,
                None => break,
            },
            Some(report) = reports.recv() => hub.report(report).await,
        }
    }
    if let Some(running) = &hub.running {
        running.cancel.store(true, Ordering::Relaxed);
    }
    drop(hub);
    // The thread ends when its job queue closes, within one token of the cancel.
    let _ = tokio::task::spawn_blocking(move || worker.join()).await;
    Ok(())
}

struct Hub {
    reply: Publisher,
    satellite: String,
    model: String,
    running: Option<Running>,
    next_id: u64,
    jobs: std::sync::mpsc::Sender<Job>,
    telemetry: Telemetry,
    /// Speculative turns dropped while their generation was still stopping: (job id, turn), whose end is published
    /// when it comes, with the tokens they cost.
    dropped: Vec<(u64, u64)>,
}

impl Hub {
    async fn call(&mut self, call: ServiceCall) {
        let parsed: Result<ChatCall, _> = serde_json::from_slice(&call.payload);
        match parsed {
            Err(e) => {
                let _ = call
                    .respond(Err(format!("not a chat turn or cancel: {e}")))
                    .await;
            }
            Ok(ChatCall::Cancel(cancel)) => {
                let hit = self
                    .running
                    .as_ref()
                    .is_some_and(|r| r.turn == cancel.cancel);
                if let Some(running) = self.running.as_ref().filter(|_| hit) {
                    running.cancel.store(true, Ordering::Relaxed);
                }
                // A speculative turn nobody will adopt is done with at once.
                if hit
                    && self.running.as_ref().is_some_and(|r| r.request.speculative)
                    && let Some(old) = self.running.take()
                {
                    self.answer_cancelled(old).await;
                }
                let body = serde_json::json!({ "cancelled": hit });
                let _ = call.respond(Ok(Bytes::from(body.to_string()))).await;
            }
            Ok(ChatCall::Turn(request)) => self.turn(*request, call).await,
        }
    }

    async fn turn(&mut self, request: ChatRequest, call: ServiceCall) {
        // The same turn asked for for real while it was generated speculatively: adopt it.
        if !request.speculative
            && let Some(running) = self.running.as_mut()
            && running.call.is_none()
            && running.request.speculative
            && same_turn(&running.request, &request)
        {
            info!(turn = request.turn, "llm: the speculative reply is adopted");
            running.call = Some(call);
            running.turn = request.turn;
            running.request.speculative = false;
            running.adopted = true;
            running.request.trace = request.trace;
            let held = std::mem::take(&mut running.held);
            let ended = running.ended.take();
            for step in held {
                self.publish_step(step).await;
            }
            if let Some(ended) = ended {
                self.finish(ended).await;
            }
            return;
        }
        // Anything running is superseded.
        if let Some(old) = self.running.take() {
            old.cancel.store(true, Ordering::Relaxed);
            self.answer_cancelled(old).await;
        }
        self.next_id += 1;
        let cancel = Arc::new(AtomicBool::new(false));
        let job = Job {
            id: self.next_id,
            request: request.clone(),
            cancel: cancel.clone(),
        };
        if self.jobs.send(job).is_err() {
            let _ = call
                .respond(Err("the generator has stopped".to_owned()))
                .await;
            return;
        }
        let speculative = request.speculative;
        self.running = Some(Running {
            id: self.next_id,
            turn: request.turn,
            request,
            cancel,
            // A speculative call is answered at once: its caller waits for nothing.
            call: if speculative {
                let _ = call
                    .respond(Ok(Bytes::from_static(br#"{"speculating":true}"#)))
                    .await;
                None
            } else {
                Some(call)
            },
            held: Vec::new(),
            ended: None,
            published: 0,
            adopted: false,
            received_us: now_us(),
            sentences_us: Vec::new(),
        });
    }

    /// A superseded turn ends as cancelled (its own End event, and its caller's answer).
    async fn answer_cancelled(&mut self, old: Running) {
        if old.request.speculative {
            debug!(turn = old.turn, "llm: a speculative reply is dropped");
            match old.ended {
                Some(ended) => self.publish_dropped(old.turn, ended.ok()),
                None => self.dropped.push((old.id, old.turn)),
            }
            return;
        }
        let stats = ChatStats::default();
        self.publish(ChatEvent::End {
            turn: old.turn,
            finish: Finish::Cancelled,
            stats,
        });
        if let Some(call) = old.call {
            let answer = ChatAnswer {
                turn: old.turn,
                reply: String::new(),
                generated: String::new(),
                sentences: old.published,
                finish: Finish::Cancelled,
                call: None,
                stats,
            };
            let _ = call.respond(Ok(json(&answer))).await;
        }
    }

    async fn report(&mut self, report: Report) {
        match report {
            Report::Step(id, step) => {
                let Some(running) = self.running.as_mut().filter(|r| r.id == id) else {
                    return;
                };
                if matches!(step, Step::Sentence(_)) {
                    running.sentences_us.push(now_us());
                }
                if running.request.speculative {
                    running.held.push(step);
                } else {
                    self.publish_step(step).await;
                }
            }
            Report::Done(id, ended) => {
                if let Some(at) = self.dropped.iter().position(|(job, _)| *job == id) {
                    let (_, turn) = self.dropped.swap_remove(at);
                    self.publish_dropped(turn, ended.ok());
                    return;
                }
                let Some(running) = self.running.as_mut().filter(|r| r.id == id) else {
                    return;
                };
                if running.request.speculative {
                    running.ended = Some(ended);
                } else {
                    self.finish(ended).await;
                }
            }
        }
    }

    async fn publish_step(&mut self, step: Step) {
        let Some(running) = self.running.as_mut() else {
            return;
        };
        let turn = running.turn;
        let event = match step {
            Step::Prompt(prompt) => ChatEvent::Prompt {
                turn,
                prompt,
                satellite: self.satellite.clone(),
                model: self.model.clone(),
            },
            Step::Sentence(text) => {
                let index = running.published;
                running.published += 1;
                ChatEvent::Sentence { turn, index, text }
            }
            Step::Call(call) => ChatEvent::Call { turn, call },
        };
        self.publish(event);
    }

    /// The end of a speculative turn nobody adopted: cancelled, with what it cost (`speculated`), so that the agent
    /// can count the work preemption wasted (docs/llm.md, "Preemptive replies").
    fn publish_dropped(&self, turn: u64, outcome: Option<Outcome>) {
        let stats = ChatStats {
            speculated: true,
            dropped: true,
            ..outcome.map(|o| o.stats).unwrap_or_default()
        };
        self.publish(ChatEvent::End {
            turn,
            finish: Finish::Cancelled,
            stats,
        });
    }

    /// The running turn ended: its End event, then its caller's answer.
    async fn finish(&mut self, ended: Result<Outcome, String>) {
        let Some(mut running) = self.running.take() else {
            return;
        };
        let Some(call) = running.call.take() else {
            return;
        };
        match ended {
            Ok(outcome) => {
                let mut stats = outcome.stats;
                stats.speculated = running.adopted;
                let trace = trace_of(&running.request);
                self.record(&running, trace, &outcome, &stats);
                self.publish(ChatEvent::End {
                    turn: running.turn,
                    finish: outcome.finish,
                    stats,
                });
                info!(
                    turn = running.turn,
                    trace_id = %trace.map(|t| t.trace.to_string()).unwrap_or_default(),
                    finish = ?outcome.finish,
                    sentences = outcome.sentences.len(),
                    tokens = stats.tokens,
                    first_token_ms = stats.first_token_ms,
                    cached = stats.cached_tokens,
                    "llm: turn done"
                );
                let answer = ChatAnswer {
                    turn: running.turn,
                    reply: outcome.sentences.join(" "),
                    generated: outcome.generated,
                    sentences: outcome.sentences.len() as u32,
                    finish: outcome.finish,
                    call: outcome.call,
                    stats,
                };
                let _ = call.respond(Ok(json(&answer))).await;
            }
            Err(reason) => {
                warn!(turn = running.turn, "llm: the turn failed: {reason}");
                let _ = call.respond(Err(reason)).await;
            }
        }
    }

    /// The turn's spans under the reply span its request named: the generation, its first token, and each
    /// sentence from the one before it (the first from the first token).
    fn record(
        &self,
        running: &Running,
        trace: Option<TraceContext>,
        outcome: &Outcome,
        stats: &ChatStats,
    ) {
        let Some(reply) = trace.filter(|_| self.telemetry.is_on()) else {
            return;
        };
        let start = running.received_us;
        let end = now_us();
        let generate = SpanRecord::under(reply, "llm.generate", start, end)
            .with("satellite", self.satellite.as_str())
            .with("model", self.model.as_str())
            .with("turn", running.turn)
            .with("finish", format!("{:?}", outcome.finish).to_lowercase())
            .with("prompt_tokens", stats.prompt_tokens)
            .with("cached_tokens", stats.cached_tokens)
            .with("tokens", stats.tokens)
            .with("speculated", stats.speculated);
        let generation = generate.context;
        self.telemetry.record(generate);
        let first_token = start + stats.first_token_ms * 1000;
        self.telemetry.record(SpanRecord::under(
            generation,
            "llm.first_token",
            start,
            first_token,
        ));
        let mut from = first_token;
        for (index, &at) in running.sentences_us.iter().enumerate() {
            self.telemetry.record(
                SpanRecord::under_as(
                    generation,
                    "llm.sentence",
                    &format!("sentence {index}"),
                    from,
                    at,
                )
                .with("index", index as u64),
            );
            from = at;
        }
    }

    fn publish(&self, event: ChatEvent) {
        // Overflow: the stream's lanes drop oldest per subscriber; a full local queue drops this event (counted by
        // the SDK) rather than stall the turn.
        if let Ok(false) = self.reply.try_publish(json(&event)) {
            debug!("llm: an event was dropped, the hub link is busy");
        }
    }
}

/// The reply span a request names, if it names one that parses (a malformed one only costs the turn its spans).
fn trace_of(request: &ChatRequest) -> Option<TraceContext> {
    let text = request.trace.as_deref()?;
    TraceContext::parse(text)
        .inspect_err(|e| {
            debug!(
                turn = request.turn,
                "llm: the request's trace is not used: {e}"
            )
        })
        .ok()
}

/// Two requests for the same turn: everything but the speculative flag, the turn number and the trace is the same.
fn same_turn(a: &ChatRequest, b: &ChatRequest) -> bool {
    let mut a = a.clone();
    a.speculative = b.speculative;
    a.trace.clone_from(&b.trace);
    a.turn = b.turn;
    &a == b
}

fn json<T: serde::Serialize>(value: &T) -> Bytes {
    Bytes::from(serde_json::to_vec(value).unwrap_or_default())
}

/// The generator's thread: one job at a time, each step reported as it comes.
fn generate_loop(
    mut generator: Box<dyn Generator>,
    limits: TurnLimits,
    jobs: &std::sync::mpsc::Receiver<Job>,
    reports: &mpsc::Sender<Report>,
) {
    let mut renderings = crate::prompt::Renderings::default();
    while let Ok(job) = jobs.recv() {
        if job.cancel.load(Ordering::Relaxed) {
            let _ = reports.blocking_send(Report::Done(job.id, Err("cancelled".into())));
            continue;
        }
        let id = job.id;
        let mut step = |step: Step| {
            let _ = reports.blocking_send(Report::Step(id, step));
        };
        let outcome = turn::run(
            generator.as_mut(),
            &mut renderings,
            &job.request,
            limits,
            &job.cancel,
            &mut step,
        )
        .map_err(|e| e.to_string());
        if reports.blocking_send(Report::Done(id, outcome)).is_err() {
            break;
        }
    }
}
