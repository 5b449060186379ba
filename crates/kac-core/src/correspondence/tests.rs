use super::fit::fit;
use super::nearest::scan_tile;
use super::orientation::outward_sign;
use super::*;
use crate::geometry::generate;
use crate::geometry::TriangleMesh;
use crate::operators::{self, OperatorOptions};
use crate::spectrum::{self, Control, EigenOptions, Spectrum};
use crate::Shape;

/// A permutation of 0..n from a fixed seed (a linear congruential shuffle: reproducible, no dependency).
fn permutation(n: usize, seed: u64) -> Vec<u32> {
    let mut p: Vec<u32> = (0..n as u32).collect();
    let mut s = seed;
    for i in (1..n).rev() {
        s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        let j = (s >> 33) as usize % (i + 1);
        p.swap(i, j);
    }
    p
}

/// The copy of `m` whose vertex y is `m`'s vertex perm[y], moved by `motion`.
fn shuffled(m: &TriangleMesh, perm: &[u32], motion: impl Fn([f64; 3]) -> [f64; 3]) -> TriangleMesh {
    let mut inverse = vec![0u32; perm.len()];
    for (y, &x) in perm.iter().enumerate() {
        inverse[x as usize] = y as u32;
    }
    let mut out = m.clone();
    out.vertices = perm.iter().map(|&x| motion(m.vertices[x as usize])).collect();
    out.faces = m.faces.iter().map(|f| f.map(|v| inverse[v as usize])).collect();
    out
}

/// A lumpy sphere with no symmetry.
fn lumpy(level: u32) -> TriangleMesh {
    let mut m = generate::icosphere(level);
    for p in &mut m.vertices {
        let [x, y, z] = *p;
        let r = 1.0 + 0.3 * x + 0.2 * y * y - 0.25 * z * z * z + 0.15 * x * y + 0.1 * (3.0 * z).sin();
        *p = [x * r, 1.3 * y * r, 0.8 * z * r];
    }
    m
}

fn spectrum_of(m: &TriangleMesh, k: usize) -> (operators::Operator, Spectrum) {
    let op = operators::build(&Shape::TriangleMesh(m.clone()), &OperatorOptions::default()).unwrap();
    let s = spectrum::eigs(&op.pair, &EigenOptions { k, ..Default::default() }, None, Control::default()).unwrap();
    (op, s)
}

fn run(a: &TriangleMesh, b: &TriangleMesh, k: usize, o: &CorrespondenceOptions) -> Correspondence {
    let (oa, sa) = spectrum_of(a, k);
    let (ob, sb) = spectrum_of(b, k);
    let s = SpectralShape { basis: Basis::of(&sa, &oa.pair), pair: &oa.pair, surface: Some(a) };
    let t = SpectralShape { basis: Basis::of(&sb, &ob.pair), pair: &ob.pair, surface: Some(b) };
    correspond(&s, &t, o, &Control::default()).unwrap()
}

fn area(m: &TriangleMesh) -> f64 {
    m.faces
        .iter()
        .map(|f| {
            let [a, b, c] = f.map(|v| m.vertices[v as usize]);
            let (u, v) = ([b[0] - a[0], b[1] - a[1], b[2] - a[2]], [c[0] - a[0], c[1] - a[1], c[2] - a[2]]);
            let n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
            0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
        })
        .sum()
}

/// The mean geodesic distance (heat method on the source) between each sampled target vertex's match and its
/// true match, over √area.
fn geodesic_error(src: &TriangleMesh, found: &[u32], truth: &[u32], samples: usize) -> f64 {
    let step = (truth.len() / samples).max(1);
    let mut total = 0.0;
    let mut count = 0;
    for y in (0..truth.len()).step_by(step) {
        let (a, b) = (truth[y] as usize, found[y] as usize);
        if a != b {
            let g = crate::pde::geodesic::heat_method(src, &[a], &Default::default()).unwrap();
            total += g.distance[b];
        }
        count += 1;
    }
    total / count as f64 / area(src).sqrt()
}

/// A rigidly moved copy with its vertices shuffled: the answer is the permutation, both ways.
#[test]
fn a_shuffled_rigid_copy_is_matched_by_its_permutation() {
    let a = lumpy(3);
    let perm = permutation(a.vertices.len(), 7);
    let (c, s) = (0.6f64.cos(), 0.6f64.sin());
    let b = shuffled(&a, &perm, |[x, y, z]| [c * x - s * y + 3.0, s * x + c * y - 1.0, z + 0.5]);
    let o = CorrespondenceOptions { fit_k: 20, refine_k: 60, ..Default::default() };
    let r = run(&a, &b, 60, &o);
    let exact = r.target_to_source.iter().zip(&perm).filter(|(f, t)| f == t).count();
    let fraction = exact as f64 / perm.len() as f64;
    let err = geodesic_error(&a, &r.target_to_source, &perm, 60);
    eprintln!("rigid copy: {fraction} exact, mean geodesic error {err:.5}");
    assert!(fraction > 0.97 && err < 0.005, "{fraction} exact, mean geodesic error {err}");
    let back = r.source_to_target.iter().enumerate().filter(|(x, &y)| perm[y as usize] as usize == *x).count();
    assert!(back as f64 / perm.len() as f64 > 0.97, "{back} of {} matched back", perm.len());
    assert_eq!(r.sizes.first().copied(), Some(20));
    assert_eq!(r.sizes.last().copied(), Some(60));
    assert!(r.orthogonality_defect < 0.05, "C of an isometry is orthogonal: {}", r.orthogonality_defect);
}

/// A bend of an asymmetric flat domain (one of Gordon, Webb & Wolpert's drums) onto a cylinder: a near-isometry
/// (edges across the bend become chords), with its vertices shuffled.
#[test]
fn a_bent_drum_is_matched_within_a_small_geodesic_error() {
    let a = generate::gww_drum(1, 12);
    let perm = permutation(a.vertices.len(), 11);
    let r0 = 0.6;
    let b = shuffled(&a, &perm, |[x, y, _]| [r0 * (x / r0).sin(), y, r0 * (1.0 - (x / r0).cos())]);
    let r = run(&a, &b, 60, &CorrespondenceOptions { fit_k: 20, refine_k: 60, ..Default::default() });
    let err = geodesic_error(&a, &r.target_to_source, &perm, 60);
    eprintln!("bent drum: mean geodesic error {err:.4} (√area units)");
    assert!(err < 0.02, "mean geodesic error {err}");
}

/// A partial copy: the source with a cap cut off (its vertices beyond a plane, about a tenth of the area), the
/// remaining vertices shuffled, three pairs known. Each target vertex's true match is the vertex it was copied
/// from.
#[test]
fn a_partial_copy_is_matched_within_a_stated_geodesic_error() {
    let a = lumpy(3);
    let cut = 0.75 * a.vertices.iter().map(|p| p[0]).fold(f64::NEG_INFINITY, f64::max);
    let kept: Vec<u32> = (0..a.vertices.len() as u32).filter(|&v| a.vertices[v as usize][0] < cut).collect();
    let mut new_of = vec![u32::MAX; a.vertices.len()];
    for (i, &v) in kept.iter().enumerate() {
        new_of[v as usize] = i as u32;
    }
    let mut part = a.clone();
    part.vertices = kept.iter().map(|&v| a.vertices[v as usize]).collect();
    part.faces = a
        .faces
        .iter()
        .filter(|f| f.iter().all(|&v| new_of[v as usize] != u32::MAX))
        .map(|f| f.map(|v| new_of[v as usize]))
        .collect();
    let perm = permutation(part.vertices.len(), 13);
    let b = shuffled(&part, &perm, |p| p);
    let truth: Vec<u32> = perm.iter().map(|&i| kept[i as usize]).collect();
    // Three known pairs: WKS alone does not survive the cut (the cut's boundary changes every eigenfunction
    // near it; measured 0.39 without landmarks), three landmarks pin the map.
    let mut inverse = vec![0u32; perm.len()];
    for (y, &x) in perm.iter().enumerate() {
        inverse[x as usize] = y as u32;
    }
    let landmarks: Vec<(u32, u32)> = [0usize, 97, 194].iter().map(|&x| (kept[x], inverse[x])).collect();
    let o = CorrespondenceOptions { fit_k: 20, refine_k: 60, partial: true, landmarks, ..Default::default() };
    let r = run(&a, &b, 80, &o);
    let err = geodesic_error(&a, &r.target_to_source, &truth, 60);
    // Without the landmarks the map goes astray, and C's orthogonality defect says so: 0.47 against 0.22 for
    // the exact map (the service warns above 0.35: `correspondence-not-isometric`).
    let astray = run(&a, &b, 80, &CorrespondenceOptions { landmarks: vec![], ..o.clone() });
    let err_astray = geodesic_error(&a, &astray.target_to_source, &truth, 60);
    assert!(err_astray > 0.2, "without landmarks: {err_astray}");
    assert!(
        r.orthogonality_defect < 0.3 && astray.orthogonality_defect > 0.4,
        "{} {}",
        r.orthogonality_defect,
        astray.orthogonality_defect
    );
    eprintln!("partial copy ({} of {} vertices): mean geodesic error {err:.4}", kept.len(), a.vertices.len());
    assert!(err < 0.01, "mean geodesic error {err}");
}

/// The refinement improves on the fit alone, and a stop ends it.
#[test]
fn zoomout_improves_the_fit_and_a_stop_ends_it() {
    let a = generate::gww_drum(2, 12);
    let perm = permutation(a.vertices.len(), 5);
    // A strong near-isometry: a tight bend, and a 15 % stretch growing across the drum.
    let r0 = 0.5;
    let b = shuffled(&a, &perm, |[x, y, _]| {
        let y = y * (1.0 + 0.15 * x / 3.0);
        [x, r0 * (y / r0).sin(), r0 * (1.0 - (y / r0).cos())]
    });
    eprintln!("{} vertices", a.vertices.len());
    let fitted = run(&a, &b, 80, &CorrespondenceOptions { fit_k: 10, refine_k: 10, ..Default::default() });
    let refined = run(&a, &b, 80, &CorrespondenceOptions { fit_k: 10, refine_k: 80, ..Default::default() });
    let (e0, e1) = (
        geodesic_error(&a, &fitted.target_to_source, &perm, 60),
        geodesic_error(&a, &refined.target_to_source, &perm, 60),
    );
    // ZoomOut's steps on a sample of 300 vertices per shape (the final maps over every vertex).
    let sampled = CorrespondenceOptions { fit_k: 10, refine_k: 80, refine_samples: 300, ..Default::default() };
    let e2 = geodesic_error(&a, &run(&a, &b, 80, &sampled).target_to_source, &perm, 60);
    eprintln!("fit alone {e0:.4}, refined {e1:.4}, refined on samples {e2:.4}");
    assert!(e1 < 0.5 * e0 && e1 < 0.02, "fit {e0}, refined {e1}");
    assert!(e2 < e0 && e2 < 0.02, "fit {e0}, refined on samples {e2}");
    let (oa, sa) = spectrum_of(&a, 30);
    let s = SpectralShape { basis: Basis::of(&sa, &oa.pair), pair: &oa.pair, surface: Some(&a) };
    let stop = std::sync::atomic::AtomicBool::new(true);
    let stopped = Control { stop: Some(&stop), ..Control::default() };
    let r = correspond(&s, &s, &CorrespondenceOptions { fit_k: 10, refine_k: 30, ..Default::default() }, &stopped);
    assert!(matches!(r, Err(CorrespondenceError::Stopped(_))));
}

/// The fit's normal equations against the energy written term by term: for small random A, B, eigenvalues and
/// non-symmetric operators, the solution of fit() has zero gradient of E(C) = w_d‖CA − B‖² + w_l Σ D_ij C_ij²
/// + w_c Σ_f ‖C X_f − Y_f C‖² (checked by central differences of E, entry by entry).
#[test]
fn the_fit_solves_its_energy() {
    let (kt, ks, q) = (3usize, 4usize, 5usize);
    let r = |i: usize| ((i * 7919 + 13) % 101) as f64 / 50.0 - 1.0;
    let a = Mat::from_fn(ks, q, |i, j| r(i * 31 + j));
    let b = Mat::from_fn(kt, q, |i, j| r(i * 17 + j + 500));
    let ls: Vec<f64> = (0..ks).map(|i| i as f64 * 1.3).collect();
    let lt: Vec<f64> = (0..kt).map(|i| i as f64 * 1.1 + 0.2).collect();
    let ops: Vec<(Mat<f64>, Mat<f64>, f64)> = (0..2)
        .map(|f| {
            (
                Mat::from_fn(ks, ks, |i, j| r(900 + f * 50 + i * 5 + j)),
                Mat::from_fn(kt, kt, |i, j| r(300 + f * 40 + i * 3 + j)),
                0.7,
            )
        })
        .collect();
    let o = CorrespondenceOptions {
        descriptor_weight: 1.0,
        laplacian_weight: 0.3,
        commutativity_weight: 0.7,
        ..Default::default()
    };
    let c = fit(&a, &b, &ls, &lt, &ops, &o).unwrap();
    let mut d = Mat::from_fn(kt, ks, |i, j| (lt[i] - ls[j]).powi(2));
    let norm = d.norm_l2();
    d = Mat::from_fn(kt, ks, |i, j| d[(i, j)] / norm);
    let energy = |c: &Mat<f64>| {
        let mut e = 0.0;
        let mut ca = Mat::zeros(kt, q);
        matmul(ca.as_mut(), Accum::Replace, c.as_ref(), a.as_ref(), 1.0, Par::Seq);
        e += o.descriptor_weight
            * (0..kt)
                .flat_map(|i| (0..q).map(move |j| (i, j)))
                .map(|(i, j)| (ca[(i, j)] - b[(i, j)]).powi(2))
                .sum::<f64>();
        e += o.laplacian_weight
            * (0..kt)
                .flat_map(|i| (0..ks).map(move |j| (i, j)))
                .map(|(i, j)| d[(i, j)] * c[(i, j)].powi(2))
                .sum::<f64>();
        for (x, y, w) in &ops {
            let mut cx = Mat::zeros(kt, ks);
            matmul(cx.as_mut(), Accum::Replace, c.as_ref(), x.as_ref(), 1.0, Par::Seq);
            matmul(cx.as_mut(), Accum::Add, y.as_ref(), c.as_ref(), -1.0, Par::Seq);
            e += w * cx.norm_l2().powi(2);
        }
        e
    };
    let h = 1e-6;
    for i in 0..kt {
        for j in 0..ks {
            let (mut up, mut down) = (c.clone(), c.clone());
            up[(i, j)] += h;
            down[(i, j)] -= h;
            let g = (energy(&up) - energy(&down)) / (2.0 * h);
            assert!(g.abs() < 1e-6, "∂E/∂C[{i},{j}] = {g}");
        }
    }
}

/// A function carried by C to a rotated shuffled copy is the function at the permutation, up to what lies above
/// the basis (the x coordinate of a smooth shape: within 2 % in 60 eigenfunctions).
#[test]
fn a_function_travels_by_the_map() {
    let a = lumpy(3);
    let perm = permutation(a.vertices.len(), 7);
    let b = shuffled(&a, &perm, |[x, y, z]| [-y, x, z]);
    let (oa, sa) = spectrum_of(&a, 60);
    let (ob, sb) = spectrum_of(&b, 60);
    let s = SpectralShape { basis: Basis::of(&sa, &oa.pair), pair: &oa.pair, surface: Some(&a) };
    let t = SpectralShape { basis: Basis::of(&sb, &ob.pair), pair: &ob.pair, surface: Some(&b) };
    let r = correspond(
        &s,
        &t,
        &CorrespondenceOptions { fit_k: 20, refine_k: 60, ..Default::default() },
        &Control::default(),
    )
    .unwrap();
    let f: Vec<f64> = a.vertices.iter().map(|p| p[0]).collect();
    let g = transfer_function(&s, &t, &r.c, &f);
    let want: Vec<f64> = perm.iter().map(|&x| f[x as usize]).collect();
    let err = g.iter().zip(&want).map(|(u, v)| (u - v).powi(2)).sum::<f64>().sqrt();
    let norm = want.iter().map(|v| v * v).sum::<f64>().sqrt();
    assert!(err < 0.02 * norm, "relative error {}", err / norm);
}

/// A shape with a mirror symmetry (x → −x: an icosphere made lumpy by a function even in x) against a rotated,
/// shuffled copy: the mirror map is an isometry too, which WKS probes, Laplacian and descriptor commutativity
/// cannot tell from the true map. The orientation term can: with it the map is the true one (no flip); the
/// mirror map turns orientation, so its orientation operators anticommute, and the fit's energy says so.
#[test]
fn the_orientation_term_keeps_a_symmetric_shape_from_flipping() {
    let a = symmetric_lumpy();
    orientation_keeps_the_map(&a, &mirror_of(&a));
}

/// The same with holes (two faces and their mirror images cut out, as a scan's holes at a cat's paws): the
/// surface still encloses a volume by [`outward_sign`], so the term still applies and still holds the map.
#[test]
fn the_orientation_term_holds_on_a_surface_with_small_holes() {
    let mut a = symmetric_lumpy();
    let mirror = mirror_of(&a);
    let key = |f: &[u32; 3]| {
        let mut k = *f;
        k.sort_unstable();
        k
    };
    let mut cut = vec![];
    for start in [0, a.faces.len() / 2] {
        let f = a.faces[start];
        let image = key(&f.map(|v| mirror[v as usize]));
        let g = a.faces.iter().position(|h| key(h) == image).expect("the mirror image of a face is a face");
        cut.extend([start, g]);
    }
    cut.sort_unstable();
    cut.dedup();
    assert_eq!(cut.len(), 4, "two faces and their images, none its own");
    for &f in cut.iter().rev() {
        a.faces.remove(f);
    }
    assert!(outward_sign(&a).is_some(), "small holes still enclose");
    orientation_keeps_the_map(&a, &mirror);
}

/// Which surfaces enclose a volume, and which way they are wound.
#[test]
fn outward_sign_tells_enclosing_surfaces_and_their_winding() {
    let sphere = lumpy(2);
    assert_eq!(outward_sign(&sphere), Some(1.0));
    let mut inside_out = sphere.clone();
    inside_out.faces.iter_mut().for_each(|f| f.swap(1, 2));
    assert_eq!(outward_sign(&inside_out), Some(-1.0));
    let mut holed = sphere.clone();
    holed.faces.truncate(holed.faces.len() - 3);
    assert_eq!(outward_sign(&holed), Some(1.0), "a few faces missing");
    // A hemisphere and a flat drum have no outward side.
    let mut half = sphere.clone();
    half.faces.retain(|f| f.iter().all(|&v| half_z(&sphere, v)));
    assert_eq!(outward_sign(&half), None);
    assert_eq!(outward_sign(&generate::gww_drum(1, 6)), None);
}

fn half_z(m: &TriangleMesh, v: u32) -> bool {
    m.vertices[v as usize][2] >= 0.0
}

/// A lumpy sphere with a mirror symmetry, x → −x.
fn symmetric_lumpy() -> TriangleMesh {
    let mut a = generate::icosphere(3);
    for p in &mut a.vertices {
        let [x, y, z] = *p;
        let r = 1.0 + 0.3 * y + 0.2 * x * x - 0.25 * z * z * z + 0.1 * (3.0 * z).sin();
        *p = [x * r, 1.3 * y * r, 0.8 * z * r];
    }
    a
}

/// The mirror image of each vertex (the icosphere's vertices are symmetric under x → −x).
fn mirror_of(a: &TriangleMesh) -> Vec<u32> {
    let mirror: Vec<u32> = a
        .vertices
        .iter()
        .map(|&[x, y, z]| {
            let d = |q: &[f64; 3]| (q[0] + x).powi(2) + (q[1] - y).powi(2) + (q[2] - z).powi(2);
            (0..a.vertices.len()).min_by(|&i, &j| d(&a.vertices[i]).total_cmp(&d(&a.vertices[j]))).unwrap() as u32
        })
        .collect();
    let moved = (0..a.vertices.len()).filter(|&v| mirror[v] as usize != v).count();
    assert!(moved > a.vertices.len() / 2, "the mirror moves most vertices");
    for (v, &m) in mirror.iter().enumerate() {
        let (p, q) = (a.vertices[v], a.vertices[m as usize]);
        assert!((p[0] + q[0]).abs() + (p[1] - q[1]).abs() + (p[2] - q[2]).abs() < 1e-9, "an exact mirror");
    }
    mirror
}

/// Against a rotated shuffled copy: with the orientation term the true map, away from the mirror map.
fn orientation_keeps_the_map(a: &TriangleMesh, mirror: &[u32]) {
    let perm = permutation(a.vertices.len(), 17);
    let b = shuffled(a, &perm, |[x, y, z]| [-y, x, z + 1.0]);
    let truth_flipped: Vec<u32> = perm.iter().map(|&x| mirror[x as usize]).collect();
    let base = CorrespondenceOptions { fit_k: 20, refine_k: 60, ..Default::default() };
    let with = run(a, &b, 80, &base);
    let without = run(a, &b, 80, &CorrespondenceOptions { orientation_weight: 0.0, ..base.clone() });
    let err = |r: &Correspondence, truth: &[u32]| geodesic_error(a, &r.target_to_source, truth, 60);
    let (w, wf) = (err(&with, &perm), err(&with, &truth_flipped));
    let (o, of) = (err(&without, &perm), err(&without, &truth_flipped));
    eprintln!("with orientation: {w:.4} (mirror {wf:.4}); without: {o:.4} (mirror {of:.4})");
    assert!(w < 0.02 && wf > 0.1, "with the orientation term: error {w}, against the mirror {wf}");
    assert!(w <= o, "the orientation term does not make the map worse: {w} against {o}");
}

/// The nearest rows against every distance (f64): each query's chosen row within single-precision rounding of
/// the nearest, its distance the chosen row's; across tiles (n past 1,024) and blocks (q not a multiple of 64).
#[test]
fn nearest_rows_finds_the_nearest() {
    let r = |i: usize| ((i.wrapping_mul(2654435761) >> 7) % 10_007) as f64 / 5003.5 - 1.0;
    let (n, q, d) = (2_500, 130, 37);
    let data = Mat::from_fn(n, d, |i, j| r(i * d + j));
    let query = Mat::from_fn(q, d, |i, j| r(900_001 + i * d + j) * 0.9);
    let (idx, dist) = nearest_rows(data.as_ref(), query.as_ref());
    let dist_to = |a: usize, b: usize| (0..d).map(|j| (query[(a, j)] - data[(b, j)]).powi(2)).sum::<f64>().sqrt();
    let mut exact = 0;
    for a in 0..q {
        let best = (0..n).map(|b| dist_to(a, b)).fold(f64::INFINITY, f64::min);
        let chosen = dist_to(a, idx[a] as usize);
        assert!(chosen * chosen - best * best <= 1e-5 * d as f64, "query {a}: {chosen} against {best}");
        assert!((dist[a] - chosen).abs() <= 1e-12 * chosen.max(1.0), "the chosen row's distance");
        exact += usize::from(chosen == best);
    }
    assert!(exact * 100 >= q * 95, "{exact} of {q} exactly the nearest (the rest within rounding)");
}

/// The scan of a tile is the same on every instruction set this CPU has.
#[test]
fn the_tile_scan_is_the_same_on_every_instruction_set() {
    let (rows, cols) = (37, 300);
    let g: Vec<f32> = (0..rows * cols).map(|i| ((i * 7919) % 1009) as f32 / 1009.0).collect();
    let dn: Vec<f32> = (0..cols).map(|i| ((i * 104_729) % 997) as f32 / 997.0).collect();
    let mut results = vec![];
    for isa in crate::simd::Isa::available() {
        let (mut bd, mut local) = (vec![0.5f32; rows], vec![-1.0f32; rows]);
        bd[3] = f32::INFINITY;
        scan_tile(isa, &g, &dn, &mut bd, &mut local);
        assert!(local[3] >= 0.0, "a row with no bound finds one");
        results.push((isa, bd, local));
    }
    for (isa, bd, local) in &results[1..] {
        assert_eq!((bd, local), (&results[0].1, &results[0].2), "{isa:?} against {:?}", results[0].0);
    }
}

/// Bijective ZoomOut on the bent drum, on samples and on every vertex: the map stays as good, and the vertex maps
/// both ways agree at least as often (a source vertex carried to the target and back lands on itself).
#[test]
fn bijective_zoomout_keeps_the_two_maps_together() {
    let a = generate::gww_drum(1, 12);
    let perm = permutation(a.vertices.len(), 11);
    let r0 = 0.45;
    let b = shuffled(&a, &perm, |[x, y, _]| {
        let y = y * (1.0 + 0.15 * x / 3.0);
        [r0 * (x / r0).sin(), y, r0 * (1.0 - (x / r0).cos())]
    });
    let (oa, sa) = spectrum_of(&a, 60);
    let (ob, sb) = spectrum_of(&b, 60);
    let s = SpectralShape { basis: Basis::of(&sa, &oa.pair), pair: &oa.pair, surface: Some(&a) };
    let t = SpectralShape { basis: Basis::of(&sb, &ob.pair), pair: &ob.pair, surface: Some(&b) };
    let round_trips = |r: &Correspondence| {
        let back = (0..a.vertices.len()).filter(|&x| r.target_to_source[r.source_to_target[x] as usize] as usize == x);
        back.count() as f64 / a.vertices.len() as f64
    };
    for samples in [300, 0] {
        let o = CorrespondenceOptions { fit_k: 20, refine_k: 60, refine_samples: samples, ..Default::default() };
        let plain = correspond(&s, &t, &o, &Control::default()).unwrap();
        let both = correspond(&s, &t, &CorrespondenceOptions { bijective: true, ..o }, &Control::default()).unwrap();
        let (e0, e1) = (
            geodesic_error(&a, &plain.target_to_source, &perm, 60),
            geodesic_error(&a, &both.target_to_source, &perm, 60),
        );
        let (r0, r1) = (round_trips(&plain), round_trips(&both));
        eprintln!("samples {samples}: error {e0:.4} → {e1:.4} bijective; round trips {r0:.3} → {r1:.3}");
        assert!(e1 < 0.02 && e1 <= e0 + 0.002, "bijective error {e1} against {e0}");
        assert!(r1 >= r0 - 0.01, "round trips {r1} against {r0}");
    }
}

/// Parameters out of range are refused, naming the parameter.
#[test]
fn bad_parameters_are_refused() {
    let a = lumpy(2);
    let (oa, sa) = spectrum_of(&a, 20);
    let s = SpectralShape { basis: Basis::of(&sa, &oa.pair), pair: &oa.pair, surface: Some(&a) };
    let go = Control::default();
    // A coupled fit larger than the bound is refused before any allocation (the spectrum would allow it).
    let b = lumpy(3);
    let (ob, sb) = spectrum_of(&b, MAX_COUPLED_FIT_K + 1);
    let big = SpectralShape { basis: Basis::of(&sb, &ob.pair), pair: &ob.pair, surface: Some(&b) };
    let o = CorrespondenceOptions { fit_k: MAX_COUPLED_FIT_K + 1, ..Default::default() };
    assert!(matches!(correspond(&big, &big, &o, &go), Err(CorrespondenceError::Descriptor(_))));
    for o in [
        CorrespondenceOptions { fit_k: 1, ..Default::default() },
        CorrespondenceOptions { fit_k: 21, ..Default::default() },
        CorrespondenceOptions { landmarks: vec![(0, 9999)], fit_k: 10, ..Default::default() },
        CorrespondenceOptions { laplacian_weight: f64::NAN, fit_k: 10, ..Default::default() },
        CorrespondenceOptions { descriptors: MAX_DESCRIPTORS + 1, fit_k: 10, ..Default::default() },
        CorrespondenceOptions { bijective: true, partial: true, fit_k: 10, ..Default::default() },
    ] {
        assert!(matches!(correspond(&s, &s, &o, &go), Err(CorrespondenceError::Descriptor(_))), "{o:?}");
    }
}

/// Options that no pair of shapes could honour are refused by `check`, before any spectrum, each naming the
/// option it is about (a step of 0 was taken as 1 or named `descriptors`; a weight of 1e308 overflowed the fit's
/// system, refused as "singular: give more descriptors"; two pairs sharing a vertex were each taken).
#[test]
fn options_no_shapes_could_honour_are_refused_naming_the_option() {
    let named = |o: CorrespondenceOptions| match o.check() {
        Err(DescriptorError::InvalidParameter { name, message }) => (name, message),
        other => panic!("{o:?}: {other:?}"),
    };
    let d = CorrespondenceOptions::default;
    assert_eq!(named(CorrespondenceOptions { descriptor_step: 0, ..d() }).0, "descriptor_step");
    assert_eq!(named(CorrespondenceOptions { refine_step: 0, ..d() }).0, "refine_step");
    assert_eq!(named(CorrespondenceOptions { descriptors: 0, ..d() }).0, "descriptors");
    assert_eq!(named(CorrespondenceOptions { fit_k: 1, ..d() }).0, "fit_k");
    let (name, message) = named(CorrespondenceOptions { descriptor_weight: 1e308, ..d() });
    assert_eq!(name, "descriptor_weight");
    assert!(message.contains("[0, 1e6]"), "{message}");
    for w in [-1.0, f64::NAN, f64::INFINITY, MAX_WEIGHT * 2.0] {
        assert_eq!(named(CorrespondenceOptions { orientation_weight: w, ..d() }).0, "orientation_weight");
    }
    assert!(CorrespondenceOptions { descriptor_weight: MAX_WEIGHT, laplacian_weight: 0.0, ..d() }.check().is_ok());
    // A vertex paired twice, on either side; the same pair twice is one landmark.
    for landmarks in [vec![(0, 0), (0, 1)], vec![(0, 0), (1, 0)], vec![(3, 4), (5, 6), (5, 7)]] {
        let (name, message) = named(CorrespondenceOptions { landmarks: landmarks.clone(), ..d() });
        assert_eq!(name, "landmarks", "{landmarks:?}");
        assert!(message.contains("two vertices"), "{message}");
    }
    assert!(CorrespondenceOptions { landmarks: vec![(0, 0), (0, 0), (1, 1)], ..d() }.check().is_ok());
    let too_many = (0..=MAX_LANDMARKS as u32).map(|i| (i, i)).collect();
    assert_eq!(named(CorrespondenceOptions { landmarks: too_many, ..d() }).0, "landmarks");
}
