//! The brain module: runs the teleo-reactive program (`agent-brain`) on the hub. Percepts come from
//! `Agent.transcript`, `Agent.detections` and the agent's own speech; the effects speak, publish, call services
//! and run whitelisted commands; every rule change is published on `Agent.rules`. See docs/brain.md.

mod actuators;
mod chat;
mod params;
mod percepts;
mod program_file;
mod shelf;
mod speech;
mod turn;
mod wire;

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use agent_brain::{
    Action, Brain, Capabilities, EchoFilter, Effect, Language, Now, PerceptError, Value, WallClock,
};
use agent_contract::channels;
use agent_contract::chat::{ChatEvent, Facts, Tool};
use agent_contract::rules::ChatStep;
use agent_contract::transcript::TranscriptMessage;
use flow::tick::Tick;
use flow::{Client, Data, Publisher, Subscription};
use tokio::sync::mpsc;
use tokio::time::Instant;
use tracing::{debug, info, warn};

use actuators::{Actuators, OUTCOME_QUEUE, Outcome};
use chat::{Ask, Chats, DONE_QUEUE, Next};
use flow_hub::module::{Module, ModuleContext, ModuleFuture};
use params::BrainParams;
use percepts::{Hearing, Percept};
use program_file::{ProgramFile, Reload};
use shelf::Shelf;
use speech::{PlayoutClock, Speech};

/// The built-in brain module (`[modules.brain]`), conversing in the agent's language, answering from the knowledge
/// folder (`[agent] knowledge`) when there is one.
#[derive(Debug, Default)]
pub struct BrainModule {
    pub language: Language,
    pub knowledge: Option<PathBuf>,
}

impl Module for BrainModule {
    fn name(&self) -> &'static str {
        "brain"
    }

    fn check(&self, params: &serde_json::Value) -> anyhow::Result<()> {
        let params = BrainParams::from_json(params)?;
        if let Some(dir) = &self.knowledge
            && dir.exists()
            && !dir.is_dir()
        {
            anyhow::bail!("[agent] knowledge: {} is not a folder", dir.display());
        }
        let capabilities = Capabilities {
            commands: params.commands.keys().cloned().collect(),
        };
        ProgramFile::new(params.program(self.language), capabilities)
            .load()
            .map(drop)
            .map_err(|e| anyhow::anyhow!("[modules.brain] program: {e:#}"))
    }

    fn run(self: Box<Self>, ctx: ModuleContext) -> ModuleFuture {
        Box::pin(run(ctx, self.language, self.knowledge))
    }
}

/// Counters shown at `/api/status`.
#[derive(Debug, Default)]
struct Counters {
    transcripts: u64,
    echoes_dropped: u64,
    bad_messages: u64,
    steps: u64,
    rule_changes: u64,
    reloads: u64,
    reload_errors: u64,
    last_reload_error: Option<String>,
}

/// Everything the loop works on.
struct Mind {
    brain: Brain,
    file: ProgramFile,
    actuators: Actuators,
    echo: EchoFilter,
    rules: Publisher,
    playout: PlayoutClock,
    db: BTreeMap<String, Value>,
    client: Client,
    utc_offset_s: i32,
    /// The language of the clock's words.
    language: Language,
    counters: Counters,
    /// The last reply asked of the TTS module, for the trace entry of a barge-in that cuts it off.
    saying: Option<String>,
    /// The turn the last final transcript started (its trace context), which a chat turn's request names.
    answering: Option<flow_telemetry::TraceContext>,
    /// Start the model on the transcript of a pause (`chat_preempt`).
    preempt: bool,
    /// A final transcript came since the last step: a speculative reply it did not adopt is dropped after it.
    heard_final: bool,
    /// When the last final transcript's speech ended, and `chat_thinking_ms`: a chat turn without a sentence by then
    /// asserts `thinking` (`Mind::ponder`), and it holds until the reply comes.
    speech_ended: Option<Instant>,
    think_after: Option<Duration>,
    thinking: bool,
    speech: Speech,
    /// The knowledge folder's index.
    shelf: Shelf,
    /// Chat turns with the language-model satellite.
    chats: Chats,
}

async fn run(
    mut ctx: ModuleContext,
    language: Language,
    knowledge: Option<PathBuf>,
) -> anyhow::Result<()> {
    let params = BrainParams::from_json(&ctx.params)?;
    let capabilities = Capabilities {
        commands: params.commands.keys().cloned().collect(),
    };
    let mut file = ProgramFile::new(params.program(language), capabilities);
    let program = file.load()?;

    let client = ctx.client.clone();
    let transcripts = client.subscribe(channels::TRANSCRIPT.name).await?;
    let pauses = client.subscribe(channels::TRANSCRIPT_PAUSE.name).await?;
    let detections = client.subscribe(channels::DETECTIONS.name).await?;
    let speech_out = client.subscribe(channels::SPEECH.name).await?;
    let avatar = client.subscribe(channels::AVATAR.name).await?;
    let chat_reply = client.subscribe(channels::CHAT_REPLY.name).await?;
    // Subscribed before anything is said to be ready, so that no transcript published after it is missed.
    info!(program = %file.path().display(), rules = program.rule_count(), "brain: program loaded");
    let folder_language = match language {
        Language::It => agent_knowledge::Language::It,
        Language::En => agent_knowledge::Language::En,
    };
    let (shelf, mut shelf_updates) = Shelf::open(knowledge, folder_language)
        .await
        .map_err(|e| anyhow::anyhow!("[agent] knowledge: {e:#}"))?;
    let (chat_done_tx, mut chat_done) = mpsc::channel(DONE_QUEUE);
    let speech = Speech::start(client.clone());
    // The voice makes the program's fixed replies now, while nobody is waiting for them (docs/voice.md).
    tokio::spawn(speech::prepare_sayings(
        client.clone(),
        program.fixed_sayings(),
    ));
    let rules = client
        .publisher(channels::RULES.name, channels::headers::RULES)
        .await?;
    let (outcome_tx, mut outcomes) = mpsc::channel(OUTCOME_QUEUE);
    let mut mind = Mind {
        brain: Brain::new(program),
        file,
        actuators: Actuators::new(client.clone(), speech.clone(), &params, outcome_tx),
        echo: EchoFilter::new(params.echo_window(), params.echo_threshold),
        rules,
        playout: PlayoutClock::default(),
        db: BTreeMap::new(),
        client: client.clone(),
        utc_offset_s: params
            .utc_offset_minutes
            .map_or_else(wire::local_utc_offset_s, |minutes| minutes * 60),
        language,
        counters: Counters::default(),
        saying: None,
        answering: None,
        preempt: params.chat_preempt,
        heard_final: false,
        speech_ended: None,
        think_after: (params.chat_thinking_ms > 0)
            .then(|| Duration::from_millis(params.chat_thinking_ms)),
        thinking: false,
        speech: speech.clone(),
        shelf,
        chats: Chats::new(
            client.clone(),
            speech,
            chat_done_tx,
            chat::ChatLimits {
                max_sentences: params.chat_max_sentences,
                reply_timeout: params.chat_timeout(),
            },
            params.chat_memory_turns,
            params.chat_forget_after(),
        ),
    };
    mind.chats.recall().await;
    mind.refresh_db().await;
    mind.step().await;

    let mut ticks = ctx.ticks();
    loop {
        // Sleep until the brain's next deadline (a fact going stale, the end of the agent's speech), or forever.
        let wake = mind.next_wakeup();
        let deadline = async move {
            match wake {
                Some(at) => tokio::time::sleep_until(at).await,
                None => std::future::pending().await,
            }
        };
        tokio::select! {
            () = ctx.stopped() => break,
            data = transcripts.recv() => match data {
                Some(data) => mind.heard(&data),
                None => break,
            },
            data = pauses.recv() => match data {
                Some(data) => mind.paused(&data),
                None => break,
            },
            data = detections.recv() => match data {
                Some(data) => mind.seen(&data),
                None => break,
            },
            data = speech_out.recv() => match data {
                Some(data) => mind.spoke(&data, &speech_out),
                None => break,
            },
            data = avatar.recv() => match data {
                Some(data) => mind.avatar(&data),
                None => break,
            },
            data = chat_reply.recv() => match data {
                Some(data) => mind.chat_event(&data).await,
                None => break,
            },
            Some(done) = chat_done.recv() => {
                // llm-sat publishes a turn's events before it answers the call, so they are queued by now: taken
                // first, since the select picks at random among ready branches, and on a loaded machine the
                // answer could end the turn before its prompt was seen (tests/llm.rs's Italian turn lost its
                // prompt trace once in a fresh-clone run).
                while let Some(data) = chat_reply.try_recv() {
                    mind.chat_event(&data).await;
                }
                for next in mind.chats.done(done) {
                    mind.chat_next(next).await;
                }
            }
            Some(outcome) = outcomes.recv() => mind.outcome(outcome),
            Some(update) = shelf_updates.next() => mind.shelf.swap(update),
            tick = ticks.recv() => {
                if matches!(tick, Ok(Tick::OneSec)) {
                    mind.each_second(&ctx).await;
                }
            }
            () = deadline => {}
        }
        mind.step().await;
    }
    Ok(())
}

impl Mind {
    fn now(&self) -> Now {
        let unix_ms = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_millis() as i64);
        Now {
            at: Instant::now().into_std(),
            clock: WallClock::from_unix_ms(unix_ms, self.utc_offset_s).in_language(self.language),
        }
    }

    fn next_wakeup(&self) -> Option<Instant> {
        let now = Instant::now();
        let brain = self
            .brain
            .next_wakeup(now.into_std())
            .map(Instant::from_std);
        let speech_end = self.playout.speaking_until(now);
        [brain, speech_end, self.think_at()]
            .into_iter()
            .flatten()
            .min()
    }

    /// When `thinking` is due: a chat turn waits for its first sentence and the program perceives `thinking`.
    fn think_at(&self) -> Option<Instant> {
        if self.thinking || !self.chats.awaiting_reply() {
            return None;
        }
        self.brain.program().decl("thinking")?;
        Some(self.speech_ended? + self.think_after?)
    }

    /// Asserts `thinking` once the model's reply is late, and retracts it when the reply (or its end) comes.
    fn ponder(&mut self) {
        let now = Instant::now();
        if self.think_at().is_some_and(|at| at <= now) {
            info!("brain: the model's reply is late: thinking");
            self.thinking = true;
            self.perceive("thinking", Vec::new());
        } else if self.thinking && !self.chats.awaiting_reply() {
            self.thinking = false;
            self.brain.retract("thinking");
        }
    }

    fn perceive(&mut self, name: &str, args: Vec<Value>) {
        if let Err(e) = self.brain.perceive(Instant::now().into_std(), name, args) {
            self.percept_rejected(name, &e);
        }
    }

    fn percept_rejected(&mut self, name: &str, error: &PerceptError) {
        self.counters.bad_messages += 1;
        warn!(
            percept = name,
            "brain: the program's declaration does not fit: {error}"
        );
    }

    /// A transcript: dropped when it is the agent hearing itself, otherwise `heard(text)`; voice activity
    /// makes `listening` hold while the user speaks.
    fn heard(&mut self, data: &Data) {
        let text = match percepts::hearing(&data.payload) {
            Ok(Hearing::Said(text)) => text,
            Ok(Hearing::Speaking) => {
                self.perceive("listening", Vec::new());
                return;
            }
            Ok(Hearing::Paused) => {
                self.brain.retract("listening");
                return;
            }
            Ok(Hearing::Nothing) => return,
            Err(e) => {
                self.counters.bad_messages += 1;
                warn!("brain: bad message on Agent.transcript: {e}");
                return;
            }
        };
        // A final transcript means the user has finished this utterance.
        self.brain.retract("listening");
        if let Some(said) = self.echo.echo_of(Instant::now().into_std(), &text) {
            self.counters.echoes_dropped += 1;
            info!(transcript = %text, said, "brain: dropped a transcript of the agent's own voice");
            return;
        }
        self.counters.transcripts += 1;
        self.heard_final = true;
        self.speech_ended = Some(percepts::speech_end(&data.payload).unwrap_or_else(Instant::now));
        self.answering = percepts::turn_trace(&data.payload);
        self.speech
            .answering(self.answering.map(|t| t.child("reply")));
        match self.answering {
            Some(turn) => debug!(transcript = %text, trace_id = %turn.trace, "brain: heard"),
            None => debug!(transcript = %text, "brain: heard"),
        }
        self.know(&text);
        self.perceive("heard", vec![Value::Text(text)]);
    }

    /// `known(text)` when the knowledge folder holds a passage sure enough for `recall` (programs that declare it).
    fn know(&mut self, text: &str) {
        if self.brain.program().decl("known").is_some() && self.shelf.recall(text).is_some() {
            self.perceive("known", vec![Value::Text(text.to_owned())]);
        }
    }

    /// The transcript of a pause, before the end of the turn is decided: when the program would hand it to the
    /// model as it stands (a trial step on a copy of the brain, which performs nothing), the model starts on it
    /// speculatively, and the final transcript adopts that reply if it is the same (docs/llm.md, "Preemptive
    /// replies").
    fn paused(&mut self, data: &Data) {
        if !self.preempt {
            return;
        }
        let text = match serde_json::from_slice::<TranscriptMessage>(&data.payload) {
            Ok(t) if !t.is_final => t.text.trim().to_owned(),
            Ok(_) => return,
            Err(e) => {
                self.counters.bad_messages += 1;
                debug!(
                    "brain: bad message on {}: {e}",
                    channels::TRANSCRIPT_PAUSE.name
                );
                return;
            }
        };
        if text.is_empty()
            || self
                .echo
                .echo_of(Instant::now().into_std(), &text)
                .is_some()
        {
            return;
        }
        let now = self.now();
        let mut trial = self.brain.clone();
        trial.retract("listening");
        if trial.program().decl("known").is_some()
            && self.shelf.recall(&text).is_some()
            && trial
                .perceive(now.at, "known", vec![Value::Text(text.clone())])
                .is_err()
        {
            return;
        }
        if trial
            .perceive(now.at, "heard", vec![Value::Text(text.clone())])
            .is_err()
        {
            return;
        }
        let step = trial.step(&now, &self.db);
        let chat = step.effects.iter().find_map(|effect| match effect {
            Effect::Start(Action::Chat { text, tool })
            | Effect::Fire(Action::Chat { text, tool }) => Some((text.clone(), tool.clone())),
            _ => None,
        });
        let Some((asked, tool)) = chat else {
            return;
        };
        let tools = self.tools();
        let facts = self.facts(&now, &asked);
        if let Some(turn) = self.chats.speculate(Ask {
            text: asked.clone(),
            language: self.language.code().to_owned(),
            tools,
            force_tool: tool,
            facts,
        }) {
            debug!(turn, text = %asked, "brain: a speculative chat turn starts at the pause");
        }
    }

    fn seen(&mut self, data: &Data) {
        match percepts::detections(&data.payload) {
            Ok(found) => {
                for percept in found {
                    match percept {
                        Percept::One { name, args } => self.perceive(name, args),
                        Percept::Set { name, sets } => {
                            if let Err(e) =
                                self.brain
                                    .perceive_set(Instant::now().into_std(), name, sets)
                            {
                                self.percept_rejected(name, &e);
                            }
                        }
                    }
                }
            }
            Err(e) => {
                self.counters.bad_messages += 1;
                debug!("brain: bad message on Agent.detections: {e}");
            }
        }
    }

    /// The agent's own speech: `speaking` holds while it is audible.
    fn spoke(&mut self, data: &Data, channel: &Subscription) {
        let framed = channel
            .info()
            .is_some_and(|info| wire::speech_is_framed(&info.header));
        self.playout
            .chunk(Instant::now(), data.payload.len(), framed);
    }

    /// A `speech_stop` on `Agent.avatar` ends speech at once; one from a barge-in while the agent was audible
    /// is recorded in the rule trace with the reply it cut off.
    fn avatar(&mut self, data: &Data) {
        let Some(stop) = wire::speech_stop(&data.payload) else {
            return;
        };
        let audible = self.playout.speaking_until(Instant::now()).is_some();
        if stop.barge_in
            && audible
            && let Some(said) = self.saying.clone()
        {
            let now = self.now();
            let active = wire::rule_path(&self.active_rules());
            info!(said, "brain: the user barged in");
            let message = wire::interruption_message(
                now.clock.unix_ms,
                self.brain.program().origin(),
                &active,
                &said,
            );
            if let Ok(false) = self.rules.try_publish(message) {
                debug!("brain: the barge-in entry was dropped, the link is busy");
            }
        }
        if stop.barge_in {
            self.chat_interrupted();
        }
        self.playout.stop();
    }

    /// Generation of the running chat turn stops, and the trace says what the user heard of it.
    fn chat_interrupted(&mut self) {
        if let Some((turn, heard)) = self.chats.interrupt(Instant::now()) {
            info!(turn, heard, "brain: the chat turn is interrupted");
            self.chat_trace(turn, "interrupted", heard);
        }
    }

    /// One event of `Agent.chat.reply`.
    async fn chat_event(&mut self, data: &Data) {
        let event = match serde_json::from_slice::<ChatEvent>(&data.payload) {
            Ok(event) => event,
            Err(e) => {
                self.counters.bad_messages += 1;
                warn!("brain: bad message on {}: {e}", channels::CHAT_REPLY.name);
                return;
            }
        };
        if let ChatEvent::Sentence { text, index, .. } = &event
            && self.chats.running() == Some(event.turn())
        {
            self.echo.said(Instant::now().into_std(), text);
            // What the agent said last is the reply so far, for "say that again".
            let reply = match (index, self.saying.as_deref()) {
                (0, _) | (_, None) => text.clone(),
                (_, Some(before)) => format!("{before} {text}"),
            };
            self.brain.said(Instant::now().into_std(), &reply);
            self.saying = Some(reply);
        }
        let playout_end = self.playout.speaking_until(Instant::now());
        for next in self.chats.event(event, playout_end).await {
            self.chat_next(next).await;
        }
    }

    async fn chat_next(&mut self, next: Next) {
        match next {
            Next::Trace { turn, step, text } => self.chat_trace(turn, step, text),
            Next::Call {
                turn,
                service,
                payload,
            } => {
                let listed = self
                    .brain
                    .program()
                    .tools()
                    .iter()
                    .any(|tool| tool.service == service);
                let text = payload.to_string();
                if !listed {
                    warn!(
                        service,
                        "brain: the model called a service the program does not list"
                    );
                    let reason = format!("{service} is not a tool: {text}");
                    self.chat_trace(turn, "failed", reason.clone());
                    // Reported like any failed call, so the program can say so: a call is never dropped silently.
                    self.perceive("failed", vec![Value::Text(service), Value::Text(reason)]);
                    return;
                }
                self.chat_trace(turn, "call", format!("{service} {text}"));
                let action = Action::Call {
                    service,
                    payload: wire::value_from_json(payload),
                };
                self.actuators.perform(Effect::Fire(action)).await;
            }
            Next::Failed { turn, reason } => {
                warn!(turn, "brain: the chat turn failed: {reason}");
                self.chat_trace(turn, "failed", reason.clone());
                self.perceive(
                    "failed",
                    vec![Value::Text("chat".into()), Value::Text(reason)],
                );
            }
        }
    }

    fn chat_trace(&mut self, turn: u64, step: &str, text: String) {
        let now = self.now();
        let active = wire::rule_path(&self.active_rules());
        let message = wire::chat_message(
            now.clock.unix_ms,
            self.brain.program().origin(),
            &active,
            ChatStep {
                turn,
                step: step.to_owned(),
                text,
            },
        );
        if let Ok(false) = self.rules.try_publish(message) {
            debug!("brain: a chat trace entry was dropped, the link is busy");
        }
    }

    /// What the agent perceives now, for a chat turn.
    fn facts(&self, now: &Now, question: &str) -> Facts {
        let store = self.brain.store();
        let fresh = |name: &str, window: Duration| {
            store
                .named(name)
                .find(|fact| fact.is_fresh(now.at, Some(window)))
                .map(|fact| fact.args.clone())
        };
        let text = |value: Option<&Value>| {
            value.map(|v| v.as_text().map_or_else(|| v.to_string(), str::to_owned))
        };
        let face = fresh("face", Duration::from_millis(1500));
        let faces = face
            .as_ref()
            .and_then(|args| match args.first() {
                Some(Value::Num(n)) => Some(*n as u32),
                _ => None,
            })
            .unwrap_or(0);
        let field = |path: [&str; 2]| {
            now.clock
                .field(&path.map(str::to_owned))
                .map(|v| v.to_string())
                .unwrap_or_default()
        };
        let names: Vec<String> = store
            .named("acquaintance")
            .filter(|fact| fact.is_fresh(now.at, Some(Duration::from_millis(1500))))
            .filter_map(|fact| text(fact.args.first()))
            .collect();
        Facts {
            faces,
            face_where: face.as_ref().and_then(|args| text(args.get(1))),
            speaker_where: fresh("speaker", Duration::from_millis(1500))
                .and_then(|args| text(args.first())),
            names,
            code: fresh("code", Duration::from_secs(10)).and_then(|args| text(args.first())),
            motion: fresh("motion", Duration::from_millis(1500))
                .and_then(|args| text(args.first())),
            time: field(["time", "spoken"]),
            date: field(["date", "spoken"]),
            last_said: store
                .named(agent_brain::SAID)
                .next()
                .and_then(|fact| text(fact.args.first())),
            passages: self.shelf.passages(question),
        }
    }

    /// The services the program lets the model call.
    fn tools(&self) -> Vec<Tool> {
        self.brain
            .program()
            .tools()
            .iter()
            .map(|tool| Tool {
                service: tool.service.clone(),
                description: tool.description.clone(),
                args: tool.args.clone(),
            })
            .collect()
    }

    /// Starts a chat turn for `chat(T)` or `chat(T, "Service")`.
    fn chat(&mut self, now: &Now, text: &str, tool: Option<String>) {
        let tools = self.tools();
        let facts = self.facts(now, text);
        let reply = self.answering.map(|t| t.child("reply"));
        let passages: Vec<String> = facts
            .passages
            .iter()
            .map(|p| passage_line(&p.file, "", &p.text))
            .collect();
        let turn = self.chats.start(
            Ask {
                text: text.to_owned(),
                language: self.language.code().to_owned(),
                tools,
                force_tool: tool,
                facts,
            },
            reply,
        );
        for passage in passages {
            self.chat_trace(turn, "passage", passage);
        }
        match reply {
            Some(reply) => info!(turn, trace_id = %reply.trace, "brain: a chat turn starts"),
            None => debug!(turn, text, "brain: a chat turn starts"),
        }
    }

    /// `recall(T)`: says the knowledge folder's passage for `T`, or asserts `failed("recall", reason)` so that the
    /// program can hand the question on. The trace names the file and heading the answer came from.
    async fn recall(&mut self, text: &str) {
        let Some(hit) = self.shelf.recall(text) else {
            debug!(text, "brain: nothing in the knowledge folder answers it");
            self.perceive(
                "failed",
                vec![
                    Value::Text("recall".into()),
                    Value::Text("nothing in the knowledge folder answers it".into()),
                ],
            );
            return;
        };
        info!(file = %hit.file, heading = %hit.heading, "brain: recalled from the knowledge folder");
        self.chat_trace(
            0,
            "passage",
            passage_line(&hit.file, &hit.heading, &hit.text),
        );
        self.echo.said(Instant::now().into_std(), &hit.text);
        self.brain.said(Instant::now().into_std(), &hit.text);
        self.saying = Some(hit.text.clone());
        self.actuators
            .perform(Effect::Fire(Action::Say { text: hit.text }))
            .await;
    }

    fn outcome(&mut self, outcome: Outcome) {
        debug!(?outcome, "brain: outcome");
        let (name, args) = outcome.percept();
        self.perceive(name, args);
    }

    async fn each_second(&mut self, ctx: &ModuleContext) {
        match self.file.reload_if_changed() {
            Reload::Unchanged => {}
            Reload::Loaded(program) => {
                self.counters.reloads += 1;
                self.counters.last_reload_error = None;
                info!(rules = program.rule_count(), "brain: program reloaded");
                self.brain.reload(program);
            }
            Reload::Failed(message) => {
                self.counters.reload_errors += 1;
                warn!(
                    "brain: the changed program does not load, the previous one keeps running:\n{message}"
                );
                self.counters.last_reload_error = Some(message);
            }
        }
        self.refresh_db().await;
        ctx.report(self.status());
    }

    /// Re-reads the pair-database keys the program uses (none for most programs, then this costs nothing).
    async fn refresh_db(&mut self) {
        let keys: Vec<String> = self.brain.program().db_keys().map(str::to_owned).collect();
        self.db.retain(|key, _| keys.contains(key));
        for key in keys {
            match self.client.var_get(&key).await {
                Ok(Some(value)) => {
                    self.db.insert(key, wire::value_from_json(value));
                }
                Ok(None) => {
                    self.db.remove(&key);
                }
                Err(e) => debug!(key, "brain: pair database read failed: {e}"),
            }
        }
    }

    /// Re-evaluates the program and performs what changed.
    async fn step(&mut self) {
        self.ponder();
        let now = self.now();
        // `speaking` follows the play-out of the agent's speech.
        let speaking = self
            .playout
            .speaking_until(Instant::from_std(now.at))
            .is_some();
        let was_speaking = self.brain.store().named("speaking").next().is_some();
        if speaking && !was_speaking {
            self.perceive("speaking", Vec::new());
        } else if !speaking && was_speaking {
            self.brain.retract("speaking");
        }
        let step = self.brain.step(&now, &self.db);
        self.counters.steps += 1;
        for warning in &step.warnings {
            warn!("brain: {warning}");
        }
        for trace in &step.traces {
            self.counters.rule_changes += 1;
            info!("brain: {trace}");
            let message = wire::trace_message(trace, self.brain.program().origin());
            if let Ok(false) = self.rules.try_publish(message) {
                debug!("brain: a trace was dropped, the link is busy");
            }
        }
        for effect in step.effects {
            if let Effect::Fire(Action::Say { text }) | Effect::Start(Action::Say { text }) =
                &effect
            {
                self.echo.said(now.at, text);
                self.saying = Some(text.clone());
            }
            if matches!(effect, Effect::Fire(Action::Cancel)) {
                self.chat_interrupted();
                self.playout.stop();
            }
            match effect.action() {
                Action::Chat { text, tool } if !matches!(effect, Effect::Stop(_)) => {
                    let (text, tool) = (text.clone(), tool.clone());
                    self.chat(&now, &text, tool);
                    continue;
                }
                Action::ForgetConversation => {
                    self.chats.forget();
                    continue;
                }
                Action::Recall { text } => {
                    let text = text.clone();
                    self.recall(&text).await;
                    continue;
                }
                _ => {}
            }
            self.actuators.perform(effect).await;
        }
        // The final transcript's step has run: a speculative reply it did not adopt is stopped.
        if std::mem::take(&mut self.heard_final) {
            self.chats.drop_early();
        }
    }

    /// The active rules, outermost first, as traces name them.
    fn active_rules(&self) -> Vec<String> {
        self.brain
            .active()
            .iter()
            .map(ToString::to_string)
            .collect()
    }

    fn status(&self) -> serde_json::Value {
        let c = &self.counters;
        let active = self.active_rules();
        serde_json::json!({
            "program": self.file.path().display().to_string(),
            "active": active,
            "transcripts": c.transcripts,
            "echoes_dropped": c.echoes_dropped,
            "bad_messages": c.bad_messages,
            "steps": c.steps,
            "rule_changes": c.rule_changes,
            "reloads": c.reloads,
            "reload_errors": c.reload_errors,
            "last_reload_error": c.last_reload_error,
            "outcomes_dropped": self.actuators.dropped_outcomes,
        })
    }
}

/// A passage as the trace shows it: where it came from, then its words.
fn passage_line(file: &str, heading: &str, text: &str) -> String {
    if heading.is_empty() {
        format!("{file}: {text}")
    } else {
        format!("{file} ({heading}): {text}")
    }
}
