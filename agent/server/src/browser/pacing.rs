//! The camera frame rate the server advises a page to use, from how many video frames it had to drop.
//!
//! Each second with more than one drop lowers the advice by 3 fps (not below 5); five quiet seconds in a row raise
//! it by 1 fps (up to 15). A single drop is a scheduling hiccup, not congestion. Dropping fast and recovering slowly
//! keeps a congested link from oscillating.

pub const MAX_FPS: u32 = 15;
pub const MIN_FPS: u32 = 5;
const STEP_DOWN: u32 = 3;
const QUIET_SECONDS_TO_RAISE: u32 = 5;
/// Drops in one second that count as congestion.
const CONGESTED: u64 = 2;

#[derive(Debug, Clone)]
pub struct FpsAdvice {
    fps: u32,
    quiet_seconds: u32,
    last_drops: u64,
}

impl Default for FpsAdvice {
    fn default() -> Self {
        FpsAdvice {
            fps: MAX_FPS,
            quiet_seconds: 0,
            last_drops: 0,
        }
    }
}

impl FpsAdvice {
    /// Called once a second with the running total of dropped video frames; returns the advice.
    pub fn tick(&mut self, total_drops: u64) -> u32 {
        let new = total_drops.saturating_sub(self.last_drops);
        self.last_drops = total_drops;
        if new >= CONGESTED {
            self.fps = self.fps.saturating_sub(STEP_DOWN).max(MIN_FPS);
            self.quiet_seconds = 0;
        } else if new > 0 {
            self.quiet_seconds = 0;
        } else {
            self.quiet_seconds += 1;
            if self.quiet_seconds >= QUIET_SECONDS_TO_RAISE {
                self.fps = (self.fps + 1).min(MAX_FPS);
                self.quiet_seconds = 0;
            }
        }
        self.fps
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drops_lower_fast_and_quiet_raises_slowly() {
        let mut a = FpsAdvice::default();
        assert_eq!(a.tick(0), 15);
        assert_eq!(a.tick(1), 15, "one drop is a hiccup");
        assert_eq!(a.tick(4), 12);
        assert_eq!(a.tick(9), 9);
        assert_eq!(a.tick(20), 6);
        assert_eq!(a.tick(30), 5, "never below the floor");
        for _ in 0..4 {
            assert_eq!(a.tick(30), 5);
        }
        assert_eq!(a.tick(30), 6, "five quiet seconds raise by one");
    }
}
