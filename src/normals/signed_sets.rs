//! Union-find with a parity bit per element: the sign of an element relative to its set's root.
//! Joining two sets along a signed relation ("same" / "opposite") keeps every relation inside a
//! set consistent, which orients a spanning forest without walking it. Path compression and union
//! by size: `O(α(n))` amortised per operation.

/// Union-find with path compression, union by size and parity relative to the root.
pub(crate) struct SignedSets {
    parent: Vec<u32>,
    parity: Vec<bool>,
    size: Vec<u32>,
}

impl SignedSets {
    /// `n` singletons, each with parity `false`.
    pub(crate) fn new(n: usize) -> Self {
        SignedSets {
            parent: (0..n as u32).collect(),
            parity: vec![false; n],
            size: vec![1; n],
        }
    }

    /// Root of `i` and the parity of `i` relative to it.
    pub(crate) fn find(&mut self, i: u32) -> (u32, bool) {
        let mut path = Vec::new();
        let mut r = i;
        while self.parent[r as usize] != r {
            path.push(r);
            r = self.parent[r as usize];
        }
        // Compress from the top down so each parity is relative to the root.
        let mut acc = false;
        for &v in path.iter().rev() {
            acc ^= self.parity[v as usize];
            self.parity[v as usize] = acc;
            self.parent[v as usize] = r;
        }
        (
            r,
            if path.is_empty() {
                false
            } else {
                self.parity[i as usize]
            },
        )
    }

    /// Join the sets of `a` and `b` so that their parities differ by `!agree`. False when they
    /// were already one set.
    pub(crate) fn union(&mut self, a: u32, b: u32, agree: bool) -> bool {
        let ((ra, pa), (rb, pb)) = (self.find(a), self.find(b));
        if ra == rb {
            return false;
        }
        let (big, small) = if self.size[ra as usize] >= self.size[rb as usize] {
            (ra, rb)
        } else {
            (rb, ra)
        };
        self.parent[small as usize] = big;
        self.parity[small as usize] = pa ^ pb ^ !agree;
        self.size[big as usize] += self.size[small as usize];
        true
    }

    /// Number of elements in the set of `i`.
    pub(crate) fn set_size(&mut self, i: u32) -> u32 {
        let r = self.find(i).0;
        self.size[r as usize]
    }
}
