//! A discrete-event queue on the integer-nanosecond mission clock. Events at the same time
//! come out in the order they were scheduled, so a run never depends on heap internals;
//! events pushed with [`Scheduler::push_first`] come out before the others of their time
//! (the world's physics step at t, so every sensor stamped t sees the world of time t).

use realms_core::Time;
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// Events ordered by (time, rank, insertion order).
#[derive(Debug)]
pub struct Scheduler<E> {
    heap: BinaryHeap<Reverse<Entry<E>>>,
    seq: u64,
}

/// A queued event with its sort key: time, rank, insertion order.
type Entry<E> = (Time, Rank, u64, Slot<E>);

/// Which events of one instant come out first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Rank {
    First,
    InOrder,
}

/// Wraps an event so the heap orders only by (time, rank, seq), never by the event itself.
#[derive(Debug)]
struct Slot<E>(E);

impl<E> PartialEq for Slot<E> {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}
impl<E> Eq for Slot<E> {}
impl<E> PartialOrd for Slot<E> {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl<E> Ord for Slot<E> {
    fn cmp(&self, _: &Self) -> std::cmp::Ordering {
        std::cmp::Ordering::Equal
    }
}

impl<E> Default for Scheduler<E> {
    fn default() -> Self {
        Scheduler {
            heap: BinaryHeap::new(),
            seq: 0,
        }
    }
}

impl<E> Scheduler<E> {
    /// An empty queue.
    pub fn new() -> Self {
        Self::default()
    }

    /// Schedules `event` at `at`, after everything already scheduled then.
    pub fn push(&mut self, at: Time, event: E) {
        self.push_ranked(at, Rank::InOrder, event);
    }

    /// Schedules `event` at `at`, before every event of that time pushed with
    /// [`Scheduler::push`] (and after those pushed here earlier).
    pub fn push_first(&mut self, at: Time, event: E) {
        self.push_ranked(at, Rank::First, event);
    }

    fn push_ranked(&mut self, at: Time, rank: Rank, event: E) {
        self.heap.push(Reverse((at, rank, self.seq, Slot(event))));
        self.seq += 1;
    }

    /// Time of the next event.
    pub fn peek_time(&self) -> Option<Time> {
        self.heap.peek().map(|Reverse((t, _, _, _))| *t)
    }

    /// Removes and returns the next event if it is due at or before `until`.
    pub fn pop_due(&mut self, until: Time) -> Option<(Time, E)> {
        if self.peek_time()? > until {
            return None;
        }
        self.heap.pop().map(|Reverse((t, _, _, Slot(e)))| (t, e))
    }

    /// Number of pending events.
    pub fn len(&self) -> usize {
        self.heap.len()
    }

    /// Whether nothing is pending.
    pub fn is_empty(&self) -> bool {
        self.heap.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_time_events_keep_insertion_order() {
        let mut s = Scheduler::new();
        s.push(Time(5), "b1");
        s.push(Time(1), "a");
        s.push(Time(5), "b2");
        s.push(Time(9), "c");
        assert_eq!(s.pop_due(Time(5)), Some((Time(1), "a")));
        assert_eq!(s.pop_due(Time(5)), Some((Time(5), "b1")));
        assert_eq!(s.pop_due(Time(5)), Some((Time(5), "b2")));
        assert_eq!(s.pop_due(Time(5)), None);
        assert_eq!(s.peek_time(), Some(Time(9)));
    }

    #[test]
    fn events_pushed_first_lead_their_instant_whenever_pushed() {
        let mut s = Scheduler::new();
        s.push(Time(5), "sensor");
        s.push(Time(3), "earlier");
        s.push_first(Time(5), "physics");
        s.push_first(Time(5), "physics again");
        assert_eq!(s.pop_due(Time(5)), Some((Time(3), "earlier")));
        assert_eq!(s.pop_due(Time(5)), Some((Time(5), "physics")));
        assert_eq!(s.pop_due(Time(5)), Some((Time(5), "physics again")));
        assert_eq!(s.pop_due(Time(5)), Some((Time(5), "sensor")));
        assert_eq!(s.pop_due(Time(5)), None);
    }
}
