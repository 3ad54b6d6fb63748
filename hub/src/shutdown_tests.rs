//! The shutdown order, tested on a real server: modules get their stop signal while the hub still serves them.

use tokio::sync::oneshot;

use crate::config::Config;
use crate::module::{Module, ModuleContext, ModuleFuture};
use crate::server::{Application, start};

/// What the module got when it asked: the channel names, or the error.
type Answer = Result<Vec<String>, String>;

/// A module whose last act, after the stop signal, is to ask the hub for its channels; it says what it got.
struct LastWords {
    said: oneshot::Sender<Answer>,
}

impl Module for LastWords {
    fn name(&self) -> &'static str {
        "last_words"
    }

    fn run(self: Box<Self>, mut ctx: ModuleContext) -> ModuleFuture {
        Box::pin(async move {
            let _own = ctx.client.publisher("Test.last_words", "{}").await?;
            ctx.stopped().await;
            let answer = ctx
                .client
                .channels()
                .await
                .map(|list| list.into_iter().map(|c| c.name).collect())
                .map_err(|e| e.to_string());
            let _ = self.said.send(answer);
            Ok(())
        })
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stopping_module_still_reaches_the_hub() -> anyhow::Result<()> {
    let dir = tempfile::tempdir()?;
    let mut config = Config::load(None)?;
    config.server.http = "127.0.0.1:0".into();
    config.server.flow_tcp = String::new();
    config.server.flow_unix = String::new();
    config.server.data_dir = dir.path().to_path_buf();
    let (said, heard) = oneshot::channel();
    let app = Application {
        modules: vec![Box::new(LastWords { said })],
        ..Application::default()
    };
    let server = start(config, app).await?;
    server.shutdown().await;
    let answer = heard.await?;
    // Before the order was fixed, the hub's goodbye had closed the module's link by now.
    let names = answer.map_err(|e| anyhow::anyhow!("the module lost the hub at its stop: {e}"))?;
    assert!(names.iter().any(|n| n == "Test.last_words"), "{names:?}");
    Ok(())
}
