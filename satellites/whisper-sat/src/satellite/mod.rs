//! The satellite: listens, claims utterances through the hub, transcribes them, submits transcripts.
//!
//! Every satellite segments the same `Agent.audio` stream and finds the same utterances. An idle satellite claims
//! the oldest utterance it knows by creating its claim channel (see `crate::claim`); the hub grants the name
//! to one. The holder transcribes, submits the transcript to the relay and marks its claim done in the claim's
//! header; the others drop the utterance when they see the transcript or the done mark. A holder that dies loses
//! its channels, the hub says so, and the others claim the utterance again. See docs/asr.md.
//!
//! With speculation (the default) utterances become claimable when they pause, before the hangover has ended them:
//! the holder decodes during the hangover and submits the result once the utterance ends unchanged, never before
//! (see `crate::speculation`). A claim stays with the holder when the voice resumes, since its id is the
//! utterance's start.
//!
//! The parts: `audio` listens (the segmentation thread and the subscriptions that feed it), `relay` takes the
//! transcript relay role, `worker` holds the transcriber, the claim and the decode in flight, `claiming` takes and
//! finishes claims on the hub, and `event_loop` handles each input as it comes. `run` here starts them and stops
//! them.

mod audio;
mod claiming;
mod error;
mod event_loop;
mod relay;
mod settings;
mod worker;

use flow::Client;
use std::collections::HashSet;
use std::sync::atomic::Ordering;
use tokio::sync::watch;

use crate::claim::PRESENCE_PREFIX;
use crate::transcriber::Transcriber;
pub use error::SatelliteError;
use event_loop::Satellite;
pub use settings::Settings;

/// Runs a satellite until the client closes or Ctrl-C.
pub async fn run(
    client: Client,
    transcriber: Transcriber,
    settings: Settings,
) -> Result<(), SatelliteError> {
    let presence = client
        .publisher(
            &format!("{PRESENCE_PREFIX}{}", settings.name),
            &serde_json::json!({ "model": transcriber.model_name(), "threads": transcriber.config().threads })
                .to_string(),
        )
        .await
        .map_err(SatelliteError::Presence)?;
    let (enabled_tx, enabled_rx) = watch::channel(true);
    let (listener, utterances) =
        audio::Listener::start(settings.segmenter.clone(), settings.speculate)?;
    let tasks = [
        tokio::spawn(audio::follow_ctrl(client.clone(), enabled_tx)),
        tokio::spawn(audio::follow_audio(
            client.clone(),
            listener.clone(),
            enabled_rx.clone(),
        )),
        tokio::spawn(audio::follow_speech(
            client.clone(),
            listener.clone(),
            settings.echo_gate,
        )),
        tokio::spawn(relay::relay(
            client.clone(),
            settings.name.clone(),
            listener.activity.clone(),
            settings.relay,
        )),
    ];
    let transcripts = client.subscribe(relay::TRANSCRIPT).await?;
    let events = client.events();
    let peers: HashSet<String> = client
        .channels()
        .await?
        .into_iter()
        .filter(|c| c.name.starts_with(PRESENCE_PREFIX) && c.name != presence.name())
        .map(|c| c.name)
        .collect();
    let dropped = listener.dropped.clone();
    let mut sat = Satellite::new(
        client.clone(),
        transcriber,
        settings,
        presence.name().to_owned(),
        listener,
        peers,
    );
    sat.listen(utterances, transcripts, events).await?;
    for t in tasks {
        t.abort();
    }
    let dropped = dropped.load(Ordering::Relaxed);
    tracing::info!(dropped, "satellite stopped");
    drop(presence);
    Ok(())
}
