//! A store of the entries used most recently, within a bound on their summed cost: the
//! process-wide caches of the sparse points' preparation (each mesh's placement, bounded by
//! bytes; the link-tested point sets, bounded by count) keep what a viewer session or a
//! benchmark will ask for again without growing with every setting tried.

/// Entries by key, the least recently used first. Lookups scan: the stores hold at most a few
/// thousand entries, looked up once per mesh of a build.
pub struct Recent<K, V> {
    entries: Vec<(K, V, usize)>,
    cost: usize,
    cap: usize,
}

impl<K: PartialEq, V> Recent<K, V> {
    /// An empty store that keeps a summed cost of at most `cap`.
    pub const fn new(cap: usize) -> Self {
        Self {
            entries: Vec::new(),
            cost: 0,
            cap,
        }
    }

    /// The value kept for `key`, now the most recently used.
    pub fn get(&mut self, key: &K) -> Option<&V> {
        let at = self.entries.iter().position(|(k, _, _)| k == key)?;
        let entry = self.entries.remove(at);
        self.entries.push(entry);
        self.entries.last().map(|(_, value, _)| value)
    }

    /// Keeps `value` for `key` (replacing what was kept for it) at `cost`, then drops the
    /// least recently used entries until the summed cost is within the cap. The entry just
    /// kept stays, however costly.
    pub fn insert(&mut self, key: K, value: V, cost: usize) {
        if let Some(at) = self.entries.iter().position(|(k, _, _)| *k == key) {
            self.cost -= self.entries.remove(at).2;
        }
        self.entries.push((key, value, cost));
        self.cost += cost;
        while self.cost > self.cap && self.entries.len() > 1 {
            self.cost -= self.entries.remove(0).2;
        }
    }

    /// The entries kept.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Their summed cost.
    pub fn cost(&self) -> usize {
        self.cost
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The least recently used go first once the cost passes the cap; a replaced entry counts
    /// once; an entry costlier than the cap stays, alone.
    #[test]
    fn the_most_recently_used_stay_within_the_cap() {
        let mut store = Recent::new(30);
        for key in 0..3 {
            store.insert(key, key * 10, 10);
        }
        assert_eq!((store.len(), store.cost()), (3, 30));
        assert_eq!(store.get(&0), Some(&0));
        store.insert(3, 30, 10);
        assert_eq!(store.get(&1), None, "1 was the least recently used");
        for key in [0, 2, 3] {
            assert_eq!(store.get(&key), Some(&(key * 10)));
        }
        store.insert(2, 21, 10);
        assert_eq!(
            (store.len(), store.cost(), store.get(&2)),
            (3, 30, Some(&21))
        );
        store.insert(9, 90, 40);
        assert_eq!((store.len(), store.cost()), (1, 40));
        assert_eq!(store.get(&9), Some(&90));
    }
}
