//! The pair database over the protocol: every acknowledged write survives a
//! `kill -9` of the server and a restart on the same data directory, including
//! writes acknowledged while others were still in flight at the moment of the kill.
//!
//! Build the binaries first: `cargo build -p robot-agent -p flowctl`.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

use agent_tests::{Agent, DataDir, PATIENCE, RawConn, run, until};
use anyhow::Context;
use flow::protocol::{Command, ErrorCode, Reply};
use flow::{Client, ClientEvent};
use serde_json::json;

#[tokio::test]
async fn acknowledged_writes_survive_kill9_and_restart() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = Agent::start(&dir).await?;
    let client = agent.client("writer").await?;
    let mut expected_main = BTreeMap::new();
    for i in 0..100 {
        let value = json!({ "i": i, "text": format!("value {i} é😀"), "list": [i, i * 2] });
        client.var_set(&format!("key{i:03}"), &value).await?;
        expected_main.insert(format!("key{i:03}"), value);
    }
    // Overwrites and deletes are acknowledged writes too.
    client.var_set("key000", &json!("overwritten")).await?;
    expected_main.insert("key000".into(), json!("overwritten"));
    for i in (1..100).step_by(10) {
        client.var_del(&format!("key{i:03}")).await?;
        expected_main.remove(&format!("key{i:03}"));
    }
    // A second database, and one created then removed.
    client.db_create("robot").await?;
    client.db_create("scratch").await?;
    client.db_select("robot").await?;
    client.var_set("pose", &json!({"x": 1.5, "y": -2})).await?;
    client.db_select("scratch").await?;
    client.var_set("tmp", &json!(true)).await?;
    client.db_remove("scratch").await?;
    // And one written by flowctl, right before the kill.
    agent_tests::run(
        {
            let mut cmd = agent.flowctl()?;
            cmd.args(["db", "set", "from.flowctl", "[1,2,3]"]);
            cmd
        },
        b"",
        PATIENCE,
    )
    .await?
    .ok()?;
    expected_main.insert("from.flowctl".into(), json!([1, 2, 3]));

    // No shutdown code runs: whatever was acknowledged must already be on disk.
    agent.kill9().await?;
    let agent = Agent::start(&dir).await?;
    let reader = agent.client("reader").await?;
    assert_eq!(
        reader.var_list().await?,
        expected_main.keys().cloned().collect::<Vec<_>>()
    );
    for (key, value) in &expected_main {
        assert_eq!(reader.var_get(key).await?.as_ref(), Some(value), "{key}");
    }
    assert_eq!(reader.var_get("key001").await?, None);
    assert_eq!(reader.db_list().await?, vec!["main", "robot"]);
    reader.db_select("robot").await?;
    assert_eq!(reader.var_list().await?, vec!["pose"]);
    assert_eq!(
        reader.var_get("pose").await?,
        Some(json!({"x": 1.5, "y": -2}))
    );
    let gone = reader
        .db_select("scratch")
        .await
        .expect_err("removed database");
    assert_eq!(gone.code(), Some(ErrorCode::NoDatabase));
    // flowctl sees the same after the restart.
    let mut cmd = agent.flowctl()?;
    cmd.args(["db", "get", "from.flowctl"]);
    assert_eq!(run(cmd, b"", PATIENCE).await?.ok()?.trim(), "[1,2,3]");
    Ok(())
}

#[tokio::test]
async fn writes_acknowledged_during_a_kill_are_all_kept() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = Agent::start(&dir).await?;
    // Writers run flat out on their own connections until the server dies;
    // each records a write only once the hub has acknowledged it.
    let acked: Arc<Mutex<BTreeMap<String, u64>>> = Arc::default();
    let (first_acks_tx, mut first_acks) = tokio::sync::mpsc::channel::<()>(64);
    let mut writers = Vec::new();
    for w in 0..4 {
        let client = agent.client(&format!("writer{w}")).await?;
        let acked = acked.clone();
        let first_acks_tx = first_acks_tx.clone();
        writers.push(tokio::spawn(async move {
            for n in 0u64.. {
                let key = format!("w{w}.{n:06}");
                if client.var_set(&key, &json!(n)).await.is_err() {
                    return n;
                }
                acked
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner)
                    .insert(key, n);
                let _ = first_acks_tx.try_send(());
            }
            0
        }));
    }
    drop(first_acks_tx);
    // Kill once every writer has had writes acknowledged.
    until("40 acknowledged writes", PATIENCE, async {
        for _ in 0..40 {
            first_acks.recv().await.context("writers stopped early")?;
        }
        anyhow::Ok(())
    })
    .await??;
    agent.kill9().await?;
    for writer in writers {
        tokio::time::timeout(PATIENCE, writer)
            .await
            .context("a writer did not notice the server's death")??;
    }
    let acked = std::mem::take(
        &mut *acked
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner),
    );
    assert!(
        acked.len() >= 40,
        "only {} writes acknowledged",
        acked.len()
    );

    let agent = Agent::start(&dir).await?;
    let reader = agent.client("reader").await?;
    let stored = reader.var_list().await?;
    for (key, n) in &acked {
        assert_eq!(
            reader.var_get(key).await?,
            Some(json!(n)),
            "acknowledged {key} lost"
        );
    }
    // Unacknowledged writes may or may not have landed, but nothing else appears.
    for key in &stored {
        assert!(key.starts_with('w'), "unexpected key {key}");
    }
    Ok(())
}

#[tokio::test]
async fn database_commands_refuse_what_they_cannot_do() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let agent = Agent::start(&dir).await?;
    let client: Client = agent.client("db-user").await?;
    let mut events = client.events();
    client.db_create("robot").await?;
    let again = client.db_create("robot").await.expect_err("exists");
    assert_eq!(again.code(), Some(ErrorCode::Exists));
    let missing = client.db_select("nowhere").await.expect_err("no such db");
    assert_eq!(missing.code(), Some(ErrorCode::NoDatabase));
    let missing = client.db_remove("nowhere").await.expect_err("no such db");
    assert_eq!(missing.code(), Some(ErrorCode::NoDatabase));
    // Selecting a database tells this connection (and only it) which one is current.
    client.db_select("robot").await?;
    let changed = tokio::time::timeout(PATIENCE, async {
        loop {
            if let Ok(ClientEvent::DbChanged(name)) = events.recv().await {
                return name;
            }
        }
    })
    .await
    .context("no DbChanged event")?;
    assert_eq!(changed, "robot");
    client.var_set("k", &json!(1)).await?;
    // Removing the current database removes its variables.
    client.db_remove("robot").await?;
    // A missing database is an error for every variable command, var_get
    // included: only a missing key in an existing database is "no value".
    let gone = client.var_get("k").await.expect_err("database removed");
    assert_eq!(gone.code(), Some(ErrorCode::NoDatabase));
    let gone = client.var_list().await.expect_err("database removed");
    assert_eq!(gone.code(), Some(ErrorCode::NoDatabase));
    let gone = client
        .var_set("k", &json!(2))
        .await
        .expect_err("database removed");
    assert_eq!(gone.code(), Some(ErrorCode::NoDatabase));
    let gone = client.var_del("k").await.expect_err("database removed");
    assert_eq!(gone.code(), Some(ErrorCode::NoDatabase));
    client.db_create("robot").await?;
    assert_eq!(client.var_get("k").await?, None);

    // Values must be JSON: the hub checks, whatever the client library does.
    let mut raw = RawConn::login(agent.flow_tcp, agent.token(), false).await?;
    let refused = raw
        .request(Command::VarSet {
            key: "bad".into(),
            value: "{not json".into(),
        })
        .await?;
    assert_eq!(
        refused.map_err(|e| e.code).err(),
        Some(ErrorCode::BadRequest)
    );
    let stored = raw
        .request(Command::VarSet {
            key: "good".into(),
            value: "{\"ok\":true}".into(),
        })
        .await?;
    assert_eq!(stored, Ok(Reply::Done));
    let read = raw.request(Command::VarGet { key: "good".into() }).await?;
    assert_eq!(read, Ok(Reply::Value("{\"ok\":true}".into())));
    Ok(())
}
