//! The bridge's link to the Zenoh network, decided apart from any I/O:
//! how long to wait before the next attempt (0.5 s doubling to 30 s,
//! back to the start once connected) and what is worth a log line. A
//! router that stays away is said once (a WARN), not once per retry; the
//! connection coming up is said once (an INFO); a connection lost is
//! said once again.

use std::time::Duration;

/// The first wait after a failed attempt.
pub const FIRST_RETRY: Duration = Duration::from_millis(500);
/// The longest wait between attempts.
pub const MAX_RETRY: Duration = Duration::from_secs(30);

/// What the supervisor should log after an event, if anything.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Say {
    Nothing,
    /// The first failure since start or since the link was up.
    Unreachable,
    Connected,
    Lost,
}

/// The link's state across attempts.
#[derive(Debug, Clone)]
pub struct Link {
    next_wait: Duration,
    up: bool,
    /// A failure was said since the link was last up (or since start).
    said_down: bool,
}

impl Default for Link {
    fn default() -> Self {
        Self {
            next_wait: FIRST_RETRY,
            up: false,
            said_down: false,
        }
    }
}

impl Link {
    /// An attempt failed: what to say, and how long to wait before the next.
    pub fn failed(&mut self) -> (Say, Duration) {
        self.up = false;
        let wait = self.next_wait;
        self.next_wait = (self.next_wait * 2).min(MAX_RETRY);
        let say = if self.said_down {
            Say::Nothing
        } else {
            self.said_down = true;
            Say::Unreachable
        };
        (say, wait)
    }

    /// The session is up: the next outage starts from the first wait.
    pub fn connected(&mut self) -> Say {
        self.up = true;
        self.said_down = false;
        self.next_wait = FIRST_RETRY;
        Say::Connected
    }

    /// A session that was up is gone; the next attempt follows at once
    /// (a router restarting is usually back within the first wait).
    pub fn lost(&mut self) -> Say {
        if !self.up {
            return Say::Nothing;
        }
        self.up = false;
        // The loss is said; the failures of the attempts after it are not.
        self.said_down = true;
        Say::Lost
    }

    pub fn is_up(&self) -> bool {
        self.up
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn waits_double_to_thirty_seconds_and_a_down_router_is_said_once() {
        let mut link = Link::default();
        let mut waits = Vec::new();
        let mut said = Vec::new();
        for _ in 0..10 {
            let (say, wait) = link.failed();
            said.push(say);
            waits.push(wait.as_millis());
        }
        assert_eq!(
            waits,
            [500, 1000, 2000, 4000, 8000, 16000, 30000, 30000, 30000, 30000]
        );
        assert_eq!(said[0], Say::Unreachable);
        assert!(said[1..].iter().all(|s| *s == Say::Nothing), "{said:?}");
        assert!(!link.is_up());
    }

    #[test]
    fn connecting_resets_the_wait_and_a_loss_is_said_once() {
        let mut link = Link::default();
        link.failed();
        link.failed();
        assert_eq!(link.connected(), Say::Connected);
        assert!(link.is_up());
        assert_eq!(link.lost(), Say::Lost);
        assert_eq!(link.lost(), Say::Nothing, "lost once");
        // The retries after a loss are not said again.
        assert_eq!(link.failed(), (Say::Nothing, FIRST_RETRY));
        assert_eq!(link.failed().0, Say::Nothing);
        assert_eq!(link.connected(), Say::Connected);
        // A later outage that fails at once is said again.
        assert_eq!(link.lost(), Say::Lost);
        link.connected();
        assert_eq!(link.failed(), (Say::Unreachable, FIRST_RETRY));
    }
}
