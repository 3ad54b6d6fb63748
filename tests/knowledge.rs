//! The knowledge folder (`[agent] knowledge`, docs/knowledge.md) through a real robot-agent on the default rule
//! program, with no language model: a question the folder answers is said from its passage by the rule's
//! `recall(T)`, and the trace names the file; a file added to the folder is found without a restart; a folder path
//! that is a file stops the agent at start, naming it. (A passage reaching the model quoted: tests/llm.rs.)

use std::path::{Path, PathBuf};
use std::time::Duration;

use agent_contract::channels as ch;
use agent_knowledge::{Knowledge, Language};
use agent_tests::{Agent, DataDir, PATIENCE, next_json, until, until_subscribers};
use anyhow::Context;
use flow::{Publisher, Subscription};
use serde_json::json;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// A robot-agent answering from `folder` on the default program, and the test speaking for the user.
struct Rig {
    _dir: DataDir,
    _agent: Agent,
    transcript: Publisher,
    rules: Subscription,
    avatar: Subscription,
}

impl Rig {
    async fn start(folder: &Path) -> anyhow::Result<Rig> {
        let dir = DataDir::new()?;
        let config = format!(
            "[agent]\nknowledge = {:?}\n[modules.brain]\nprogram = {:?}\nchat_thinking_ms = 0\n[modules.vision]\nenabled = false\n",
            folder.display().to_string(),
            repo().join("config/brain.tr").display().to_string()
        );
        let agent =
            Agent::start_configured(&dir, &config, "brain: the knowledge folder is indexed")
                .await?;
        let user = agent.client("knowledge-test").await?;
        let rules = user.subscribe(ch::RULES.name).await?;
        let avatar = user.subscribe(ch::AVATAR.name).await?;
        let transcript = user
            .publisher(ch::TRANSCRIPT.name, ch::headers::TRANSCRIPT)
            .await?;
        // The brain subscribes to the pauses' transcripts right after the transcripts, and nobody else does.
        let _pauses = user
            .publisher(ch::TRANSCRIPT_PAUSE.name, ch::headers::TRANSCRIPT)
            .await?;
        until_subscribers(&user, ch::TRANSCRIPT_PAUSE.name, 1, PATIENCE).await?;
        // Agent.rules comes after: a question heard before our subscription was attached to it would have its rule
        // trace go nowhere.
        until_subscribers(&user, ch::RULES.name, 1, PATIENCE).await?;
        Ok(Rig {
            _dir: dir,
            _agent: agent,
            transcript,
            rules,
            avatar,
        })
    }

    async fn hear(&self, text: &str) -> anyhow::Result<()> {
        let message = json!({ "text": text, "final": true }).to_string();
        self.transcript.publish(message.into_bytes()).await?;
        Ok(())
    }
}

#[tokio::test]
async fn a_question_the_folder_answers_is_said_from_its_passage_with_no_model() -> anyhow::Result<()>
{
    let folder = repo().join("knowledge");
    let question = "Where are the recordings stored?";
    let expected = Knowledge::open(&folder, Language::En)?
        .best(question)
        .context("the example folder no longer answers the question")?;
    let rig = Rig::start(&folder).await?;
    rig.hear(question).await?;
    let fired = next_json(&rig.rules, PATIENCE, |m| {
        m["action"].as_str().is_some_and(|a| a.contains("recall("))
    })
    .await?;
    assert_eq!(fired["rule"], "main.converse > answer.know", "{fired}");
    let traced = next_json(&rig.rules, PATIENCE, |m| m["chat"]["step"] == "passage").await?;
    let line = traced["chat"]["text"].as_str().unwrap_or_default();
    assert!(
        line.starts_with(&format!("{} (", expected.file)),
        "{traced}"
    );
    let caption = next_json(&rig.avatar, PATIENCE, |m| m["cmd"] == "say").await?;
    assert_eq!(caption["text"], expected.text.as_str(), "{caption}");
    Ok(())
}

#[tokio::test]
async fn a_file_added_to_the_folder_is_found_without_a_restart() -> anyhow::Result<()> {
    let folder = tempfile::tempdir()?;
    let rig = Rig::start(folder.path()).await?;
    let answer =
        "The lab is open from nine in the morning to five in the afternoon, Monday to Friday.";
    std::fs::write(
        folder.path().join("opening.md"),
        format!("# Opening hours\n\n{answer}\n"),
    )?;
    // The watcher indexes the folder again a moment after the change: ask until the answer comes from it (before
    // that, the question goes to the model, which is not there).
    until("the added file's answer", PATIENCE, async {
        loop {
            rig.hear("When is the lab open?").await?;
            if let Ok(caption) = next_json(&rig.avatar, Duration::from_secs(2), |m| {
                m["cmd"] == "say" && m["text"] == answer
            })
            .await
            {
                return anyhow::Ok(caption);
            }
        }
    })
    .await??;
    Ok(())
}

#[tokio::test]
async fn a_knowledge_path_that_is_a_file_stops_the_agent_naming_it() -> anyhow::Result<()> {
    let dir = DataDir::new()?;
    let file = dir.path().join("not-a-folder.md");
    std::fs::write(&file, "# Not a folder\n")?;
    let config = format!("[agent]\nknowledge = {:?}\n", file.display().to_string());
    let started =
        Agent::start_configured(&dir, &config, "brain: the knowledge folder is indexed").await;
    let Err(e) = started else {
        anyhow::bail!("the agent started with a file as its knowledge folder");
    };
    let message = format!("{e:#}");
    assert!(message.contains("not-a-folder.md"), "{message}");
    assert!(message.contains("knowledge"), "{message}");
    Ok(())
}
