//! The robot-agent server library: hub core, transports, HTTP and modules.
