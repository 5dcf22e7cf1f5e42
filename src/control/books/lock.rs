//! A job's slot is read and written under a std `Mutex`, never across an
//! `.await`; a task that panicked while holding one left a state that is
//! still the best account of its joint, so a poisoned lock is taken as is.

use std::sync::{Mutex, MutexGuard};

pub(crate) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}
