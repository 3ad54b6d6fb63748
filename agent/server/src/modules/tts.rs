//! The TTS module: speaks for the agent. It takes requests on the `Agent.say` service (and `{"say": ...}` on
//! `Agent.ctrl`), synthesises them (`agent-voice`: the Piper voice for English, espeak-ng for other languages and
//! for requests naming an espeak-ng voice) sentence by sentence, streams the PCM on
//! `Agent.speech` and the matching visemes, caption and stop commands on `Agent.avatar`, and stops talking when
//! the user starts to (barge-in). It also owns the behaviour controllers (blink, gaze, listening), which share
//! its `Agent.avatar` publisher. See docs/voice.md.

mod avatar_out;
pub mod behaviour;
pub mod params;
mod prepare;
pub mod speaker;
pub mod wire;

use std::sync::Arc;

use agent_brain::Language;
use agent_voice::{Engine, Synthesizer, SynthesizerConfig, VoiceSettings};
use anyhow::Context;
use bytes::Bytes;
use flow::tick::Tick;
use tokio::time::Instant;
use tracing::{debug, info, warn};

use agent_contract::avatar::AvatarCommand;
use agent_contract::channels;
use avatar_out::AvatarOut;
use behaviour::Event;
use flow_hub::module::{Module, ModuleContext, ModuleFuture};
use params::TtsParams;
use speaker::{Counters, Outputs, Speaker};
use wire::{CancelTarget, Hearing, SayRequest, VoiceChoice};

/// The built-in TTS module (`[modules.tts]`), speaking the agent's language unless its section names a voice.
#[derive(Debug, Default)]
pub struct TtsModule {
    pub language: Language,
}

impl Module for TtsModule {
    fn name(&self) -> &'static str {
        "tts"
    }

    fn check(&self, params: &serde_json::Value) -> anyhow::Result<()> {
        // A missing or damaged voice stops the server here, at start, rather than leaving it mute.
        TtsParams::from_json(params)?.check_files(self.language)
    }

    fn run(self: Box<Self>, ctx: ModuleContext) -> ModuleFuture {
        Box::pin(run(ctx, self.language))
    }
}

/// Everything the request handlers need.
struct Tts {
    synth: Synthesizer,
    voice: VoiceSettings,
    speaker: Speaker,
    avatar: AvatarOut,
    behaviour: behaviour::Sender,
    barge_in: bool,
    counters: Arc<Counters>,
}

async fn run(mut ctx: ModuleContext, language: Language) -> anyhow::Result<()> {
    let params = TtsParams::from_json(&ctx.params)?;
    let engine_config = SynthesizerConfig {
        data_path: params.data_path.clone(),
        chunk_ms: params.chunk_ms,
        queue_capacity: 16,
        chunk_queue: 64,
        piper: params.piper_for(language),
    };
    // Loading espeak-ng's data takes a few milliseconds of blocking file reads, the Piper voice about a second: it
    // loads while the channels are made, so that `Agent.say` exists from the start and an early request waits in
    // the service's queue instead of finding no such channel.
    let engine = tokio::task::spawn_blocking(move || Synthesizer::start(engine_config));
    let client = ctx.client.clone();
    let speech = client
        .publisher(
            channels::SPEECH.name,
            &channels::headers::speech(agent_voice::SAMPLE_RATE, params.chunk_ms),
        )
        .await?;
    // The visemes, captions and behaviour commands all need this channel; another owner (a module started
    // earlier) would leave the avatar without lip-sync, so that is an error naming the cause.
    let avatar = client.publisher(channels::AVATAR.name, channels::headers::AVATAR).await.with_context(|| {
        format!("[modules.tts] cannot own {}: start the tts module before any other publisher of it", channels::AVATAR.name)
    })?;
    let avatar = AvatarOut(Arc::new(avatar));
    let mut service = client
        .serve(channels::SAY.name, channels::headers::SAY)
        .await?;
    let ctrl = client.subscribe(channels::CTRL.name).await?;
    let transcripts = client.subscribe(channels::TRANSCRIPT.name).await?;
    let detections = client.subscribe(channels::DETECTIONS.name).await?;
    let synth = engine
        .await
        .context("starting the speech engine")?
        .context("[modules.tts] starting the speech engine")?;
    anyhow::ensure!(
        synth.sample_rate() == agent_voice::SAMPLE_RATE,
        "[modules.tts] the speech engine speaks at {} Hz, {} is announced at {}",
        synth.sample_rate(),
        channels::SPEECH.name,
        agent_voice::SAMPLE_RATE
    );

    let (behaviour, events) = behaviour::channel();
    if params.behaviour.enabled {
        tokio::spawn(behaviour::run(
            params.behaviour.clone(),
            avatar.clone(),
            events,
        ));
    }
    let counters = Arc::new(Counters::default());
    let speaker = Speaker::start(Outputs {
        speech: Arc::new(speech),
        avatar: avatar.clone(),
        behaviour: behaviour.clone(),
        sample_rate: synth.sample_rate(),
        lead: params.lead(),
        counters: counters.clone(),
        telemetry: ctx.telemetry(),
    });
    let tts = Tts {
        synth,
        voice: params.voice_settings(language),
        speaker,
        avatar,
        behaviour,
        barge_in: params.barge_in,
        counters,
    };
    info!(engine = ?tts.voice.engine, voice = %tts.voice.voice, rate = tts.voice.rate_wpm, "tts: speaking on {} and {}", channels::SPEECH.name, channels::AVATAR.name);

    // Texts made in the voice's cache ahead (`prepare`), stopped by any speech asked for.
    let mut preparing = prepare::Preparations::default();
    let mut ticks = ctx.ticks();
    loop {
        tokio::select! {
            () = ctx.stopped() => break,
            call = service.next() => {
                let Some(call) = call else { break };
                let answer = match wire::say_request(&call.payload) {
                    Ok(SayRequest::Prepare { text }) => {
                        preparing.start(&tts.synth, &tts.voice, &text, call);
                        continue;
                    }
                    Ok(request) => {
                        if matches!(request, SayRequest::Say { .. }) {
                            preparing.stop();
                        }
                        tts.request(request).await
                    }
                    Err(reason) => Err(format!("bad {} request: {reason}", channels::SAY.name)),
                };
                if let Err(e) = call.respond(answer).await {
                    debug!("tts: answer not delivered: {e}");
                }
            }
            () = preparing.finished() => {}
            data = ctrl.recv() => {
                let Some(data) = data else { break };
                if let Some(request) = wire::ctrl_request(&data.payload) {
                    if matches!(request, SayRequest::Say { .. }) {
                        preparing.stop();
                    }
                    if let Err(reason) = tts.request(request).await {
                        warn!("tts: {} request failed: {reason}", channels::CTRL.name);
                    }
                }
            }
            data = transcripts.recv() => {
                let Some(data) = data else { break };
                if let Some(hearing) = wire::hearing(&data.payload) {
                    tts.heard(hearing).await;
                }
            }
            latest = detections.recv_latest() => {
                let Some((data, _skipped)) = latest else { break };
                tts.behaviour.send(Event::Seen(wire::sighting(&data.payload)));
            }
            tick = ticks.recv() => {
                if matches!(tick, Ok(Tick::OneSec)) {
                    ctx.report(tts.status());
                }
            }
        }
    }
    tts.speaker.cancel(CancelTarget::All);
    Ok(())
}

impl Tts {
    /// Carries out a `say` or `cancel` request; the answer goes back to the caller.
    async fn request(&self, request: SayRequest) -> Result<Bytes, String> {
        match request {
            SayRequest::Say {
                text,
                choice,
                trace,
            } => {
                let voice = self.voice_for(choice);
                let utterance = self.speaker.say(&self.synth, &text, &voice, trace)?;
                debug!(utterance, %text, "tts: queued");
                Ok(wire::said(utterance))
            }
            SayRequest::Cancel(target) => {
                let stopped = self.speaker.cancel(target);
                if target == CancelTarget::All {
                    // The page may still be playing audio already sent; it stops on this command.
                    self.avatar
                        .send(&AvatarCommand::SpeechStop {
                            utterance: None,
                            barge_in: false,
                        })
                        .await;
                }
                Ok(wire::cancelled(&stopped))
            }
            // The service loop hands these to `prepare::Preparations`, which answers them when they are done.
            SayRequest::Prepare { .. } => Err("prepare is taken on Agent.say only".into()),
            SayRequest::Mood(mood) => {
                self.behaviour.send(Event::Mood(mood));
                Ok(Bytes::from_static(b"{}"))
            }
        }
    }

    /// Follows the user's voice: barge-in, and the listening and thinking behaviour.
    async fn heard(&self, hearing: Hearing) {
        match hearing {
            Hearing::Speaking => {
                if self.barge_in && self.speaker.is_audible(Instant::now()) {
                    let stopped = self.speaker.cancel(CancelTarget::All);
                    self.avatar
                        .send(&AvatarCommand::SpeechStop {
                            utterance: None,
                            barge_in: true,
                        })
                        .await;
                    Counters::bump(&self.counters.barge_ins);
                    info!(?stopped, "tts: barge-in, the user speaks");
                }
                self.behaviour.send(Event::UserSpeaking);
            }
            Hearing::Paused => self.behaviour.send(Event::UserPaused),
            Hearing::Said => self.behaviour.send(Event::Heard),
        }
    }

    /// The configured voice with a request's changes; a request that names a voice names an espeak-ng one.
    fn voice_for(&self, choice: VoiceChoice) -> VoiceSettings {
        VoiceSettings {
            engine: if choice.voice.is_some() {
                Engine::Espeak
            } else {
                self.voice.engine
            },
            voice: choice.voice.unwrap_or_else(|| self.voice.voice.clone()),
            rate_wpm: choice.rate_wpm.unwrap_or(self.voice.rate_wpm),
            pitch: choice.pitch.unwrap_or(self.voice.pitch),
            ..self.voice.clone()
        }
    }

    fn status(&self) -> serde_json::Value {
        let mut status = self.counters.to_json();
        if let Some(object) = status.as_object_mut() {
            object.insert("voice".into(), self.voice.voice.clone().into());
            object.insert(
                "engine".into(),
                match self.voice.engine {
                    Engine::Piper => "piper",
                    Engine::Espeak => "espeak",
                }
                .into(),
            );
            object.insert(
                "speaking".into(),
                self.speaker.is_audible(Instant::now()).into(),
            );
            object.insert(
                "behaviour_events_dropped".into(),
                self.behaviour.dropped().into(),
            );
            // The Piper voice's network runs and the sentences its cache played instead (docs/voice.md).
            let stats = self.synth.stats();
            object.insert("piper_runs".into(), stats.piper_runs.into());
            object.insert("piper_cache_hits".into(), stats.piper_cache_hits.into());
        }
        status
    }
}
