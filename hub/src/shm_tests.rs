//! Shared memory on a real server: Unix-socket clients get large payloads by reference, TCP clients the same bytes,
//! and every slot comes back.

use std::time::Duration;

use flow::{Client, ConnectOptions, FlowAddr};

use crate::config::Config;
use crate::server::{Application, RunningServer, start};

async fn server(dir: &std::path::Path) -> anyhow::Result<RunningServer> {
    let mut config = Config::load(None)?;
    config.server.http = "127.0.0.1:0".into();
    config.server.flow_tcp = "127.0.0.1:0".into();
    config.server.flow_unix = "flow.sock".into();
    config.server.data_dir = dir.to_path_buf();
    start(config, Application::default()).await
}

async fn client(addr: FlowAddr, token: &str, name: &str) -> anyhow::Result<Client> {
    Ok(Client::connect(&addr, ConnectOptions::new(name, token)).await?)
}

/// Waits for `check` to hold, polling: the slots come back asynchronously (a release travels to the hub).
async fn eventually(what: &str, check: impl Fn() -> bool) -> anyhow::Result<()> {
    for _ in 0..400 {
        if check() {
            return Ok(());
        }
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    anyhow::bail!("{what} did not happen within 10 s")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unix_subscribers_get_large_payloads_by_reference_and_give_every_slot_back()
-> anyhow::Result<()> {
    let dir = tempfile::tempdir()?;
    let server = server(dir.path()).await?;
    let token = server.shared.tokens.admin().to_string();
    let unix = FlowAddr::Unix(server.flow_unix.clone().expect("unix socket"));
    let tcp = FlowAddr::Tcp(server.flow_tcp.expect("tcp").to_string());
    let publisher_client = client(unix.clone(), &token, "pub").await?;
    assert!(publisher_client.uses_shared_memory());
    let by_ref = client(unix.clone(), &token, "sub-unix").await?;
    let by_bytes = client(tcp, &token, "sub-tcp").await?;
    assert!(!by_bytes.uses_shared_memory());
    let publisher = publisher_client.publisher("Test.frames", "{}").await?;
    let sub_ref = by_ref.subscribe("Test.frames").await?;
    let sub_bytes = by_bytes.subscribe("Test.frames").await?;
    eventually("the publisher hearing of its subscribers", || {
        publisher.has_subscribers()
    })
    .await?;
    let sizes = [100usize, 5000, 70_000, 1 << 20, 3000, 300_000];
    let segments = server.shared.hub.segments();
    let mut shared_seen = 0;
    let mut kept = Vec::new();
    for i in 0..40usize {
        let len = sizes[i % sizes.len()];
        let want: Vec<u8> = (0..len).map(|k| (k * 7 + i) as u8).collect();
        publisher.publish(want.clone()).await?;
        let a = tokio::time::timeout(Duration::from_secs(10), sub_ref.recv())
            .await?
            .expect("unix message");
        let b = tokio::time::timeout(Duration::from_secs(10), sub_bytes.recv())
            .await?
            .expect("tcp message");
        assert_eq!(a.seq, b.seq, "message {i}");
        assert_eq!(a.ts_us, b.ts_us, "message {i}");
        assert!(
            a.payload == want[..],
            "message {i}: the unix payload differs"
        );
        assert!(
            b.payload == want[..],
            "message {i}: the tcp payload differs"
        );
        assert!(!flow::shm::is_shared(&b.payload), "tcp payloads are bytes");
        if flow::shm::is_shared(&a.payload) {
            shared_seen += 1;
        }
        assert!(
            want.len() >= 4096 || !flow::shm::is_shared(&a.payload),
            "message {i}: small payloads go as bytes"
        );
        // A few messages kept a while: their slots stay held until they are dropped.
        if i % 10 == 3 {
            kept.push(a.payload);
        }
    }
    assert!(segments.stats().slots_held() > 0 || kept.iter().all(|k| !flow::shm::is_shared(k)));
    drop(kept);
    // Zero-copy publishing: a frame written in place into a loaned slot.
    let mut loan = publisher
        .loan(70_000)
        .expect("the 70 kB messages' segment has a free slot");
    loan.as_mut_slice().fill(0xab);
    loan.truncate(65_000);
    loan.publish().await?;
    let a = tokio::time::timeout(Duration::from_secs(10), sub_ref.recv())
        .await?
        .expect("unix message");
    let b = tokio::time::timeout(Duration::from_secs(10), sub_bytes.recv())
        .await?
        .expect("tcp message");
    assert!(flow::shm::is_shared(&a.payload));
    assert_eq!(a.payload.len(), 65_000);
    assert!(a.payload.iter().all(|&x| x == 0xab) && a.payload == b.payload);
    drop((a, b));
    // A loan dropped unpublished frees its slot for the next one.
    let first = publisher.loan(70_000).expect("free slot");
    drop(first);
    assert!(publisher.loan(70_000).is_some());
    // The first large message of each size goes inline while its segment is asked for; the rest by reference.
    assert!(
        shared_seen >= 20,
        "only {shared_seen} of 40 messages came by reference"
    );
    assert!(segments.stats().messages() >= 20);
    eventually("every slot given back", || {
        segments.stats().slots_held() == 0
    })
    .await?;
    drop(publisher);
    eventually("the removed channel's segments unmapped", || {
        segments.stats().segments() == 0
    })
    .await?;
    server.shutdown().await;
    Ok(())
}
