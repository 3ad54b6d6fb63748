//! Texts made in the voice's cache without being played (`Agent.say` with `prepare`: the brain's fixed replies at
//! start). Each is an utterance of the engine whose audio goes nowhere; speech asked for meanwhile stops them, so a
//! preparation holds a reply back by at most the network run under way (docs/voice.md, "The cache").

use agent_voice::{CancelToken, Engine, Synthesizer, Utterance, VoiceSettings};
use flow::ServiceCall;
use tokio::task::JoinSet;
use tracing::debug;

use super::wire;

/// Preparations under way at once; more are refused (the brain asks one at a time).
const AT_ONCE: usize = 2;

/// The preparations under way, each a task that answers its call when the text is in the cache.
#[derive(Debug, Default)]
pub struct Preparations {
    tasks: JoinSet<()>,
    tokens: Vec<CancelToken>,
}

impl Preparations {
    /// Prepares `text` in `voice` and answers `call` once it is in the cache (`{"cached": true}`); at once with
    /// `{"cached": false}` for a voice without a cache (espeak-ng, which needs none), and with an error when too
    /// many are under way.
    pub fn start(
        &mut self,
        synth: &Synthesizer,
        voice: &VoiceSettings,
        text: &str,
        call: ServiceCall,
    ) {
        let started: Result<Option<Utterance>, String> = if voice.engine != Engine::Piper {
            Ok(None)
        } else if self.tasks.len() >= AT_ONCE {
            Err(format!("{AT_ONCE} texts are being prepared already"))
        } else {
            synth
                .speak(text, voice)
                .map(Some)
                .map_err(|e| e.to_string())
        };
        if let Ok(Some(utterance)) = &started {
            self.tokens.push(utterance.cancel_token());
        }
        self.tasks.spawn(async move {
            let answer = match started {
                Ok(Some(utterance)) => utterance
                    .collect()
                    .await
                    .map(|recording| wire::prepared(!recording.cancelled))
                    .map_err(|e| e.to_string()),
                Ok(None) => Ok(wire::prepared(false)),
                Err(reason) => Err(reason),
            };
            if let Err(e) = call.respond(answer).await {
                debug!("tts: answer to a preparation not delivered: {e}");
            }
        });
    }

    /// Stops every preparation under way: speech was asked for, and it comes first.
    pub fn stop(&mut self) {
        for token in self.tokens.drain(..) {
            token.cancel();
        }
    }

    /// Waits for a preparation to finish; never returns while none is under way.
    pub async fn finished(&mut self) {
        if self.tasks.join_next().await.is_none() {
            std::future::pending::<()>().await;
        }
        if self.tasks.is_empty() {
            self.tokens.clear();
        }
    }
}
