//! Variational implicits benchmarks: Turk–O'Brien on Koch K4 (Mann: 143 s in Octave),
//! Shen's four MLS variants on the square at 101×101 (Mann Table 1: 8/11/29/38 s), and incremental
//! constraint addition vs a fresh solve at N = 2000.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use rbfsurf::polygonize::marching_squares::{Grid2, MarchingParams, contour};
use rbfsurf::variational::workbench::{contour_field, fit_curve, grid_for};
use rbfsurf::variational::{
    CurveMethod, CurveParams, ImplicitField, IncrementalSystem, Offset, Origin, RadialKernel,
    TurkObrienParams, ValueConstraint, datasets, fit_turk_obrien,
};

fn turk_obrien_k4(c: &mut Criterion) {
    let s = datasets::koch(4);
    let grid = grid_for(
        &s,
        &CurveParams {
            grid: 200,
            ..Default::default()
        },
    )
    .unwrap();
    let t0 = std::time::Instant::now();
    let fit = fit_turk_obrien(&s, &TurkObrienParams::default()).unwrap();
    let t1 = std::time::Instant::now();
    let a = rbfsurf::variational::adaptive::sample_grid_adaptive(&fit, &grid, 16, 2);
    let t2 = std::time::Instant::now();
    let lines = contour_field(&fit, &grid);
    eprintln!(
        "K4 one run: fit {:.1} ms, adaptive sampling {:.1} ms ({} of {} nodes evaluated, {} tests), \
         sampling + contour {:.1} ms, {} polylines",
        (t1 - t0).as_secs_f64() * 1e3,
        (t2 - t1).as_secs_f64() * 1e3,
        a.evaluated,
        (grid.nx + 1) * (grid.ny + 1),
        a.tests,
        t2.elapsed().as_secs_f64() * 1e3,
        lines.len()
    );
    eprintln!(
        "K4: {} unknowns, rcond {:.2e}, grid {}x{}",
        fit.info.unknowns, fit.info.rcond, grid.nx, grid.ny
    );
    let mut g = c.benchmark_group("turk_obrien_k4");
    g.sample_size(10);
    g.bench_function("fit", |b| {
        b.iter(|| fit_turk_obrien(black_box(&s), &TurkObrienParams::default()).unwrap())
    });
    g.bench_function("fit+contour200", |b| {
        b.iter(|| {
            let fit = fit_turk_obrien(black_box(&s), &TurkObrienParams::default()).unwrap();
            contour(
                &|x: &[f64; 2]| fit.value(x),
                &grid,
                &MarchingParams::default(),
            )
        })
    });
    g.bench_function("fit+contour200_adaptive", |b| {
        b.iter(|| {
            let fit = fit_turk_obrien(black_box(&s), &TurkObrienParams::default()).unwrap();
            contour_field(&fit, &grid)
        })
    });
    g.finish();
}

fn shen_square(c: &mut Criterion) {
    let s = datasets::square();
    let grid = Grid2 {
        min: [-3.0, -3.0],
        max: [3.0, 3.0],
        nx: 100,
        ny: 100,
    };
    let mut g = c.benchmark_group("shen_square_101");
    for m in [
        CurveMethod::ShenConstant,
        CurveMethod::ShenConstantNormals,
        CurveMethod::ShenLinear,
        CurveMethod::ShenLinearNormals,
    ] {
        let p = CurveParams {
            method: m,
            offset: Offset::Normalized(0.05),
            ..Default::default()
        };
        g.bench_function(format!("{m:?}"), |b| {
            b.iter(|| {
                let f = fit_curve(black_box(&s), &p).unwrap().field;
                contour_field(f.as_ref(), &grid)
            })
        });
    }
    g.finish();
}

fn rng(s: &mut u64) -> f64 {
    *s = s.wrapping_add(0x9E3779B97F4A7C15);
    let mut z = *s;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58476D1CE4E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D049BB133111EB);
    (z ^ (z >> 31)) as f64 / u64::MAX as f64
}

fn random(n: usize, seed: u64, row0: usize) -> Vec<ValueConstraint<2>> {
    let mut s = seed;
    (0..n)
        .map(|k| ValueConstraint {
            p: [rng(&mut s) - 0.5, rng(&mut s) - 0.5],
            value: rng(&mut s) - 0.5,
            origin: Origin::Sample(row0 + k),
        })
        .collect()
}

fn incremental(c: &mut Criterion) {
    let n = 2000;
    let base = random(n, 1, 0);
    let sys = IncrementalSystem::new(&base, RadialKernel::ThinPlate).unwrap();
    let mut g = c.benchmark_group("incremental_n2000");
    g.sample_size(10);
    for m in [1usize, 10, 100] {
        let add = random(m, 2, n);
        let all: Vec<_> = base.iter().chain(&add).copied().collect();
        let mut inc = sys.clone();
        inc.add(&add).unwrap();
        let fresh = IncrementalSystem::new(&all, RadialKernel::ThinPlate)
            .unwrap()
            .expansion();
        let e = inc.expansion();
        let scale = fresh
            .alpha
            .iter()
            .chain(&fresh.poly)
            .map(|v| v.abs())
            .fold(0.0, f64::max);
        let diff = e
            .alpha
            .iter()
            .chain(&e.poly)
            .zip(fresh.alpha.iter().chain(&fresh.poly))
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "M={m}: max relative coefficient difference vs fresh solve {:.2e}",
            diff / scale
        );
        g.bench_function(format!("add_{m}"), |b| {
            b.iter_batched(
                || sys.clone(),
                |mut s| s.add(black_box(&add)).unwrap(),
                criterion::BatchSize::LargeInput,
            )
        });
        g.bench_function(format!("fresh_{}", n + m), |b| {
            b.iter(|| IncrementalSystem::new(black_box(&all), RadialKernel::ThinPlate).unwrap())
        });
    }
    g.finish();
}

criterion_group!(benches, turk_obrien_k4, shen_square, incremental);
criterion_main!(benches);
