//! The robot-agent server binary: the flow hub with the agent's modules and page (`robot_agent::application`),
//! run until Ctrl-C or SIGTERM by the hub's command line, whose `doctor` also checks the agent's models.

mod doctor;

#[tokio::main]
async fn main() {
    flow_hub::cli::main_with(
        "robot-agent",
        "The robot agent: flow hub, avatar web UI and internal modules.",
        robot_agent::application,
        &[&doctor::Models],
    )
    .await;
}
