//! Who holds the microphone/camera role: one page at a time drives the agent, later claims wait in order.

use std::collections::VecDeque;

/// A page's identity on the role board (one per socket).
pub type PageId = u64;

/// The answer to a claim.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Claim {
    Granted,
    /// Someone else holds the role; this page waits in line.
    Busy,
}

/// The role holder and the pages waiting for it.
#[derive(Debug, Default)]
pub struct RoleBoard {
    holder: Option<PageId>,
    waiting: VecDeque<PageId>,
}

impl RoleBoard {
    pub fn holder(&self) -> Option<PageId> {
        self.holder
    }

    pub fn is_waiting(&self, page: PageId) -> bool {
        self.waiting.contains(&page)
    }

    /// `page` asks for the role.
    pub fn claim(&mut self, page: PageId) -> Claim {
        match self.holder {
            None => {
                self.holder = Some(page);
                self.waiting.retain(|p| *p != page);
                Claim::Granted
            }
            Some(h) if h == page => Claim::Granted,
            Some(_) => {
                if !self.waiting.contains(&page) {
                    self.waiting.push_back(page);
                }
                Claim::Busy
            }
        }
    }

    /// `page` gives the role back or leaves (closes its socket); a waiting claim is withdrawn. Returns the page
    /// that now holds the role, if the holder changed to someone.
    pub fn leave(&mut self, page: PageId) -> Option<PageId> {
        self.waiting.retain(|p| *p != page);
        if self.holder != Some(page) {
            return None;
        }
        self.holder = self.waiting.pop_front();
        self.holder
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_claim_wins_and_the_next_takes_over_in_order() {
        let mut b = RoleBoard::default();
        assert_eq!(b.claim(1), Claim::Granted);
        assert_eq!(b.claim(1), Claim::Granted, "claiming twice is harmless");
        assert_eq!(b.claim(2), Claim::Busy);
        assert_eq!(b.claim(3), Claim::Busy);
        assert_eq!(b.claim(2), Claim::Busy, "no double place in line");
        assert_eq!(b.leave(1), Some(2));
        assert_eq!(b.holder(), Some(2));
        assert_eq!(b.leave(2), Some(3));
        assert_eq!(b.leave(3), None);
        assert_eq!(b.holder(), None);
    }

    #[test]
    fn a_waiting_page_that_leaves_loses_its_place() {
        let mut b = RoleBoard::default();
        b.claim(1);
        b.claim(2);
        assert!(b.is_waiting(2));
        assert_eq!(b.leave(2), None);
        assert!(!b.is_waiting(2));
        assert_eq!(b.leave(1), None);
        assert_eq!(b.holder(), None);
    }
}
