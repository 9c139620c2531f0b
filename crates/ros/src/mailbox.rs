//! A bounded hand-over between threads that drops the oldest item when full: a node that
//! cannot keep up maps the newest frames and counts what it dropped, instead of lagging
//! further behind with a growing queue.

use std::collections::VecDeque;
use std::sync::{Condvar, Mutex};

pub struct Mailbox<T> {
    state: Mutex<State<T>>,
    ready: Condvar,
    capacity: usize,
}

struct State<T> {
    items: VecDeque<T>,
    dropped: u64,
    closed: bool,
}

impl<T> Mailbox<T> {
    /// `capacity` is at least 1.
    pub fn new(capacity: usize) -> Self {
        Self {
            state: Mutex::new(State {
                items: VecDeque::new(),
                dropped: 0,
                closed: false,
            }),
            ready: Condvar::new(),
            capacity: capacity.max(1),
        }
    }

    /// Hands `item` over; the oldest waiting item is dropped (and counted) when full. Returns
    /// whether one was dropped.
    pub fn put(&self, item: T) -> bool {
        let mut s = self.state.lock().expect("no panics while held");
        let dropped = s.items.len() >= self.capacity;
        if dropped {
            s.items.pop_front();
            s.dropped += 1;
        }
        s.items.push_back(item);
        self.ready.notify_one();
        dropped
    }

    /// [`put`](Self::put), but when full the oldest `expendable` item goes first (the new
    /// one included, when it is the only one): a mapping node that falls behind drops frames
    /// between keyframes, whose masks the map makes itself, before the keyframes that are
    /// its only evidence. Returns whether one was dropped.
    pub fn put_dropping_first(&self, item: T, expendable: impl Fn(&T) -> bool) -> bool {
        let mut s = self.state.lock().expect("no panics while held");
        let full = s.items.len() >= self.capacity;
        if full {
            s.dropped += 1;
            match s.items.iter().position(&expendable) {
                Some(oldest) => {
                    s.items.remove(oldest);
                }
                None if expendable(&item) => return true,
                None => {
                    s.items.pop_front();
                }
            }
        }
        s.items.push_back(item);
        self.ready.notify_one();
        full
    }

    /// The next item; `None` once closed and empty.
    pub fn take(&self) -> Option<T> {
        let mut s = self.state.lock().expect("no panics while held");
        loop {
            if let Some(item) = s.items.pop_front() {
                return Some(item);
            }
            if s.closed {
                return None;
            }
            s = self.ready.wait(s).expect("no panics while held");
        }
    }

    /// No more items: [`take`](Self::take) returns what is left, then `None`.
    pub fn close(&self) {
        self.state.lock().expect("no panics while held").closed = true;
        self.ready.notify_all();
    }

    /// Items dropped because the mailbox was full.
    pub fn dropped(&self) -> u64 {
        self.state.lock().expect("no panics while held").dropped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn full_mailbox_drops_the_oldest_and_counts() {
        let m = Mailbox::new(2);
        assert!(!m.put(1));
        assert!(!m.put(2));
        assert!(m.put(3));
        m.close();
        assert_eq!((m.take(), m.take(), m.take()), (Some(2), Some(3), None));
        assert_eq!(m.dropped(), 1);
    }

    #[test]
    fn a_full_mailbox_drops_the_oldest_expendable_item_first() {
        let m = Mailbox::new(3);
        let odd = |i: &i32| i % 2 == 1;
        for i in [2, 3, 4] {
            assert!(!m.put_dropping_first(i, odd));
        }
        // 3 goes, though 2 is older; then, with no odd one waiting, the new odd one.
        assert!(m.put_dropping_first(6, odd));
        assert!(m.put_dropping_first(7, odd));
        // With none expendable, the oldest.
        assert!(m.put_dropping_first(8, odd));
        m.close();
        let rest: Vec<i32> = std::iter::from_fn(|| m.take()).collect();
        assert_eq!(rest, [4, 6, 8]);
        assert_eq!(m.dropped(), 3);
    }

    #[test]
    fn take_waits_for_a_producer() {
        let m = std::sync::Arc::new(Mailbox::new(1));
        let producer = {
            let m = m.clone();
            std::thread::spawn(move || {
                for i in 0..100 {
                    // A capacity-1 mailbox with a slow consumer drops; count what arrives.
                    m.put(i);
                }
                m.close();
            })
        };
        let mut got = Vec::new();
        while let Some(i) = m.take() {
            got.push(i);
        }
        producer.join().unwrap();
        assert_eq!(got.len() as u64 + m.dropped(), 100);
        assert!(got.windows(2).all(|w| w[0] < w[1]), "order kept: {got:?}");
        assert_eq!(got.last(), Some(&99), "the newest item always arrives");
    }
}
