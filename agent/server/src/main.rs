//! The robot-agent server binary: the flow hub with the agent's modules and page (`robot_agent::application`),
//! run until Ctrl-C or SIGTERM by the hub's command line.

#[tokio::main]
async fn main() {
    flow_hub::cli::main(
        "robot-agent",
        "The robot agent: flow hub, avatar web UI and internal modules.",
        robot_agent::application,
    )
    .await;
}
