//! `flow-hub`: the hub alone, without the agent's modules or page (what satellites, benchmarks and tests of the hub
//! need). Options as `robot-agent`'s.

#[tokio::main]
async fn main() {
    flow_hub::cli::main(
        "flow-hub",
        "The flow hub: channels, services, pair database and pulses for satellites.",
        |_| Ok(flow_hub::Application::default()),
    )
    .await;
}
