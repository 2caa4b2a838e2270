//! Long-running fuzz soak of the point-file parsers (ignored by default; run with
//! `SOAK_ITERS=1000000 cargo test --test library parser_soak -- --ignored --nocapture`): seeded random
//! mutations (byte flips, insertions, deletions, truncation, splices of header keywords) of valid
//! PLY (ascii + binary), XYZ, CSV, PTS and OBJ inputs, plus pure random bytes, through
//! `parse_point_cloud` with small limits. Any panic fails; the counts of accepted/refused inputs
//! are printed. Complements the proptest stand-in in src/io/fuzz_tests.rs (128 cases per run).

use rbfsurf::io::{PointFormat, ReadLimits, parse_point_cloud};

struct Xs(u64);
impl Xs {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

fn seeds() -> Vec<(Vec<u8>, PointFormat)> {
    let mut bin = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nend_header\n".to_vec();
    for i in 0..18 {
        bin.extend_from_slice(&(i as f32 * 0.25).to_le_bytes());
    }
    vec![
        (bin, PointFormat::Ply),
        (b"ply\nformat ascii 1.0\ncomment c\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n".to_vec(), PointFormat::Ply),
        (b"0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n1e3 -2.5e-3 7 1 0 0\n".to_vec(), PointFormat::Xyz),
        (b"x,y,z,nx,ny,nz\n1,2,3,0,0,1\n4,5,6,0,1,0\n".to_vec(), PointFormat::Csv),
        (b"3\n0 0 0 10 20 30\n1 0 0 1 2 3\n0 1 0 4 5 6\n".to_vec(), PointFormat::Pts),
        (b"# obj\nv 0 0 0\nv 1 0 0\nvn 0 0 1\nvn 0 0 1\nf 1 2 1\n".to_vec(), PointFormat::Obj),
    ]
}

const TOKENS: [&[u8]; 10] = [
    b"element vertex 4294967295\n",
    b"property list uchar float x\n",
    b"format binary_big_endian 1.0\n",
    b"end_header\n",
    b"nan",
    b"-inf",
    b"1e308",
    b"\0",
    b"\r\n",
    b"element vertex 18446744073709551615\n",
];

fn mutate(r: &mut Xs, mut b: Vec<u8>) -> Vec<u8> {
    for _ in 0..1 + r.below(6) {
        match r.below(5) {
            0 if !b.is_empty() => {
                let i = r.below(b.len());
                b[i] = r.next() as u8;
            }
            1 => {
                let i = r.below(b.len() + 1);
                b.insert(i, r.next() as u8);
            }
            2 if !b.is_empty() => {
                let i = r.below(b.len());
                b.remove(i);
            }
            3 => b.truncate(r.below(b.len() + 1)),
            _ => {
                let i = r.below(b.len() + 1);
                let t = TOKENS[r.below(TOKENS.len())];
                b.splice(i..i, t.iter().copied());
            }
        }
    }
    b
}

#[test]
#[ignore = "soak: run explicitly"]
fn parsers_survive_a_long_mutation_soak() {
    let iters: usize = std::env::var("SOAK_ITERS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(200_000);
    let limits = ReadLimits {
        max_points: 10_000,
        max_bytes: 1 << 20,
        ..ReadLimits::default()
    };
    let formats = [
        PointFormat::Ply,
        PointFormat::Xyz,
        PointFormat::Csv,
        PointFormat::Pts,
        PointFormat::Obj,
    ];
    let seeds = seeds();
    let mut r = Xs(0x853c_49e6_748f_ea9b);
    let (mut ok, mut refused) = (0usize, 0usize);
    let start = std::time::Instant::now();
    for i in 0..iters {
        let (input, fmt) = if i % 10 == 0 {
            let n = r.below(600);
            (
                (0..n).map(|_| r.next() as u8).collect(),
                formats[r.below(formats.len())],
            )
        } else {
            let (s, f) = &seeds[r.below(seeds.len())];
            let f = if r.below(8) == 0 {
                formats[r.below(formats.len())]
            } else {
                *f
            };
            (mutate(&mut r, s.clone()), f)
        };
        let res = std::panic::catch_unwind(|| parse_point_cloud(&input, fmt, &limits));
        match res {
            Ok(Ok(pc)) => {
                assert!(pc.points.len() <= limits.max_points);
                if let Some(n) = &pc.normals {
                    assert_eq!(n.len(), pc.points.len());
                }
                ok += 1
            }
            Ok(Err(e)) => {
                assert!(!e.to_string().is_empty());
                refused += 1
            }
            Err(_) => panic!(
                "iteration {i}: parser panicked on {fmt:?} input {:?}",
                String::from_utf8_lossy(&input)
            ),
        }
    }
    println!(
        "soak: {iters} inputs in {:.1} s: {ok} parsed, {refused} refused with an error, 0 panics",
        start.elapsed().as_secs_f64()
    );
}
