//! Performs the rule engine's effects on the hub: speech, publications, service calls, whitelisted commands and
//! pair-database writes. Slow work (commands, calls) runs in tasks whose outcomes come back as percepts.

use std::collections::{BTreeMap, HashMap};
use std::process::Stdio;
use std::time::Duration;

use agent_brain::{Action, Effect, Value};
use agent_contract::acquaintance::{AcquaintanceAnswer, AcquaintanceRequest};
use agent_contract::channels::ACQUAINTANCES;
use flow::{Client, Publisher};
use tokio::sync::mpsc;
use tokio::task::AbortHandle;
use tracing::{debug, warn};

use super::params::BrainParams;
use super::speech::Speech;

/// The result of a command or a service call, asserted as `output(name, text)`, `reply(service, text)` or
/// `failed(name, reason)`.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    Output { command: String, text: String },
    Reply { service: String, text: String },
    Failed { name: String, reason: String },
}

impl Outcome {
    /// The percept this outcome becomes.
    pub fn percept(self) -> (&'static str, Vec<Value>) {
        match self {
            Outcome::Output { command, text } => {
                ("output", vec![Value::Text(command), Value::Text(text)])
            }
            Outcome::Reply { service, text } => {
                ("reply", vec![Value::Text(service), Value::Text(text)])
            }
            Outcome::Failed { name, reason } => {
                ("failed", vec![Value::Text(name), Value::Text(reason)])
            }
        }
    }
}

/// Outcomes waiting for the module's loop; when it is this far behind, further outcomes are dropped (and logged)
/// rather than queued without bound.
pub const OUTCOME_QUEUE: usize = 64;

/// What the brain acts with.
#[derive(Debug)]
pub struct Actuators {
    client: Client,
    speech: Speech,
    publishers: HashMap<String, Publisher>,
    commands: BTreeMap<String, Vec<String>>,
    command_timeout: Duration,
    call_timeout: Duration,
    answer_chars: usize,
    /// Durative commands and calls in progress, to abort when their rule stops being active.
    running: Vec<(Action, AbortHandle)>,
    outcomes: mpsc::Sender<Outcome>,
    /// Outcomes dropped because the loop was behind.
    pub dropped_outcomes: u64,
}

impl Actuators {
    pub fn new(
        client: Client,
        speech: Speech,
        params: &BrainParams,
        outcomes: mpsc::Sender<Outcome>,
    ) -> Self {
        Actuators {
            client,
            speech,
            publishers: HashMap::new(),
            commands: params.commands.clone(),
            command_timeout: params.command_timeout(),
            call_timeout: params.call_timeout(),
            answer_chars: params.answer_chars,
            running: Vec::new(),
            outcomes,
            dropped_outcomes: 0,
        }
    }

    /// Performs one effect. Problems are reported as `failed(...)` percepts when the program can react to them,
    /// and logged.
    pub async fn perform(&mut self, effect: Effect) {
        self.running.retain(|(_, task)| !task.is_finished());
        match effect {
            Effect::Fire(action) => self.start(action, false).await,
            Effect::Start(action) => self.start(action, true).await,
            Effect::Stop(action) => self.stop(&action).await,
        }
    }

    async fn start(&mut self, action: Action, durative: bool) {
        match &action {
            Action::Say { text } => self.speech.say(text, durative).await,
            Action::Cancel => self.speech.cancel_all().await,
            Action::Publish { channel, payload } => self.publish(channel, payload).await,
            Action::Call { service, payload } => {
                let task = self.call(service.clone(), payload);
                if durative {
                    self.running.push((action, task));
                }
            }
            Action::Run { command } => {
                let task = self.run(command.clone());
                if durative {
                    self.running.push((action, task));
                }
            }
            Action::LearnFace { name } => {
                self.acquaint("learn_face", AcquaintanceRequest::Learn(name.clone()));
            }
            Action::ForgetFace => self.acquaint("forget_face", AcquaintanceRequest::Forget(true)),
            Action::Mood { mood } => self.speech.mood(mood).await,
            // The module itself performs chat turns (they need its percepts and memory).
            Action::Chat { .. } | Action::ForgetConversation | Action::Recall { .. } => {}
            Action::Set { key, value } => {
                let client = self.client.clone();
                let (key, value) = (key.clone(), serde_json::to_value(value).unwrap_or_default());
                tokio::spawn(async move {
                    if let Err(e) = client.var_set(&key, &value).await {
                        warn!(key, "brain: set failed: {e}");
                    }
                });
            }
        }
    }

    async fn stop(&mut self, action: &Action) {
        match action {
            Action::Say { text } => self.speech.stop_durative(text).await,
            Action::Run { .. } | Action::Call { .. } => {
                // Aborting the task drops the child process, which is killed (`kill_on_drop`).
                self.running.retain(|(running, task)| {
                    if running == action {
                        task.abort();
                        false
                    } else {
                        true
                    }
                });
            }
            // A publication, a write or a cancel has nothing left to stop.
            Action::Publish { .. }
            | Action::Set { .. }
            | Action::Cancel
            | Action::Chat { .. }
            | Action::Recall { .. }
            | Action::ForgetConversation
            | Action::LearnFace { .. }
            | Action::ForgetFace
            | Action::Mood { .. } => {}
        }
    }

    async fn publish(&mut self, channel: &str, payload: &Value) {
        if !self.publishers.contains_key(channel) {
            match self
                .client
                .publisher(channel, "{\"format\":\"json\",\"from\":\"brain\"}")
                .await
            {
                Ok(publisher) => {
                    self.publishers.insert(channel.to_owned(), publisher);
                }
                Err(e) => {
                    warn!(channel, "brain: cannot publish: {e}");
                    self.report(Outcome::Failed {
                        name: channel.to_owned(),
                        reason: e.to_string(),
                    });
                    return;
                }
            }
        }
        let Some(publisher) = self.publishers.get(channel) else {
            return;
        };
        let bytes = serde_json::to_vec(payload).unwrap_or_default();
        match publisher.try_publish(bytes) {
            Ok(true) => {}
            // The link is saturated: the publication is dropped and counted by the publisher.
            Ok(false) => debug!(channel, "brain: publication dropped, link busy"),
            Err(e) => warn!(channel, "brain: publish failed: {e}"),
        }
    }

    fn call(&self, service: String, payload: &Value) -> AbortHandle {
        let client = self.client.clone();
        let outcomes = self.outcomes.clone();
        let (timeout, chars) = (self.call_timeout, self.answer_chars);
        let body = serde_json::to_vec(payload).unwrap_or_default();
        tokio::spawn(async move {
            let outcome = match client.call(&service, body, timeout).await {
                Ok(answer) => Outcome::Reply {
                    text: answer_text(&answer, chars),
                    service,
                },
                Err(e) => Outcome::Failed {
                    name: service,
                    reason: e.to_string(),
                },
            };
            send(&outcomes, outcome);
        })
        .abort_handle()
    }

    /// Asks the vision module to learn or forget the talking person's face; the outcome is asserted as
    /// `reply(action, name)` or `failed(action, reason)`.
    fn acquaint(&self, action: &'static str, request: AcquaintanceRequest) {
        let client = self.client.clone();
        let outcomes = self.outcomes.clone();
        let timeout = self.call_timeout;
        let body = serde_json::to_vec(&request).unwrap_or_default();
        tokio::spawn(async move {
            let failed = |reason: String| Outcome::Failed {
                name: action.to_owned(),
                reason,
            };
            let outcome = match client.call(ACQUAINTANCES.name, body, timeout).await {
                Ok(answer) => match serde_json::from_slice::<AcquaintanceAnswer>(&answer) {
                    Ok(answer) => Outcome::Reply {
                        service: action.to_owned(),
                        text: answer.name,
                    },
                    Err(e) => failed(format!("{} answered {e}", ACQUAINTANCES.name)),
                },
                Err(e) => failed(e.to_string()),
            };
            send(&outcomes, outcome);
        });
    }

    fn run(&self, command: String) -> AbortHandle {
        let outcomes = self.outcomes.clone();
        let argv = self.commands.get(&command).cloned().unwrap_or_default();
        let (timeout, chars) = (self.command_timeout, self.answer_chars);
        tokio::spawn(async move {
            let outcome = run_command(&command, &argv, timeout, chars).await;
            send(&outcomes, outcome);
        })
        .abort_handle()
    }

    fn report(&mut self, outcome: Outcome) {
        if !send(&self.outcomes, outcome) {
            self.dropped_outcomes += 1;
        }
    }
}

/// Queues an outcome for the loop; false when it had to be dropped.
fn send(outcomes: &mpsc::Sender<Outcome>, outcome: Outcome) -> bool {
    match outcomes.try_send(outcome) {
        Ok(()) => true,
        Err(mpsc::error::TrySendError::Full(outcome)) => {
            warn!("brain: outcome dropped, the brain is behind: {outcome:?}");
            false
        }
        // The module is shutting down.
        Err(mpsc::error::TrySendError::Closed(_)) => false,
    }
}

/// Runs a whitelisted command line (no shell) with a time limit and turns its result into an outcome.
async fn run_command(name: &str, argv: &[String], timeout: Duration, chars: usize) -> Outcome {
    let failed = |reason: String| Outcome::Failed {
        name: name.to_owned(),
        reason,
    };
    let Some((program, args)) = argv.split_first() else {
        return failed("it is not on the whitelist".into());
    };
    let child = tokio::process::Command::new(program)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .kill_on_drop(true)
        .output();
    match tokio::time::timeout(timeout, child).await {
        Err(_) => failed(format!(
            "it took longer than {} seconds",
            timeout.as_secs_f64()
        )),
        Ok(Err(e)) => failed(format!("it could not start ({e})")),
        Ok(Ok(output)) if output.status.success() => {
            let text = spoken_text(&String::from_utf8_lossy(&output.stdout), chars);
            Outcome::Output {
                command: name.to_owned(),
                text: if text.is_empty() { "done".into() } else { text },
            }
        }
        Ok(Ok(output)) => {
            let stderr = spoken_text(&String::from_utf8_lossy(&output.stderr), chars);
            failed(if stderr.is_empty() {
                format!("it ended with {}", output.status)
            } else {
                stderr
            })
        }
    }
}

/// The text of a service's answer: a JSON string, the `text` field of a JSON object, or the raw UTF-8.
fn answer_text(answer: &[u8], chars: usize) -> String {
    let raw = String::from_utf8_lossy(answer);
    let text = match serde_json::from_slice::<serde_json::Value>(answer) {
        Ok(serde_json::Value::String(text)) => text,
        Ok(serde_json::Value::Object(map)) => match map.get("text") {
            Some(serde_json::Value::String(text)) => text.clone(),
            _ => raw.into_owned(),
        },
        _ => raw.into_owned(),
    };
    spoken_text(&text, chars)
}

/// Collapses lines and runs of spaces into one line and cuts it to `chars` characters.
fn spoken_text(text: &str, chars: usize) -> String {
    let lines: Vec<&str> = text
        .lines()
        .map(str::trim)
        .filter(|line| !line.is_empty())
        .collect();
    let joined = lines
        .join(". ")
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ");
    joined.chars().take(chars).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn answers_are_made_speakable() {
        assert_eq!(answer_text(br#""Turning left.""#, 100), "Turning left.");
        assert_eq!(answer_text(br#"{"text":"ok","code":0}"#, 100), "ok");
        assert_eq!(answer_text(br#"{"code":0}"#, 100), r#"{"code":0}"#);
        assert_eq!(
            answer_text(b"line one\n\n  line   two\n", 100),
            "line one. line two"
        );
        assert_eq!(answer_text("ééééé".as_bytes(), 3), "ééé");
    }

    #[tokio::test]
    async fn commands_run_without_a_shell_and_time_out() {
        let echo = ["echo".to_owned(), "up  1 hour".to_owned()];
        assert_eq!(
            run_command("echo", &echo, Duration::from_secs(5), 100).await,
            Outcome::Output {
                command: "echo".into(),
                text: "up 1 hour".into()
            }
        );
        let sleep = ["sleep".to_owned(), "5".to_owned()];
        let outcome = run_command("sleep", &sleep, Duration::from_millis(100), 100).await;
        assert!(
            matches!(outcome, Outcome::Failed { ref reason, .. } if reason.contains("longer than")),
            "{outcome:?}"
        );
        let missing = ["/nonexistent/program".to_owned()];
        let outcome = run_command("missing", &missing, Duration::from_secs(1), 100).await;
        assert!(
            matches!(outcome, Outcome::Failed { ref reason, .. } if reason.contains("could not start"))
        );
        let false_ = ["false".to_owned()];
        let outcome = run_command("false", &false_, Duration::from_secs(5), 100).await;
        assert!(
            matches!(outcome, Outcome::Failed { ref reason, .. } if reason.contains("ended with"))
        );
    }
}
