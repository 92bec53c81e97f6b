//! The host's bookkeeping of a GPU brick pool: which brick of a brick store each pool slot
//! holds, when each slot was last used, and where a requested brick goes. The pool starts
//! small, doubles up to its budget, and then evicts the least recently used bricks, never
//! one used or uploaded in the current pass. No GPU here: `super::streamed` mirrors these
//! decisions into the device's page table and texels.

use std::collections::{HashMap, HashSet};

/// A slot holding no brick.
const FREE: u32 = u32::MAX;

/// Where a brick goes: its pool slot, and the brick it displaces there, if any.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Placement {
    /// The brick (its page-table index).
    pub brick: u32,
    /// Its pool slot.
    pub slot: u32,
    /// The brick evicted from the slot.
    pub evicted: Option<u32>,
}

/// What one [`BrickPool::admit`] did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Admission {
    /// The bricks placed, in the order requested.
    pub placed: Vec<Placement>,
    /// Slots the pool holds after it (grown by doubling when it was full).
    pub slots: u32,
    /// Requested bricks that found no slot: every slot holds a brick of this pass.
    pub refused: usize,
}

/// The slots of a brick pool and their bricks.
pub struct BrickPool {
    /// The brick in each slot, or [`FREE`].
    bricks: Vec<u32>,
    /// The last pass each slot was used or filled in.
    stamps: Vec<u32>,
    /// The slot of each resident brick.
    slot_of: HashMap<u32, u32>,
    /// Slots never filled, from the end of `bricks` down.
    free: Vec<u32>,
    /// Most slots the budget allows.
    max_slots: u32,
}

impl BrickPool {
    /// An empty pool of `initial` slots that may double up to `max_slots` (`initial` is
    /// clamped to `1..=max_slots`).
    pub fn new(initial: u32, max_slots: u32) -> BrickPool {
        let max_slots = max_slots.max(1);
        let mut pool = BrickPool {
            bricks: Vec::new(),
            stamps: Vec::new(),
            slot_of: HashMap::new(),
            free: Vec::new(),
            max_slots,
        };
        pool.grow_to(initial.clamp(1, max_slots));
        pool
    }

    /// Slots the pool holds now.
    pub fn slots(&self) -> u32 {
        self.bricks.len() as u32
    }

    /// Most slots the pool may hold.
    pub fn max_slots(&self) -> u32 {
        self.max_slots
    }

    /// The slot holding `brick`, if resident.
    #[cfg(test)]
    pub fn slot_of(&self, brick: u32) -> Option<u32> {
        self.slot_of.get(&brick).copied()
    }

    /// Bricks resident.
    pub fn resident(&self) -> usize {
        self.slot_of.len()
    }

    fn grow_to(&mut self, slots: u32) {
        let old = self.slots();
        self.bricks.resize(slots as usize, FREE);
        self.stamps.resize(slots as usize, 0);
        self.free.extend((old..slots).rev());
    }

    /// Records that the slots with `stamps[slot] == pass` were used in `pass` (the stamps
    /// the kernel wrote; a longer or shorter array covers the slots it has).
    pub fn record_use(&mut self, stamps: &[u32], pass: u32) {
        for (s, &t) in self.stamps.iter_mut().zip(stamps) {
            if t == pass {
                *s = pass;
            }
        }
    }

    /// Places the requested `bricks` (not resident; duplicates are placed once) during
    /// `pass`: in free slots, then in slots of a pool doubled up to its budget, then in the
    /// slots used longest ago before `pass`. Bricks that find none are counted as refused.
    pub fn admit(&mut self, bricks: &[u32], pass: u32) -> Admission {
        let mut out = Admission::default();
        let mut seen = HashSet::new();
        let wanted: Vec<u32> = (bricks.iter().copied())
            .filter(|b| !self.slot_of.contains_key(b) && seen.insert(*b))
            .collect();
        // Grow by doubling while free slots fall short.
        while self.free.len() < wanted.len() && self.slots() < self.max_slots {
            let next = self.slots().saturating_mul(2).min(self.max_slots);
            self.grow_to(next);
        }
        // Eviction candidates: slots holding a brick not used in this pass, oldest first.
        let shortfall = wanted.len().saturating_sub(self.free.len());
        let mut victims: Vec<u32> = if shortfall > 0 {
            let mut v: Vec<u32> = (0..self.slots())
                .filter(|&s| self.bricks[s as usize] != FREE && self.stamps[s as usize] < pass)
                .collect();
            v.sort_by_key(|&s| (self.stamps[s as usize], s));
            v.truncate(shortfall);
            v.reverse();
            v
        } else {
            Vec::new()
        };
        for brick in wanted {
            let (slot, evicted) = if let Some(slot) = self.free.pop() {
                (slot, None)
            } else if let Some(slot) = victims.pop() {
                let old = self.bricks[slot as usize];
                self.slot_of.remove(&old);
                (slot, Some(old))
            } else {
                out.refused += 1;
                continue;
            };
            self.bricks[slot as usize] = brick;
            self.stamps[slot as usize] = pass;
            self.slot_of.insert(brick, slot);
            out.placed.push(Placement {
                brick,
                slot,
                evicted,
            });
        }
        out.slots = self.slots();
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pool_doubles_up_to_its_budget_then_evicts_the_least_recently_used() {
        let mut pool = BrickPool::new(2, 6);
        let a = pool.admit(&[10, 11], 1);
        assert_eq!((a.slots, a.refused, pool.resident()), (2, 0, 2));
        // Four more: 2 -> 4 -> 6 slots (capped at the budget), all full.
        let a = pool.admit(&[12, 13, 14, 15], 2);
        assert_eq!((a.slots, a.refused), (6, 0));
        assert!(a.placed.iter().all(|p| p.evicted.is_none()));
        // Pass 3 used bricks 10 and 12 only; two new bricks evict 11 (pass 1) first, then
        // one of pass 2's unused ones (13, 14 or 15).
        let mut stamps = vec![0; 6];
        stamps[pool.slot_of(10).unwrap() as usize] = 3;
        stamps[pool.slot_of(12).unwrap() as usize] = 3;
        pool.record_use(&stamps, 3);
        let a = pool.admit(&[20, 21], 3);
        let evicted: Vec<_> = a.placed.iter().map(|p| p.evicted).collect();
        assert_eq!(evicted[0], Some(11));
        assert!(matches!(evicted[1], Some(13..=15)), "{evicted:?}");
        assert!(pool.slot_of(10).is_some() && pool.slot_of(12).is_some());
        assert_eq!(pool.slot_of(11), None);
        // Every slot used in pass 4: nothing can be evicted.
        pool.record_use(&[4; 6], 4);
        let a = pool.admit(&[30, 31], 4);
        assert_eq!((a.placed.len(), a.refused), (0, 2));
        // Resident bricks are not placed again; the slots stay a bijection.
        let a = pool.admit(&[10, 30], 5);
        assert_eq!(a.placed.len(), 1);
        let mut slots: Vec<u32> = [10, 11, 12, 13, 14, 15, 20, 21, 30, 31]
            .iter()
            .filter_map(|&b| pool.slot_of(b))
            .collect();
        slots.sort();
        slots.dedup();
        assert_eq!(slots.len(), pool.resident());
    }

    #[test]
    fn a_pool_never_exceeds_its_budget_nor_starts_empty() {
        let pool = BrickPool::new(0, 0);
        assert_eq!((pool.slots(), pool.max_slots()), (1, 1));
        let mut pool = BrickPool::new(64, 3);
        assert_eq!(pool.slots(), 3);
        let a = pool.admit(&[1, 2, 3, 4], 1);
        assert_eq!((a.slots, a.placed.len(), a.refused), (3, 3, 1));
    }
}
