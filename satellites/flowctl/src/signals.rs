//! How the long-running commands end: Ctrl-C, SIGTERM or an optional time limit.

use std::time::Duration;

/// Returns at Ctrl-C, SIGTERM or after `limit`, whichever comes first.
pub async fn until_stopped(limit: Option<Duration>) -> anyhow::Result<()> {
    let mut term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())?;
    let limit = async {
        match limit {
            Some(d) => tokio::time::sleep(d).await,
            None => std::future::pending().await,
        }
    };
    tokio::select! {
        r = tokio::signal::ctrl_c() => r?,
        _ = term.recv() => {}
        () = limit => {}
    }
    Ok(())
}
