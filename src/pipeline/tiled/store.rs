//! Where the task graph keeps its intermediate results (block point sets, splines, mesh pieces)
//! between tasks, and their binary encoding.
//!
//! Both stores hold the same encoded bytes, so the in-memory and the out-of-core executor run the
//! same decoding and give the same mesh. Encoding: little-endian, a 4-byte tag, then counts (u64)
//! and flat arrays of f64 / u32. Keys are `"points/{block}"`, `"spline/{block}"`,
//! `"piece/{region}"`: a rewritten key replaces the value (a task run twice writes the same bytes).

use crate::error::StoreError;
use crate::geometry::{Point3, TriMesh};
use std::collections::HashMap;
use std::io::Write;
use std::path::PathBuf;
use std::sync::Mutex;

/// Where intermediate results live.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum StoreKind {
    /// In the process's memory (the cloud's blocks must fit the budget).
    #[default]
    Memory,
    /// Files in a fresh temporary directory, under this directory (`None`: the system's
    /// temporary directory, `TMPDIR`); removed when the run ends.
    TempDir(Option<PathBuf>),
}

/// A store kept outside this process (the distributed executor's object store), reached
/// synchronously from the task threads.
pub(crate) trait RemoteStore: Send + Sync {
    /// Stores `bytes` under `key` (replacing any earlier value).
    fn put(&self, key: &str, bytes: Vec<u8>) -> Result<(), StoreError>;
    /// The bytes stored under `key`.
    fn get(&self, key: &str) -> Result<Vec<u8>, StoreError>;
}

/// A key–value store of encoded task results.
pub(crate) enum Store {
    Memory(Mutex<HashMap<String, Vec<u8>>>),
    Dir(tempfile::TempDir),
    /// Values elsewhere; `remove` keeps them (a redelivered task may read them again: the
    /// distributed executor deletes a job's values when the job ends).
    #[cfg_attr(not(feature = "nats"), allow(dead_code))]
    Remote(Box<dyn RemoteStore>),
}

impl Store {
    /// Opens an empty store of `kind`.
    pub(crate) fn open(kind: &StoreKind) -> Result<Store, StoreError> {
        match kind {
            StoreKind::Memory => Ok(Store::Memory(Mutex::new(HashMap::new()))),
            StoreKind::TempDir(parent) => {
                let b = tempfile::Builder::new()
                    .prefix("rbfsurf-tiles-")
                    .tempdir_in(parent.clone().unwrap_or_else(std::env::temp_dir));
                b.map(Store::Dir).map_err(|source| StoreError::Io {
                    path: parent.clone().unwrap_or_else(std::env::temp_dir),
                    source,
                })
            }
        }
    }

    fn path(dir: &tempfile::TempDir, key: &str) -> PathBuf {
        dir.path().join(key.replace('/', "-"))
    }

    /// Stores `bytes` under `key` (replacing any earlier value).
    pub(crate) fn put(&self, key: &str, bytes: Vec<u8>) -> Result<(), StoreError> {
        match self {
            Store::Memory(m) => {
                m.lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .insert(key.to_string(), bytes);
                Ok(())
            }
            Store::Dir(d) => {
                let path = Self::path(d, key);
                let io = |source| StoreError::Io {
                    path: path.clone(),
                    source,
                };
                let mut f = std::fs::File::create(&path).map_err(io)?;
                f.write_all(&bytes).map_err(io)
            }
            Store::Remote(r) => r.put(key, bytes),
        }
    }

    /// The bytes stored under `key`.
    pub(crate) fn get(&self, key: &str) -> Result<Vec<u8>, StoreError> {
        match self {
            Store::Memory(m) => m
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .get(key)
                .cloned()
                .ok_or_else(|| StoreError::Corrupt {
                    key: key.to_string(),
                    what: "missing",
                }),
            Store::Dir(d) => {
                let path = Self::path(d, key);
                std::fs::read(&path).map_err(|source| StoreError::Io { path, source })
            }
            Store::Remote(r) => r.get(key),
        }
    }

    /// Drops the value under `key` (frees its memory or disk space).
    pub(crate) fn remove(&self, key: &str) {
        match self {
            Store::Memory(m) => {
                m.lock().unwrap_or_else(|e| e.into_inner()).remove(key);
            }
            Store::Dir(d) => {
                let _ = std::fs::remove_file(Self::path(d, key));
            }
            Store::Remote(_) => {}
        }
    }
}

/// Points of one block (its outer box and halo) or one region, in ascending global id.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct PointSet {
    /// Global point ids (positions in the cleaned cloud), ascending.
    pub ids: Vec<u32>,
    /// Positions, normalised units.
    pub points: Vec<Point3>,
    /// Unit normals (zero = unusable), oriented outwards; `None` without normals.
    pub normals: Option<Vec<Point3>>,
}

/// One spline level: centres, weights and support radius (normalised units).
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct LevelData {
    pub centres: Vec<Point3>,
    pub weights: Vec<f64>,
    pub support: f64,
}

/// A block's fitted spline, as shipped between tasks.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct SplineData {
    pub levels: Vec<LevelData>,
    pub polynomial: Option<[f64; 4]>,
}

/// Little-endian writer.
#[derive(Default)]
struct Enc(Vec<u8>);

impl Enc {
    fn tag(mut self, t: &[u8; 4]) -> Self {
        self.0.extend_from_slice(t);
        self
    }
    fn u64(&mut self, v: u64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f64s(&mut self, v: impl IntoIterator<Item = f64>) {
        for x in v {
            self.0.extend_from_slice(&x.to_le_bytes());
        }
    }
    fn points(&mut self, p: &[Point3]) {
        self.u64(p.len() as u64);
        self.f64s(p.iter().flatten().copied());
    }
}

/// Little-endian reader over a stored value.
struct Dec<'a> {
    bytes: &'a [u8],
    key: &'a str,
}

impl<'a> Dec<'a> {
    fn new(bytes: &'a [u8], key: &'a str, tag: &[u8; 4]) -> Result<Self, StoreError> {
        let mut d = Dec { bytes, key };
        if d.take(4)? != tag {
            return Err(d.bad("wrong tag"));
        }
        Ok(d)
    }
    fn bad(&self, what: &'static str) -> StoreError {
        StoreError::Corrupt {
            key: self.key.to_string(),
            what,
        }
    }
    fn take(&mut self, n: usize) -> Result<&'a [u8], StoreError> {
        if self.bytes.len() < n {
            return Err(self.bad("truncated"));
        }
        let (a, b) = self.bytes.split_at(n);
        self.bytes = b;
        Ok(a)
    }
    fn u64(&mut self) -> Result<u64, StoreError> {
        Ok(u64::from_le_bytes(
            self.take(8)?.try_into().unwrap_or([0; 8]),
        ))
    }
    fn count(&mut self, item_bytes: usize) -> Result<usize, StoreError> {
        let n = self.u64()? as usize;
        if n.saturating_mul(item_bytes) > self.bytes.len() {
            return Err(self.bad("count beyond the data"));
        }
        Ok(n)
    }
    fn f64(&mut self) -> Result<f64, StoreError> {
        Ok(f64::from_bits(self.u64()?))
    }
    fn f64s(&mut self, n: usize) -> Result<Vec<f64>, StoreError> {
        let raw = self.take(n * 8)?;
        Ok(raw
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap_or([0; 8])))
            .collect())
    }
    fn points(&mut self) -> Result<Vec<Point3>, StoreError> {
        let n = self.count(24)?;
        let v = self.f64s(3 * n)?;
        Ok(v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
    }
    fn u32s(&mut self) -> Result<Vec<u32>, StoreError> {
        let n = self.count(4)?;
        let raw = self.take(n * 4)?;
        Ok(raw
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().unwrap_or([0; 4])))
            .collect())
    }
    fn end(self) -> Result<(), StoreError> {
        if self.bytes.is_empty() {
            Ok(())
        } else {
            Err(self.bad("trailing bytes"))
        }
    }
}

impl PointSet {
    pub(crate) fn encode(&self) -> Vec<u8> {
        let mut e = Enc::default().tag(b"PTS1");
        e.u64(self.ids.len() as u64);
        for id in &self.ids {
            e.0.extend_from_slice(&id.to_le_bytes());
        }
        e.points(&self.points);
        e.u64(self.normals.is_some() as u64);
        if let Some(n) = &self.normals {
            e.points(n);
        }
        e.0
    }

    pub(crate) fn decode(bytes: &[u8], key: &str) -> Result<PointSet, StoreError> {
        let mut d = Dec::new(bytes, key, b"PTS1")?;
        let ids = d.u32s()?;
        let points = d.points()?;
        let normals = if d.u64()? == 1 {
            Some(d.points()?)
        } else {
            None
        };
        if points.len() != ids.len() || normals.as_ref().is_some_and(|n| n.len() != ids.len()) {
            return Err(d.bad("lengths differ"));
        }
        d.end()?;
        Ok(PointSet {
            ids,
            points,
            normals,
        })
    }
}

impl SplineData {
    pub(crate) fn encode(&self) -> Vec<u8> {
        let mut e = Enc::default().tag(b"SPL1");
        e.u64(self.levels.len() as u64);
        for l in &self.levels {
            e.f64s([l.support]);
            e.points(&l.centres);
            e.f64s(l.weights.iter().copied());
        }
        e.u64(self.polynomial.is_some() as u64);
        e.f64s(self.polynomial.unwrap_or_default());
        e.0
    }

    pub(crate) fn decode(bytes: &[u8], key: &str) -> Result<SplineData, StoreError> {
        let mut d = Dec::new(bytes, key, b"SPL1")?;
        let n = d.count(16)?;
        let mut levels = Vec::with_capacity(n);
        for _ in 0..n {
            let support = d.f64()?;
            let centres = d.points()?;
            let weights = d.f64s(centres.len())?;
            levels.push(LevelData {
                centres,
                weights,
                support,
            });
        }
        let has_poly = d.u64()? == 1;
        let p = d.f64s(4)?;
        d.end()?;
        Ok(SplineData {
            levels,
            polynomial: has_poly.then(|| [p[0], p[1], p[2], p[3]]),
        })
    }
}

/// Encodes a mesh piece (positions, normals, triangles).
pub(crate) fn encode_piece(mesh: &TriMesh) -> Vec<u8> {
    let mut e = Enc::default().tag(b"PCE1");
    e.points(&mesh.vertices);
    e.points(&mesh.normals);
    e.u64(mesh.triangles.len() as u64);
    for t in &mesh.triangles {
        for v in t {
            e.0.extend_from_slice(&v.to_le_bytes());
        }
    }
    e.0
}

/// Decodes [`encode_piece`].
pub(crate) fn decode_piece(bytes: &[u8], key: &str) -> Result<TriMesh, StoreError> {
    let mut d = Dec::new(bytes, key, b"PCE1")?;
    let vertices = d.points()?;
    let normals = d.points()?;
    let n = d.count(12)?;
    let raw = d.take(n * 12)?;
    let triangles: Vec<[u32; 3]> = raw
        .chunks_exact(12)
        .map(|c| {
            let v = |k: usize| u32::from_le_bytes(c[4 * k..4 * k + 4].try_into().unwrap_or([0; 4]));
            [v(0), v(1), v(2)]
        })
        .collect();
    let nv = vertices.len() as u32;
    if triangles.iter().flatten().any(|&v| v >= nv) {
        return Err(d.bad("triangle index out of range"));
    }
    d.end()?;
    Ok(TriMesh {
        vertices,
        normals,
        triangles,
        colors: Vec::new(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_round_trip_in_both_stores_and_damage_is_an_error() {
        let set = PointSet {
            ids: vec![3, 7, 9],
            points: vec![[0.1, 0.2, 0.3], [1.0, -2.0, 3.5], [1e-300, 0.0, -0.0]],
            normals: Some(vec![[0.0, 0.0, 1.0]; 3]),
        };
        let spline = SplineData {
            levels: vec![LevelData {
                centres: vec![[0.5; 3]],
                weights: vec![-0.25],
                support: 0.01,
            }],
            polynomial: Some([1.0, 2.0, 3.0, 4.0]),
        };
        for kind in [StoreKind::Memory, StoreKind::TempDir(None)] {
            let s = Store::open(&kind).unwrap();
            s.put("points/0", set.encode()).unwrap();
            s.put("spline/0", spline.encode()).unwrap();
            let back = PointSet::decode(&s.get("points/0").unwrap(), "points/0").unwrap();
            assert_eq!(back, set);
            let back = SplineData::decode(&s.get("spline/0").unwrap(), "spline/0").unwrap();
            assert_eq!(back, spline);
            s.remove("points/0");
            assert!(s.get("points/0").is_err());
        }
        let bytes = set.encode();
        for cut in [0, 3, 10, bytes.len() - 1] {
            assert!(PointSet::decode(&bytes[..cut], "k").is_err(), "cut {cut}");
        }
        assert!(SplineData::decode(&bytes, "k").is_err(), "wrong tag");
    }
}
