//! Speech recognition across federated hubs (docs/federation.md, docs/asr.md): the microphone on hub A, two real
//! `whisper-sat` on A and one on hub B, which hears A's audio through the federation, claims utterances there and
//! submits to A's relay. The satellite on B is killed with SIGKILL while it holds a claim: a satellite on A
//! transcribes that speech instead, once, and no utterance is transcribed twice.
//!
//! B's satellite is named to sort first, so that it keeps the speech when a satellite on A claims it in the same
//! instant (`claim::yields_to`): the satellite on A that gave way must then take the speech back when B's claim
//! dies, although B named it a millisecond apart (its hub stamps the audio a hop later).
//!
//! Needs the binaries (`flow-hub`, `flowctl`, `whisper-sat`) and the model (`make model`); `make test` provides both.

use agent_contract::channels as ch;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use agent_tests::{Agent, DataDir, Satellite, fixture, free_port, run};
use anyhow::Context;
use flow::{Client, ClientEvent};
use serde_json::Value;

const TRANSCRIPT_PATIENCE: Duration = Duration::from_secs(120);
const QUIET: Duration = Duration::from_secs(4);
/// The satellite on hub B: its name sorts before the satellites' on A ("fed-a1", "fed-a2").
const VICTIM: &str = "fed-0b";
const CLIPS: [&str; 5] = [
    "LJ001-0001",
    "LJ001-0002",
    "LJ001-0004",
    "sb_example1",
    "jfk",
];

fn quoted(list: &[String]) -> String {
    let q: Vec<String> = list.iter().map(|s| format!("{s:?}")).collect();
    format!("[{}]", q.join(", "))
}

async fn until_channel(client: &Client, name: &str) -> anyhow::Result<()> {
    agent_tests::until_channel(client, name, TRANSCRIPT_PATIENCE)
        .await
        .map(drop)
}

/// A claim channel's holder and interval, from its name and header.
fn claim_header(name: &str, header: &str) -> Option<(String, (u64, u64))> {
    name.strip_prefix(ch::ASR_CLAIM_PREFIX)?;
    let h: Value = serde_json::from_str(header).ok()?;
    Some((
        h["satellite"].as_str()?.to_string(),
        (h["start_us"].as_u64()?, h["end_us"].as_u64()?),
    ))
}

fn overlap_us(a: (u64, u64), b: (u64, u64)) -> u64 {
    a.1.min(b.1).saturating_sub(a.0.max(b.0))
}

/// The next claim to appear (by `holder` when given): its channel name and interval.
async fn next_claim(
    events: &mut tokio::sync::broadcast::Receiver<ClientEvent>,
    holder: Option<&str>,
) -> Option<(String, (u64, u64))> {
    loop {
        match events.recv().await {
            Ok(ClientEvent::ChannelAdded(info)) => {
                if let Some((by, span)) = claim_header(&info.name, &info.header)
                    && holder.is_none_or(|h| h == by)
                {
                    return Some((info.name, span));
                }
            }
            Ok(_) | Err(tokio::sync::broadcast::error::RecvError::Lagged(_)) => {}
            Err(_) => return None,
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_satellite_on_another_hub_shares_the_work_and_its_killed_claim_is_transcribed_once()
-> anyhow::Result<()> {
    let (da, db) = (DataDir::new()?, DataDir::new()?);
    let (pa, pb) = (free_port()?, free_port()?);
    // Everything the satellites coordinate through: claims, presence and the relay's submission service.
    let asr = format!("{}*", ch::ASR_CLAIM_PREFIX.trim_end_matches("claim."));
    let section = |name: &str,
                   listen: u16,
                   connect: Option<u16>,
                   export: &[String],
                   import: &[String]| {
        format!(
            "[federation]\nenabled = true\nname = {name:?}\nlisten = [\"tcp/127.0.0.1:{listen}\"]\nconnect = {}\nexport = {}\nimport = {}\nlease_ms = 1000\n",
            quoted(
                &connect
                    .map(|p| format!("tcp/127.0.0.1:{p}"))
                    .into_iter()
                    .collect::<Vec<_>>()
            ),
            quoted(export),
            quoted(import),
        )
    };
    let microphone = [ch::AUDIO.name.to_string(), ch::TRANSCRIPT.name.to_string()];
    let a = Agent::hub_with_config(
        &da,
        &section(
            "hub-a",
            pa,
            None,
            &[microphone[0].clone(), microphone[1].clone(), asr.clone()],
            std::slice::from_ref(&asr),
        ),
    )
    .await?;
    let b = Agent::hub_with_config(
        &db,
        &section(
            "hub-b",
            pb,
            Some(pa),
            std::slice::from_ref(&asr),
            &[microphone[0].clone(), microphone[1].clone(), asr.clone()],
        ),
    )
    .await?;

    let transcripts: Arc<Mutex<Vec<Value>>> = Arc::default();
    let reader = a.client("fed-asr-transcripts").await?;
    let sub = reader.subscribe(ch::TRANSCRIPT.name).await?;
    {
        let sink = transcripts.clone();
        tokio::spawn(async move {
            while let Some(d) = sub.recv().await {
                if let Ok(v) = serde_json::from_slice::<Value>(&d.payload)
                    && v.get("text").is_some()
                {
                    sink.lock()
                        .unwrap_or_else(std::sync::PoisonError::into_inner)
                        .push(v);
                }
            }
        });
    }
    let _a1 = Satellite::start(&a, "fed-a1").await?;
    let _a2 = Satellite::start(&a, "fed-a2").await?;
    // The relay lives on A; B's satellite must find its channels imported, not take the role on B.
    let on_b = b.client("fed-asr-watch-b").await?;
    until_channel(&on_b, ch::TRANSCRIPT.name).await?;
    until_channel(&on_b, ch::ASR_SUBMIT.name).await?;
    let mut victim = Satellite::start_with(&b, VICTIM, &["--no-relay"]).await?;
    // A sees B's satellite (its presence crosses), so the work is spread over three.
    let on_a = a.client("fed-asr-watch-a").await?;
    until_channel(&on_a, &format!("{}{VICTIM}", ch::ASR_PRESENCE_PREFIX)).await?;

    let mut events = on_a.events();
    let mut killed: Option<(u64, u64)> = None;
    for clip in CLIPS {
        let cmd = a.microphone(fixture(&format!("audio/{clip}.wav"))?, 1500)?;
        let publishing = tokio::spawn(run(cmd, b"", TRANSCRIPT_PATIENCE));
        if killed.is_none() {
            // Watch the claims that reach A while the clip plays: one made on B names B's satellite. It counts once
            // it has held its speech alone for 150 ms (far longer than a hop between the hubs, shorter than the
            // end of the utterance that must come before the holder may submit): a satellite on A that claimed the
            // same speech in the same instant has given way by then (B's name sorts first).
            let sole = tokio::time::timeout(Duration::from_secs(20), async {
                loop {
                    let (name, span) = next_claim(&mut events, Some(VICTIM)).await?;
                    let watch = tokio::time::sleep(Duration::from_millis(150));
                    tokio::pin!(watch);
                    let mut rivals = std::collections::HashSet::new();
                    let mut lost = false;
                    loop {
                        tokio::select! {
                            () = &mut watch => break,
                            event = events.recv() => match event {
                                Ok(ClientEvent::ChannelAdded(info)) => {
                                    if let Some(h) = claim_header(&info.name, &info.header)
                                        && h.0 != VICTIM
                                        && overlap_us(h.1, span) > 200_000
                                    {
                                        rivals.insert(info.name);
                                    }
                                }
                                Ok(ClientEvent::ChannelRemoved { name: gone, .. }) => {
                                    lost |= gone == name;
                                    rivals.remove(&gone);
                                }
                                // Already transcribed: killing its holder now tests nothing.
                                Ok(ClientEvent::HeaderChanged { name: changed, header, .. })
                                    if changed == name && header.contains("\"done\":true") =>
                                {
                                    lost = true;
                                }
                                _ => {}
                            },
                        }
                    }
                    if !lost && rivals.is_empty() {
                        return Some(span);
                    }
                    println!("{VICTIM}'s claim {span:?}: lost {lost}, rivals {rivals:?}; waiting for another");
                }
            })
            .await
            .ok()
            .flatten();
            if let Some(span) = sole {
                victim.child.start_kill()?; // SIGKILL: the claim on B dies with its holder
                victim.child.wait().await?;
                println!(
                    "killed {VICTIM} holding the claim {span:?} alone (seen on hub A) during {clip}"
                );
                killed = Some(span);
            }
        }
        publishing.await??.ok()?;
        if killed.is_some() {
            break;
        }
    }
    let (start, end) = killed.context("the satellite on hub B never claimed an utterance")?;

    // Settle: every claim of A's own satellites done and no new transcript for a while. (Claims imported from B
    // mirror B's; B's holder is dead and its hub takes them away.)
    let deadline = tokio::time::Instant::now() + TRANSCRIPT_PATIENCE * 2;
    let mut quiet: Option<(tokio::time::Instant, usize)> = None;
    loop {
        let claims = on_a.channels().await?;
        let open: Vec<String> = claims
            .iter()
            .filter(|c| {
                c.name.starts_with(ch::ASR_CLAIM_PREFIX)
                    && !c.owner.starts_with("federation#")
                    && !c.header.contains("\"done\":true")
            })
            .map(|c| format!("{} ({}): {}", c.name, c.owner, c.header))
            .collect();
        anyhow::ensure!(
            tokio::time::Instant::now() < deadline,
            "the satellites did not finish; claims still open on hub A: {open:?}"
        );
        let n = transcripts
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .len();
        match quiet {
            Some((since, m)) if m == n && open.is_empty() => {
                if since.elapsed() >= QUIET {
                    break;
                }
            }
            _ => quiet = Some((tokio::time::Instant::now(), n)),
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    let got = transcripts
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .clone();
    println!("{got:#?}");
    // No utterance twice: transcripts never overlap in time.
    let mut spans: Vec<(u64, u64)> = got
        .iter()
        .filter_map(|t| Some((t["start_us"].as_u64()?, t["end_us"].as_u64()?)))
        .collect();
    spans.sort_unstable();
    for w in spans.windows(2) {
        assert!(w[0].1 <= w[1].0, "overlapping transcripts {w:?}: {got:?}");
    }
    // The killed claim's speech: transcribed once, by a satellite on A (B's clock is a hop behind A's, so the
    // speech is matched by overlap, as the satellites match it).
    let overlap = |t: &Value| {
        let span = (
            t["start_us"].as_u64().unwrap_or(0),
            t["end_us"].as_u64().unwrap_or(0),
        );
        overlap_us(span, (start, end)) > 200_000
    };
    let of_it: Vec<&Value> = got.iter().filter(|t| overlap(t)).collect();
    assert_eq!(of_it.len(), 1, "the killed claim's speech: {of_it:?}");
    let by = of_it[0]["satellite"].as_str().unwrap_or_default();
    println!("the killed claim's speech was transcribed by {by}");
    // B's own transcript only if it submitted in the instant between the watch and the kill.
    assert!(
        ["fed-a1", "fed-a2", VICTIM].contains(&by),
        "transcribed by {by}"
    );
    assert!(
        !of_it[0]["text"]
            .as_str()
            .unwrap_or_default()
            .trim()
            .is_empty(),
        "an empty transcript"
    );
    Ok(())
}
