//! Two index structures the mesh passes share: values of triangle corners bucketed by a vertex
//! ([`ByVertex`], a counting sort: the triangles around each vertex, the half-edges by their
//! lower vertex, a vertex's link), and disjoint sets with an optional sign per element
//! ([`UnionFind`], [`SignedSets`]).

/// Values gathered from triangle corners, bucketed by a vertex: vertex `v`'s are
/// [`ByVertex::of`]`(v)`, in triangle order, then corner order. Built in `O(V + F)`.
pub(crate) struct ByVertex<T> {
    start: Vec<usize>,
    items: Vec<T>,
}

impl<T: Copy + Default> ByVertex<T> {
    /// For `n` vertices: `item(t, k)` says for corner `k` of triangle `t` which vertex (`< n`)
    /// gets which value, or `None` to skip the corner. Called twice per corner (a count, then
    /// the fill): it must give the same answer both times.
    pub(crate) fn build(
        n: usize,
        triangles: usize,
        item: impl Fn(usize, usize) -> Option<(u32, T)>,
    ) -> Self {
        let mut start = vec![0usize; n + 1];
        for t in 0..triangles {
            for k in 0..3 {
                if let Some((v, _)) = item(t, k) {
                    start[v as usize + 1] += 1;
                }
            }
        }
        for i in 0..n {
            start[i + 1] += start[i];
        }
        let mut fill = start[..n].to_vec();
        let mut items = vec![T::default(); start[n]];
        for t in 0..triangles {
            for k in 0..3 {
                if let Some((v, x)) = item(t, k) {
                    items[fill[v as usize]] = x;
                    fill[v as usize] += 1;
                }
            }
        }
        ByVertex { start, items }
    }

    /// The values of vertex `v`.
    pub(crate) fn of(&self, v: usize) -> &[T] {
        &self.items[self.start[v]..self.start[v + 1]]
    }

    /// The values of vertex `v`, to reorder them.
    pub(crate) fn of_mut(&mut self, v: usize) -> &mut [T] {
        &mut self.items[self.start[v]..self.start[v + 1]]
    }

    /// Number of vertices (buckets).
    pub(crate) fn vertices(&self) -> usize {
        self.start.len() - 1
    }

    /// Number of values in all buckets.
    pub(crate) fn len(&self) -> usize {
        self.items.len()
    }
}

/// The triangles (indices into `triangles`) around each of `n` vertices, skipping those for
/// which `skip(t)` is true.
pub(crate) fn vertex_triangles(
    n: usize,
    triangles: &[[u32; 3]],
    skip: impl Fn(usize) -> bool,
) -> ByVertex<u32> {
    ByVertex::build(n, triangles.len(), |t, k| {
        (!skip(t)).then(|| (triangles[t][k], t as u32))
    })
}

/// What an element of a disjoint-set forest holds relative to its parent: nothing for plain
/// sets, a sign for [`SignedSets`]. Composing along the path to the root gives an element's
/// relation to its set's root.
pub(crate) trait Relation: Copy + Default {
    /// The relation to the grandparent from the relations to the parent (`self`) and the
    /// parent's to the grandparent.
    fn then(self, parent: Self) -> Self;
}

impl Relation for () {
    fn then(self, _parent: ()) {}
}

impl Relation for bool {
    fn then(self, parent: bool) -> bool {
        self ^ parent
    }
}

/// Disjoint-set forest with union by size (ties: the first argument's root stays the root) and
/// path halving: `O(α(n))` amortised per operation.
pub(crate) struct Forest<R> {
    parent: Vec<u32>,
    size: Vec<u32>,
    relation: Vec<R>,
}

/// Plain disjoint sets.
pub(crate) type UnionFind = Forest<()>;

/// Disjoint sets with a parity bit per element, its sign relative to its set's root: joining two
/// sets along a signed relation ("same" / "opposite") keeps every relation inside a set
/// consistent, which orients a spanning forest without walking it.
pub(crate) type SignedSets = Forest<bool>;

impl<R: Relation> Forest<R> {
    /// `n` singletons.
    pub(crate) fn new(n: usize) -> Self {
        Forest {
            parent: (0..n as u32).collect(),
            size: vec![1; n],
            relation: vec![R::default(); n],
        }
    }

    /// `n` singletons again, reusing the storage.
    pub(crate) fn reset(&mut self, n: usize) {
        self.parent.clear();
        self.parent.extend(0..n as u32);
        self.size.clear();
        self.size.resize(n, 1);
        self.relation.clear();
        self.relation.resize(n, R::default());
    }

    /// The root of `x`'s set and `x`'s relation to it.
    fn root(&mut self, mut x: u32) -> (u32, R) {
        let mut to_root = R::default();
        while self.parent[x as usize] != x {
            let p = self.parent[x as usize] as usize;
            let r = self.relation[x as usize].then(self.relation[p]);
            self.relation[x as usize] = r;
            self.parent[x as usize] = self.parent[p];
            to_root = to_root.then(r);
            x = self.parent[p];
        }
        (x, to_root)
    }

    /// Joins the roots `ra` and `rb` (distinct) with `relation` from the smaller to the larger.
    fn link(&mut self, ra: u32, rb: u32, relation: R) {
        let (big, small) = if self.size[ra as usize] >= self.size[rb as usize] {
            (ra, rb)
        } else {
            (rb, ra)
        };
        self.parent[small as usize] = big;
        self.relation[small as usize] = relation;
        self.size[big as usize] += self.size[small as usize];
    }

    /// Number of elements in the set of `x`.
    pub(crate) fn set_size(&mut self, x: u32) -> u32 {
        let r = self.root(x).0;
        self.size[r as usize]
    }
}

impl UnionFind {
    /// The root of `x`'s set.
    pub(crate) fn find(&mut self, x: u32) -> u32 {
        self.root(x).0
    }

    /// Joins the sets of `a` and `b`; false when they were one already.
    pub(crate) fn union(&mut self, a: u32, b: u32) -> bool {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra == rb {
            return false;
        }
        self.link(ra, rb, ());
        true
    }
}

impl SignedSets {
    /// Root of `x` and the parity of `x` relative to it.
    pub(crate) fn find(&mut self, x: u32) -> (u32, bool) {
        self.root(x)
    }

    /// Joins the sets of `a` and `b` so that their parities differ by `!agree`. False when they
    /// were already one set.
    pub(crate) fn union(&mut self, a: u32, b: u32, agree: bool) -> bool {
        let ((ra, pa), (rb, pb)) = (self.find(a), self.find(b));
        if ra == rb {
            return false;
        }
        self.link(ra, rb, pa ^ pb ^ !agree);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signs_follow_every_relation_inside_a_set() {
        // A chain 0 - 1 - ... - 9 where every third link says "opposite".
        let mut s = SignedSets::new(10);
        for i in 0..9u32 {
            assert!(s.union(i, i + 1, i % 3 != 2));
        }
        assert!(!s.union(0, 9, true));
        let (root, p0) = s.find(0);
        let mut flips = 0;
        for i in 0..10u32 {
            let (r, p) = s.find(i);
            assert_eq!(r, root);
            // Element i's sign differs from 0's by the parity of the "opposite" links before it.
            assert_eq!(p ^ p0, flips % 2 == 1, "element {i}");
            if i % 3 == 2 {
                flips += 1;
            }
        }
        assert_eq!(s.set_size(4), 10);
    }

    #[test]
    fn plain_sets_join_by_size_and_corners_bucket_by_vertex() {
        let mut u = UnionFind::new(5);
        assert!(u.union(0, 1) && u.union(2, 3) && u.union(3, 4));
        // The larger set's root stays the root.
        assert_eq!(u.find(0), u.find(1));
        assert!(u.union(1, 4));
        assert_eq!((u.find(0), u.find(4)), (2, 2));
        assert_eq!(u.set_size(0), 5);
        let tris = [[0, 1, 2], [2, 1, 3], [3, 4, 2]];
        let by = vertex_triangles(5, &tris, |t| t == 1);
        assert_eq!(by.vertices(), 5);
        assert_eq!(by.len(), 6);
        assert_eq!(by.of(2), &[0, 2]);
        assert_eq!(by.of(1), &[0]);
        assert!(by.of(3) == [2] && by.of(4) == [2] && by.of(0) == [0]);
    }
}
