//! The moves made through the API (`POST /api/v1/moves`): the running ones
//! and the last that ended, for `GET` and `DELETE`. A std `Mutex`: never
//! held across an `.await`.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

use crate::control::joints::JointRef;
use crate::motion::RunningMove;

/// Moves kept for `GET` after they ended.
const KEPT: usize = 256;

/// The moves made through the API: running ones and the last that ended.
#[derive(Default)]
pub(crate) struct MoveBook {
    inner: Mutex<Book>,
}

#[derive(Default)]
struct Book {
    next_id: u64,
    moves: BTreeMap<u64, Booked>,
}

#[derive(Clone)]
pub(crate) struct Booked {
    pub mv: Arc<RunningMove>,
    pub joints: Vec<JointRef>,
}

impl MoveBook {
    fn lock(&self) -> std::sync::MutexGuard<'_, Book> {
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub(crate) fn next_id(&self) -> u64 {
        let mut book = self.lock();
        book.next_id += 1;
        book.next_id
    }

    pub(crate) fn insert(&self, mv: Arc<RunningMove>, joints: Vec<JointRef>) {
        let mut book = self.lock();
        book.moves.insert(mv.id, Booked { mv, joints });
        while book.moves.len() > KEPT {
            let oldest_ended = book
                .moves
                .iter()
                .find(|(_, b)| !b.mv.is_running())
                .map(|(id, _)| *id);
            match oldest_ended {
                Some(id) => drop(book.moves.remove(&id)),
                None => break,
            }
        }
    }

    pub(crate) fn get(&self, id: u64) -> Option<Booked> {
        self.lock().moves.get(&id).cloned()
    }
}
