//! Current limits owed to the joints of a bus: a routine that lowered a
//! joint's limit (a grasp's hold, homing's push) could not write the
//! previous one back and read it back (the joint offline, the bus down).
//! While a limit is owed nothing new may move the joint: it would push
//! with a limit nobody chose, or have its grasp refused for a limit that
//! is not the joint's own. The control core writes it back once the joint
//! answers again ([`crate::control::current_limit`]); this is the list
//! every admission and view reads.

use std::collections::BTreeMap;
use std::sync::{Mutex, MutexGuard};

/// The limits owed, by device id: the raw limit (Q15) to write back.
#[derive(Debug, Default)]
pub struct OwedLimits {
    owed: Mutex<BTreeMap<u8, u16>>,
}

impl OwedLimits {
    // std Mutex: never held across an `.await`.
    fn lock(&self) -> MutexGuard<'_, BTreeMap<u8, u16>> {
        self.owed.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Joint `id` is owed `previous`; returns false when it already was
    /// (the first limit owed is the joint's own and stays the one owed).
    pub fn owe(&self, id: u8, previous: u16) -> bool {
        let mut owed = self.lock();
        if owed.contains_key(&id) {
            return false;
        }
        owed.insert(id, previous);
        true
    }

    /// The limit owed to joint `id`, if any.
    pub fn get(&self, id: u8) -> Option<u16> {
        self.lock().get(&id).copied()
    }

    /// Joint `id` has its limit back.
    pub fn settle(&self, id: u8) {
        self.lock().remove(&id);
    }

    /// How many joints are owed a limit.
    pub fn len(&self) -> usize {
        self.lock().len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_limit_owed_stays_owed_until_settled() {
        let o = OwedLimits::default();
        assert!(o.owe(3, 4000));
        // A second routine failing on the same joint owes what it found,
        // the first one's reduced limit: the joint's own stays owed.
        assert!(!o.owe(3, 200));
        assert_eq!(o.get(3), Some(4000));
        assert_eq!(o.len(), 1);
        o.settle(3);
        assert_eq!(o.get(3), None);
        assert!(o.is_empty());
    }
}
