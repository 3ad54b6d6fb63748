//! Shared support for the integration tests: starting a real robot-agent on free ports.
