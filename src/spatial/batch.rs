//! Parallel (rayon) radius queries for many query points at once, returning compressed
//! neighbour lists. `O(Σ query cost / threads)`; memory `O(total hits)`.

use rayon::prelude::*;

use crate::geometry::Point3;

use super::SpatialIndex;

/// Neighbour lists in compressed-row form: the neighbours of query `i` are
/// `indices[offsets[i]..offsets[i + 1]]` (unsorted within a row).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct NeighbourLists {
    /// Row starts; `queries + 1` entries, `offsets[0] = 0`.
    pub offsets: Vec<usize>,
    /// Point indices of all rows, concatenated.
    pub indices: Vec<u32>,
}

impl NeighbourLists {
    /// Number of query rows.
    pub fn rows(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Neighbours of query `i` (empty when `i` is out of range).
    pub fn row(&self, i: usize) -> &[u32] {
        match (self.offsets.get(i), self.offsets.get(i + 1)) {
            (Some(&a), Some(&b)) => &self.indices[a..b],
            _ => &[],
        }
    }
}

/// For every query point, the indices of all indexed points within distance `r`, computed in
/// parallel on the current rayon pool.
///
/// ```
/// use rbfsurf::spatial::{IndexKind, build_index, within_batch};
/// let pts = [[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [1.0, 0.0, 0.0]];
/// let index = build_index(&pts, IndexKind::KdTree, 8).unwrap();
/// let lists = within_batch(index.as_ref(), &pts, 0.2);
/// assert_eq!(lists.row(2), &[2]);
/// assert_eq!(lists.indices.len(), 5);
/// ```
pub fn within_batch(index: &dyn SpatialIndex, queries: &[Point3], r: f64) -> NeighbourLists {
    const CHUNK: usize = 1024;
    let chunks: Vec<(Vec<usize>, Vec<u32>)> = queries
        .par_chunks(CHUNK)
        .map(|chunk| {
            let mut lens = Vec::with_capacity(chunk.len());
            let mut all = Vec::new();
            let mut buf = Vec::new();
            for q in chunk {
                index.within(q, r, &mut buf);
                lens.push(buf.len());
                all.extend_from_slice(&buf);
            }
            (lens, all)
        })
        .collect();
    let total = chunks.iter().map(|c| c.1.len()).sum();
    let mut offsets = Vec::with_capacity(queries.len() + 1);
    let mut indices = Vec::with_capacity(total);
    offsets.push(0);
    for (lens, all) in chunks {
        for l in lens {
            offsets.push(offsets.last().copied().unwrap_or(0) + l);
        }
        indices.extend(all);
    }
    NeighbourLists { offsets, indices }
}

#[cfg(test)]
mod tests {
    use super::super::test_clouds::sphere_surface;
    use super::super::{IndexKind, brute_force, build_index};
    use super::*;

    #[test]
    fn batch_equals_single_queries() {
        let pts = sphere_surface(3000, 12);
        for kind in [IndexKind::Octree, IndexKind::KdTree] {
            let index = build_index(&pts, kind, 8).unwrap();
            let lists = within_batch(index.as_ref(), &pts, 0.05);
            assert_eq!(lists.rows(), pts.len());
            let mut want = Vec::new();
            for (i, q) in pts.iter().enumerate() {
                brute_force::within(&pts, q, 0.05, &mut want);
                let mut got = lists.row(i).to_vec();
                got.sort_unstable();
                assert_eq!(got, want);
            }
            assert!(lists.row(pts.len()).is_empty());
        }
        let empty = build_index(&[], IndexKind::KdTree, 8).unwrap();
        assert_eq!(within_batch(empty.as_ref(), &[], 1.0).rows(), 0);
    }
}
