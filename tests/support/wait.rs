//! Waiting on hub events with the tests' generous bound, failing with a clear
//! message instead of hanging.
//!
//! A loop that reads a stream until some message arrives has one overall deadline ([`recv_until`], [`until`]),
//! never only a timeout per receive: on a busy stream (the avatar's blinks and gaze) every single receive succeeds
//! in time and such a loop would wait forever for a message that never comes.

use std::future::Future;
use std::time::Duration;

use anyhow::{Context, anyhow, bail};
use flow::{Data, Publisher, Subscription};

/// A generous bound for anything a test waits on: the machine may be busy
/// building other crates, and tests never assert on durations.
pub const PATIENCE: Duration = Duration::from_secs(30);

/// The next message of a subscription, or an error after [`PATIENCE`].
pub async fn recv(sub: &Subscription) -> anyhow::Result<Data> {
    tokio::time::timeout(PATIENCE, sub.recv())
        .await
        .with_context(|| format!("no message on {} in time", sub.name()))?
        .context("subscription ended")
}

/// Waits until the hub tells `publisher` that someone subscribes to its channel.
pub async fn until_subscribed(publisher: &Publisher) -> anyhow::Result<()> {
    let mut watch = publisher.subscribers();
    tokio::time::timeout(PATIENCE, watch.wait_for(|on| *on))
        .await
        .with_context(|| format!("nobody subscribed to {} in time", publisher.name()))?
        .context("client closed")?;
    Ok(())
}

/// Waits until the last subscriber of `publisher`'s channel has left.
pub async fn until_unsubscribed(publisher: &Publisher) -> anyhow::Result<()> {
    let mut watch = publisher.subscribers();
    tokio::time::timeout(PATIENCE, watch.wait_for(|on| !*on))
        .await
        .with_context(|| format!("{} kept its subscribers", publisher.name()))?
        .context("client closed")?;
    Ok(())
}

/// The next payload of a subscription, unbounded: for loops that wait on several subscriptions inside a deadline of
/// their own ([`until`]).
pub async fn next_payload(sub: &Subscription) -> anyhow::Result<bytes::Bytes> {
    Ok(sub
        .recv()
        .await
        .with_context(|| format!("{} ended", sub.name()))?
        .payload)
}

/// Receives on `sub` until `pick` returns `Some` for a message, for at most `patience` in all (one deadline for the
/// whole wait, however many other messages keep arriving). Fails naming `what`, the channel, how many messages
/// went by and the last of them. Says on stderr what it waits for, so that a test the harness kills shows it.
pub async fn recv_until<T>(
    sub: &Subscription,
    what: &str,
    patience: Duration,
    mut pick: impl FnMut(&Data) -> Option<T>,
) -> anyhow::Result<T> {
    announce(what, Some(sub.name()), patience);
    // One deadline for every receive, checked between messages too: a receive that is always ready would otherwise
    // never see it pass.
    let deadline = tokio::time::Instant::now() + patience;
    let mut seen = 0usize;
    let mut last = None;
    let ended = loop {
        if tokio::time::Instant::now() >= deadline {
            break false;
        }
        match tokio::time::timeout_at(deadline, sub.recv()).await {
            Ok(Some(data)) => {
                seen += 1;
                if let Some(v) = pick(&data) {
                    return Ok(v);
                }
                last = Some(data);
            }
            Ok(None) => break true,
            Err(_) => break false,
        }
    };
    let last = last.map_or_else(|| "none".to_owned(), |d| short(&d.payload));
    if ended {
        bail!(
            "{} ended while waiting for {what}: {seen} message(s) seen, the last {last}",
            sub.name()
        );
    }
    bail!(
        "timed out after {} s waiting for {what} on {}: {seen} message(s) seen, the last {last}",
        patience.as_secs_f64(),
        sub.name()
    )
}

/// Runs `fut` (a loop that reads streams until something arrives: several subscriptions in a `select!`, a
/// WebSocket, a child's output) for at most `patience` in all, failing with an error naming `what`. Says on stderr
/// what it waits for, so that a test the harness kills shows it.
pub async fn until<F: Future>(what: &str, patience: Duration, fut: F) -> anyhow::Result<F::Output> {
    announce(what, None, patience);
    tokio::time::timeout(patience, fut).await.map_err(|_| {
        anyhow!(
            "timed out after {} s waiting for {what}",
            patience.as_secs_f64()
        )
    })
}

/// The one line a wait prints when it begins.
fn announce(what: &str, channel: Option<&str>, patience: Duration) {
    let on = channel.map(|c| format!(" on {c}")).unwrap_or_default();
    eprintln!("waiting up to {} s for {what}{on}", patience.as_secs_f64());
}

/// A message, short: its text (JSON or other UTF-8) cut at 160 characters, else its size.
pub fn short(payload: &[u8]) -> String {
    match std::str::from_utf8(payload) {
        Ok(text) if text.chars().count() > 160 => {
            format!(
                "{}... ({} bytes)",
                text.chars().take(160).collect::<String>(),
                payload.len()
            )
        }
        Ok(text) => text.to_owned(),
        Err(_) => format!("{} bytes of binary", payload.len()),
    }
}

/// A payload read as JSON, if it is JSON.
pub fn json_message(payload: &[u8]) -> Option<serde_json::Value> {
    serde_json::from_slice(payload).ok()
}

/// The next JSON message on `sub` that `wanted` accepts, within `patience` in all ([`recv_until`]: others, and
/// payloads that are not JSON, go by and the failure names the last).
pub async fn next_json(
    sub: &Subscription,
    patience: Duration,
    wanted: impl Fn(&serde_json::Value) -> bool,
) -> anyhow::Result<serde_json::Value> {
    recv_until(sub, "the expected message", patience, |data| {
        json_message(&data.payload).filter(|message| wanted(message))
    })
    .await
}

/// Waits until `name` exists on the hub of `client` (made there by a satellite or imported from another hub), and
/// returns its header; `patience` bounds the wait.
pub async fn until_channel(
    client: &flow::Client,
    name: &str,
    patience: Duration,
) -> anyhow::Result<String> {
    tokio::time::timeout(patience, async {
        loop {
            if let Ok(info) = client.channel(name).await {
                return info.header;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    })
    .await
    .with_context(|| format!("{name} did not appear"))
}

/// Waits until `name` on the hub of `client` has at least `count` subscribers (a module or satellite has attached to
/// it, so what is published next reaches it); `patience` bounds the wait.
pub async fn until_subscribers(
    client: &flow::Client,
    name: &str,
    count: u32,
    patience: Duration,
) -> anyhow::Result<()> {
    tokio::time::timeout(patience, async {
        while !client
            .channel(name)
            .await
            .is_ok_and(|info| info.stats.subscribers >= count)
        {
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    })
    .await
    .with_context(|| format!("{name} did not get {count} subscriber(s)"))
}

/// A free TCP port on loopback, for a listener a test configures (a Zenoh endpoint): bound and released, so the
/// process it is handed to binds it again at once.
pub fn free_port() -> anyhow::Result<u16> {
    Ok(std::net::TcpListener::bind("127.0.0.1:0")?
        .local_addr()?
        .port())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A real hub (`flow-hub`, kept alive with its data directory) and a channel `name` with a subscriber.
    async fn stream(
        name: &str,
    ) -> anyhow::Result<((crate::DataDir, crate::Agent), Publisher, Subscription)> {
        let dir = crate::DataDir::new()?;
        let hub = crate::Agent::hub(&dir).await?;
        let client = hub.client("waiting-test").await?;
        let publisher = client.publisher(name, "{}").await?;
        let sub = client.subscribe(name).await?;
        until_subscribed(&publisher).await?;
        Ok(((dir, hub), publisher, sub))
    }

    /// A real hub (`flow-hub`) with a channel that never stops sending messages the wait does not want.
    #[tokio::test]
    async fn recv_until_gives_up_at_its_deadline_on_a_stream_that_keeps_sending_other_messages()
    -> anyhow::Result<()> {
        let (_hub, publisher, sub) = stream("Busy.stream").await?;
        // A message every 20 ms: every single receive is far inside any per-receive timeout.
        let busy = tokio::spawn(async move {
            let mut tick = tokio::time::interval(Duration::from_millis(20));
            loop {
                tick.tick().await;
                if publisher.publish(&b"{\"blink\":true}"[..]).await.is_err() {
                    return;
                }
            }
        });
        let patience = Duration::from_secs(1);
        let waited = until(
            "the wait on the busy stream to end",
            PATIENCE,
            recv_until(&sub, "a message that never comes", patience, |_| None::<()>),
        )
        .await?;
        busy.abort();
        let err = waited
            .expect_err("nothing matches, so the wait fails")
            .to_string();
        assert!(err.contains("timed out after 1 s"), "{err}");
        assert!(err.contains("a message that never comes"), "{err}");
        assert!(err.contains("Busy.stream"), "{err}");
        assert!(err.contains(r#"{"blink":true}"#), "{err}");
        assert!(!err.contains(" 0 message(s)"), "{err}");
        Ok(())
    }

    /// The same wait finds the message it picks among the others.
    #[tokio::test]
    async fn recv_until_returns_what_it_picks_and_skips_the_rest() -> anyhow::Result<()> {
        let (_hub, publisher, sub) = stream("Picky.stream").await?;
        for n in 1..=5u8 {
            publisher.publish(vec![n]).await?;
        }
        let seq = recv_until(&sub, "the fourth message", PATIENCE, |d| {
            (d.payload[..] == [4]).then_some(d.seq)
        })
        .await?;
        assert_eq!(seq, 4);
        Ok(())
    }

    #[test]
    fn short_forms_cut_long_text_and_size_binary() {
        assert_eq!(short(b"{\"a\":1}"), r#"{"a":1}"#);
        assert!(short("x".repeat(500).as_bytes()).ends_with("... (500 bytes)"));
        assert_eq!(short(&[0xff, 0xfe, 0]), "3 bytes of binary");
    }
}
