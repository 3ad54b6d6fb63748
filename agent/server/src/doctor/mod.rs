//! The checks `robot-agent doctor` adds to the hub's (`flow_hub::doctor`): what only the agent knows, its models.

mod models;

pub use models::Models;
