//! Scraping a running agent's `/metrics` and reading it with Prometheus's own Python client
//! (`prometheus_client.parser`, in the SDK's venv that `make test` creates), so the exposition format is checked by
//! a real parser, not by ours.

use std::process::Stdio;

use anyhow::Context;
use serde::Deserialize;

use crate::Agent;
use crate::http::request;

/// One sample as the parser read it.
#[derive(Debug, Clone, Deserialize)]
pub struct Sample {
    pub family: String,
    pub kind: String,
    pub name: String,
    pub labels: std::collections::BTreeMap<String, String>,
    pub value: f64,
}

/// The text of `GET /metrics`, with the user token as a scraper would send it.
pub async fn scrape(agent: &Agent) -> anyhow::Result<String> {
    let auth = format!("Bearer {}", agent.token());
    let answer = request(agent.http, "GET", "/metrics", &[("Authorization", &auth)]).await?;
    anyhow::ensure!(
        answer.status == 200,
        "/metrics answered {}: {}",
        answer.status,
        answer.body
    );
    let kind = answer
        .headers
        .iter()
        .find(|(k, _)| k.eq_ignore_ascii_case("content-type"))
        .map(|(_, v)| v.clone())
        .unwrap_or_default();
    anyhow::ensure!(
        kind.starts_with("text/plain; version=0.0.4"),
        "content type {kind:?}"
    );
    Ok(answer.body)
}

const PARSER: &str = r#"
import json, sys
from prometheus_client.parser import text_string_to_metric_families
out = []
for family in text_string_to_metric_families(sys.stdin.read()):
    for s in family.samples:
        out.append({"family": family.name, "kind": family.type, "name": s.name, "labels": s.labels,
                    "value": s.value})
print(json.dumps(out))
"#;

/// Every sample of `text`, as `prometheus_client.parser` reads it; a parse error fails with the parser's reason.
pub async fn parse(text: &str) -> anyhow::Result<Vec<Sample>> {
    let mut child = tokio::process::Command::new(crate::recording::python()?)
        .arg("-c")
        .arg(PARSER)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .context("starting the venv's python")?;
    let run = async {
        if let Some(mut stdin) = child.stdin.take() {
            use tokio::io::AsyncWriteExt;
            stdin.write_all(text.as_bytes()).await?;
        }
        child.wait_with_output().await
    };
    let out = tokio::time::timeout(crate::wait::PATIENCE, run)
        .await
        .context("prometheus_client did not finish reading /metrics")??;
    anyhow::ensure!(
        out.status.success(),
        "prometheus_client could not parse /metrics: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    Ok(serde_json::from_slice(&out.stdout)?)
}

/// The value of the sample `name` whose labels include `labels`, if there is one.
pub fn value(samples: &[Sample], name: &str, labels: &[(&str, &str)]) -> Option<f64> {
    samples
        .iter()
        .find(|s| {
            s.name == name
                && labels
                    .iter()
                    .all(|(k, v)| s.labels.get(*k).map(String::as_str) == Some(*v))
        })
        .map(|s| s.value)
}
