//! The links the federation benchmark measures: two federated hubs, a plain Zenoh pair, and raw TCP.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use agent_tests::{Agent, DataDir, PATIENCE, free_port, until_subscribed};
use anyhow::Context;
use bytes::Bytes;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use zenoh::qos::CongestionControl;

/// Latencies in ms, per payload kind and side.
#[derive(Debug, Default)]
pub struct Latencies {
    pub jpeg_local: Vec<f64>,
    pub jpeg_remote: Vec<f64>,
    pub pcm_local: Vec<f64>,
    pub pcm_remote: Vec<f64>,
}

/// Floor latencies of the plain Zenoh pair, in ms.
#[derive(Debug, Default)]
pub struct Floor {
    pub jpeg: Vec<f64>,
    pub pcm: Vec<f64>,
}

fn now_us() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64)
}

/// `payload` with the current time in its first 8 bytes.
fn stamped(payload: &[u8]) -> Bytes {
    let mut v = payload.to_vec();
    v[..8].copy_from_slice(&now_us().to_le_bytes());
    Bytes::from(v)
}

/// Milliseconds since the stamp in `payload`.
fn age_ms(payload: &[u8]) -> f64 {
    let mut b = [0u8; 8];
    b.copy_from_slice(&payload[..8]);
    now_us().saturating_sub(u64::from_le_bytes(b)) as f64 / 1000.0
}

/// Two federated `flow-hub` processes: A exports `Bench.*`, B imports it.
pub struct Hubs {
    a: Agent,
    b: Agent,
    _dirs: (DataDir, DataDir),
}

impl Hubs {
    pub async fn start() -> anyhow::Result<Hubs> {
        let (da, db) = (DataDir::new()?, DataDir::new()?);
        let port = free_port()?;
        let section = |name: &str, extra: &str| {
            format!(
                "[hub]\nsubscriber_queue = 256\n[federation]\nenabled = true\nname = {name:?}\nqueue = 256\n{extra}\n"
            )
        };
        let a = Agent::hub_with_config(
            &da,
            &section(
                "bench-a",
                &format!("listen = [\"tcp/127.0.0.1:{port}\"]\nexport = [\"Bench.*\"]"),
            ),
        )
        .await?;
        let b = Agent::hub_with_config(
            &db,
            &section(
                "bench-b",
                &format!("connect = [\"tcp/127.0.0.1:{port}\"]\nimport = [\"Bench.*\"]"),
            ),
        )
        .await?;
        Ok(Hubs {
            a,
            b,
            _dirs: (da, db),
        })
    }

    pub async fn stop(self) {
        let _ = self.a.kill9().await;
        let _ = self.b.kill9().await;
    }

    /// 15 fps JPEG and 50 Hz PCM from A to a subscriber on A and one on B.
    pub async fn latency(
        &self,
        jpeg: &[u8],
        pcm: &[u8],
        length: Duration,
    ) -> anyhow::Result<Latencies> {
        let producer = self.a.client("bench-producer").await?;
        let pj = producer.publisher("Bench.jpeg", "{}").await?;
        let pp = producer.publisher("Bench.pcm", "{}").await?;
        let local = self.a.client("bench-local").await?;
        let remote = self.b.client("bench-remote").await?;
        until_channel(&remote, "Bench.jpeg").await?;
        until_channel(&remote, "Bench.pcm").await?;
        let subs = [
            local.subscribe("Bench.jpeg").await?,
            remote.subscribe("Bench.jpeg").await?,
            local.subscribe("Bench.pcm").await?,
            remote.subscribe("Bench.pcm").await?,
        ];
        until_subscribed(&pj).await?;
        until_subscribed(&pp).await?;
        // The remote path is complete once a probe arrives on B.
        warm_up(&pj, &subs[1]).await?;
        warm_up(&pp, &subs[3]).await?;
        for s in &subs {
            while s.try_recv().is_some() {}
        }
        let collectors: Vec<_> = subs
            .into_iter()
            .map(|sub| {
                tokio::spawn(async move {
                    let mut v = Vec::new();
                    while let Ok(Some(d)) =
                        tokio::time::timeout(Duration::from_secs(2), sub.recv()).await
                    {
                        v.push(age_ms(&d.payload));
                    }
                    v
                })
            })
            .collect();
        let mut video = tokio::time::interval(Duration::from_micros(66_667));
        let mut audio = tokio::time::interval(Duration::from_millis(20));
        let end = Instant::now() + length;
        while Instant::now() < end {
            tokio::select! {
                _ = video.tick() => pj.publish(stamped(jpeg)).await?,
                _ = audio.tick() => pp.publish(stamped(pcm)).await?,
            }
        }
        let mut out = Vec::new();
        for c in collectors {
            out.push(c.await?);
        }
        let mut it = out.into_iter();
        let mut next = || it.next().unwrap_or_default();
        Ok(Latencies {
            jpeg_local: next(),
            jpeg_remote: next(),
            pcm_local: next(),
            pcm_remote: next(),
        })
    }

    /// JPEGs published as fast as hub A takes them; messages per second delivered on B, with the producer and the
    /// reader satellites of each hub (TCP clients in this process).
    pub async fn throughput(&self, jpeg: &[u8], length: Duration) -> anyhow::Result<f64> {
        let producer = self.a.client("bench-burst").await?;
        let remote = self.b.client("bench-burst-reader").await?;
        burst_rate(&producer, &remote, jpeg, length).await
    }
}

/// The JPEG published on `producer`'s hub as fast as it takes them, for `length`: messages per second that
/// `reader`, a client of the other hub, receives through the federation.
pub async fn burst_rate(
    producer: &flow::Client,
    reader: &flow::Client,
    jpeg: &[u8],
    length: Duration,
) -> anyhow::Result<f64> {
    let p = producer.publisher("Bench.burst", "{}").await?;
    until_channel(reader, "Bench.burst").await?;
    let sub = reader.subscribe("Bench.burst").await?;
    until_subscribed(&p).await?;
    warm_up(&p, &sub).await?;
    while sub.try_recv().is_some() {}
    let count = Arc::new(AtomicU64::new(0));
    let counting = {
        let count = count.clone();
        tokio::spawn(async move {
            while let Ok(Some(_)) = tokio::time::timeout(Duration::from_secs(1), sub.recv()).await {
                count.fetch_add(1, Ordering::Relaxed);
            }
        })
    };
    let payload = Bytes::copy_from_slice(jpeg);
    let start = Instant::now();
    while start.elapsed() < length {
        p.publish(payload.clone()).await?;
    }
    let at_end = count.load(Ordering::Relaxed);
    let elapsed = start.elapsed().as_secs_f64();
    counting.abort();
    Ok(at_end as f64 / elapsed)
}

async fn until_channel(client: &flow::Client, name: &str) -> anyhow::Result<()> {
    agent_tests::until_channel(client, name, PATIENCE)
        .await
        .map(drop)
}

async fn warm_up(p: &flow::Publisher, sub: &flow::Subscription) -> anyhow::Result<()> {
    tokio::time::timeout(PATIENCE, async {
        loop {
            p.publish(stamped(&[0u8; 16])).await?;
            if tokio::time::timeout(Duration::from_millis(100), sub.recv())
                .await
                .is_ok()
            {
                return anyhow::Ok(());
            }
        }
    })
    .await
    .context("nothing crossed the federation")?
}

/// Two Zenoh peer sessions linked over TCP loopback, as two hubs' sessions are.
async fn zenoh_pair() -> anyhow::Result<(zenoh::Session, zenoh::Session)> {
    let port = free_port()?;
    let conf = |key: &str, ep: String| -> anyhow::Result<zenoh::Config> {
        let mut c = zenoh::Config::default();
        let set = |c: &mut zenoh::Config, k: &str, v: String| {
            c.insert_json5(k, &v)
                .map_err(|e| anyhow::anyhow!("{k}: {e}"))
        };
        set(&mut c, "scouting/multicast/enabled", "false".into())?;
        set(&mut c, key, format!("[\"{ep}\"]"))?;
        Ok(c)
    };
    let ep = format!("tcp/127.0.0.1:{port}");
    let a = zenoh::open(conf("listen/endpoints", ep.clone())?)
        .await
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let b = zenoh::open(conf("connect/endpoints", ep)?)
        .await
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    Ok((a, b))
}

/// A stream publisher as the federation declares one: congestion control `Drop`, samples sent express.
async fn stream_publisher(
    session: &zenoh::Session,
    key: &'static str,
) -> anyhow::Result<zenoh::pubsub::Publisher<'static>> {
    session
        .declare_publisher(key)
        .congestion_control(CongestionControl::Drop)
        .express(true)
        .await
        .map_err(|e| anyhow::anyhow!("{e}"))
}

/// Waits until `publisher` has a matching subscriber on the other session.
async fn until_matched(publisher: &zenoh::pubsub::Publisher<'_>) -> anyhow::Result<()> {
    tokio::time::timeout(PATIENCE, async {
        while !publisher
            .matching_status()
            .await
            .is_ok_and(|m| m.matching())
        {
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    })
    .await
    .context("the Zenoh pair did not match")
}

/// The same payloads at the same rates over a plain Zenoh pair.
pub async fn zenoh_latency(jpeg: &[u8], pcm: &[u8], length: Duration) -> anyhow::Result<Floor> {
    let (a, b) = zenoh_pair().await?;
    let pj = stream_publisher(&a, "bench/jpeg").await?;
    let pp = stream_publisher(&a, "bench/pcm").await?;
    let sj = b
        .declare_subscriber("bench/jpeg")
        .await
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let sp = b
        .declare_subscriber("bench/pcm")
        .await
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    until_matched(&pj).await?;
    let collect = |sub: zenoh::pubsub::Subscriber<
        zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>,
    >| {
        tokio::spawn(async move {
            let mut v = Vec::new();
            while let Ok(Ok(s)) =
                tokio::time::timeout(Duration::from_secs(2), sub.recv_async()).await
            {
                let bytes = s.payload().to_bytes();
                if bytes.len() >= 8 {
                    v.push(age_ms(&bytes));
                }
            }
            v
        })
    };
    let (cj, cp) = (collect(sj), collect(sp));
    let mut video = tokio::time::interval(Duration::from_micros(66_667));
    let mut audio = tokio::time::interval(Duration::from_millis(20));
    let end = Instant::now() + length;
    while Instant::now() < end {
        tokio::select! {
            _ = video.tick() => pj.put(stamped(jpeg)).await.map_err(|e| anyhow::anyhow!("{e}"))?,
            _ = audio.tick() => pp.put(stamped(pcm)).await.map_err(|e| anyhow::anyhow!("{e}"))?,
        }
    }
    let floor = Floor {
        jpeg: cj.await?,
        pcm: cp.await?,
    };
    let _ = a.close().await;
    let _ = b.close().await;
    Ok(floor)
}

/// The JPEG flat out over a plain Zenoh pair: messages per second received.
pub async fn zenoh_throughput(jpeg: &[u8], length: Duration) -> anyhow::Result<f64> {
    let (a, b) = zenoh_pair().await?;
    let p = stream_publisher(&a, "bench/burst").await?;
    let count = Arc::new(AtomicU64::new(0));
    let _sub = {
        let count = count.clone();
        b.declare_subscriber("bench/burst")
            .callback(move |_| {
                count.fetch_add(1, Ordering::Relaxed);
            })
            .await
            .map_err(|e| anyhow::anyhow!("{e}"))?
    };
    until_matched(&p).await?;
    let payload = Bytes::copy_from_slice(jpeg);
    count.store(0, Ordering::Relaxed);
    let start = Instant::now();
    while start.elapsed() < length {
        p.put(payload.clone())
            .await
            .map_err(|e| anyhow::anyhow!("{e}"))?;
    }
    let rate = count.load(Ordering::Relaxed) as f64 / start.elapsed().as_secs_f64();
    let _ = a.close().await;
    let _ = b.close().await;
    Ok(rate)
}

/// The JPEG flat out over one loopback TCP connection, length-prefixed: messages per second received.
pub async fn tcp_throughput(jpeg: &[u8], length: Duration) -> anyhow::Result<f64> {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
    let addr = listener.local_addr()?;
    let count = Arc::new(AtomicU64::new(0));
    let reader = {
        let count = count.clone();
        tokio::spawn(async move {
            let Ok((mut s, _)) = listener.accept().await else {
                return;
            };
            let mut len = [0u8; 4];
            let mut buf = Vec::new();
            while s.read_exact(&mut len).await.is_ok() {
                buf.resize(u32::from_le_bytes(len) as usize, 0);
                if s.read_exact(&mut buf).await.is_err() {
                    break;
                }
                count.fetch_add(1, Ordering::Relaxed);
            }
        })
    };
    let mut w = tokio::net::TcpStream::connect(addr).await?;
    w.set_nodelay(true)?;
    let len = u32::try_from(jpeg.len())?.to_le_bytes();
    let start = Instant::now();
    while start.elapsed() < length {
        w.write_all(&len).await?;
        w.write_all(jpeg).await?;
    }
    let rate = count.load(Ordering::Relaxed) as f64 / start.elapsed().as_secs_f64();
    drop(w);
    reader.abort();
    Ok(rate)
}
