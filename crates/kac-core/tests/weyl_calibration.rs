//! Weyl's estimates calibrated: on shapes whose measures are known (surfaces and solids, Neumann and Dirichlet,
//! P1 and P2 elements, several resolutions and numbers of eigenvalues k), how often estimate ± 2 × uncertainty
//! covers the truth. The truth is the mesh's own measure (an icosphere's polyhedral area, not 4π) and, for the
//! boundary, the square's 4, the cube's 6 and the polygonal disk's perimeter; exact spectra (boxes, the sphere)
//! check the estimator alone. An estimate the eigenvalues do not resolve is omitted (`unresolved`): it counts as
//! neither covered nor missed, and the figures say how many there were and how often their numbers would have
//! covered. The figures and the method are in `docs/weyl.md`; the full set runs with `-- --ignored`.

mod common;

use kac_core::descriptors::shape_dna::Measures;
use kac_core::descriptors::weyl::{weyl_estimate, WeylEstimate};
use kac_core::descriptors::zero_threshold;
use kac_core::geometry::{generate, Shape, TriangleMesh};
use kac_core::operators::{self, Boundary, OperatorOptions};
use kac_core::spectrum::{eigs, Control, EigenOptions};
use std::collections::BTreeMap;
use std::f64::consts::PI;

/// A spectrum with the measures it should tell.
struct Case {
    name: String,
    /// "d2 closed P1", "d3 Neumann P2", "d2 Dirichlet exact", ...: the rows of the figures.
    class: String,
    measures: Measures,
    /// The boundary's measure (None for a closed surface).
    boundary: Option<f64>,
    zero_tol: f64,
    /// The operator's unknowns, for the analysis' mesh-resolution warning (None: an exact spectrum).
    unknowns: Option<usize>,
    eigenvalues: Vec<f64>,
}

fn mesh_area(m: &TriangleMesh) -> f64 {
    let norm = |a: [f64; 3]| (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    m.faces.iter().map(|f| 0.5 * norm(kac_core::geometry::topology::tri_area2(&m.vertices, f))).sum()
}

/// The `k` lowest eigenpairs (plus the zero mode under Neumann conditions) of a generated shape's FEM operator.
fn mesh_case(
    name: &str,
    shape: Shape,
    boundary: Boundary,
    order: u8,
    k: usize,
    truth: (Measures, Option<f64>),
) -> Case {
    let neumann = matches!(boundary, Boundary::Neumann);
    let options = OperatorOptions { boundary, order, ..Default::default() };
    let op = operators::build(&shape, &options).unwrap_or_else(|e| panic!("{name}: {e}"));
    let want = (k + usize::from(neumann)).min(op.pair.n() - 1);
    let s = eigs(&op.pair, &EigenOptions { k: want, ..Default::default() }, None, Control::default())
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    let (measures, boundary_measure) = truth;
    let condition = match (measures.has_boundary, neumann) {
        (Some(false), _) => "closed",
        (_, true) => "Neumann",
        (_, false) => "Dirichlet",
    };
    Case {
        name: format!("{name} {condition} P{order}"),
        class: format!("d{} {condition} P{order}", measures.dimension),
        measures,
        boundary: boundary_measure,
        zero_tol: zero_threshold(&op.pair),
        unknowns: Some(op.pair.n()),
        eigenvalues: s.values,
    }
}

fn surface(area: f64, has_boundary: bool) -> Measures {
    Measures { dimension: 2, area: Some(area), has_boundary: Some(has_boundary), ..Default::default() }
}

fn unit_cube() -> Measures {
    Measures { dimension: 3, volume: Some(1.0), area: Some(6.0), has_boundary: Some(true), ..Default::default() }
}

fn icosphere(level: u32, order: u8, k: usize) -> Case {
    let m = generate::icosphere(level);
    let truth = (surface(mesh_area(&m), false), None);
    mesh_case(&format!("icosphere {level}"), Shape::TriangleMesh(m), Boundary::Neumann, order, k, truth)
}

fn square(n: usize, boundary: Boundary, order: u8, k: usize) -> Case {
    let truth = (surface(1.0, true), Some(4.0));
    mesh_case(&format!("square {n}"), Shape::TriangleMesh(generate::unit_square(n)), boundary, order, k, truth)
}

/// The disk of `rings` rings: a regular 6·rings-gon inscribed in the unit circle.
fn disk(rings: usize, boundary: Boundary, order: u8, k: usize) -> Case {
    let sides = 6.0 * rings as f64;
    let area = 0.5 * sides * (2.0 * PI / sides).sin();
    let perimeter = 2.0 * sides * (PI / sides).sin();
    let truth = (surface(area, true), Some(perimeter));
    mesh_case(&format!("disk {rings}"), Shape::TriangleMesh(generate::unit_disk(rings)), boundary, order, k, truth)
}

fn cube(n: usize, boundary: Boundary, order: u8, k: usize) -> Case {
    mesh_case(
        &format!("cube tets {n}"),
        Shape::TetMesh(generate::unit_cube_tets(n)),
        boundary,
        order,
        k,
        (unit_cube(), Some(6.0)),
    )
}

/// Exact spectra: boxes with sides `sides` (π² Σ n_i²/a_i², n_i ≥ 1 Dirichlet, ≥ 0 Neumann) and the unit sphere
/// (l(l + 1), 2l + 1 times), the first `count` values.
fn exact_cases(count: usize) -> Vec<Case> {
    let boxes: [&[f64]; 6] =
        [&[1.0, 1.0], &[1.0, 0.7], &[1.0, 0.3], &[1.0, 1.0, 1.0], &[1.0, 0.8, 0.6], &[1.0, 0.5, 0.3]];
    let mut out = vec![];
    for sides in boxes {
        for neumann in [true, false] {
            let start = usize::from(!neumann);
            let n = 40usize;
            let mut ev: Vec<f64> = vec![];
            let mut index = vec![start; sides.len()];
            loop {
                ev.push(PI * PI * index.iter().zip(sides).map(|(&i, a)| (i * i) as f64 / (a * a)).sum::<f64>());
                let Some(j) = (0..index.len()).find(|&j| index[j] + 1 < n) else { break };
                index[j] += 1;
                index[..j].iter_mut().for_each(|i| *i = start);
            }
            ev.sort_by(f64::total_cmp);
            ev.truncate(count);
            let d = sides.len() as u8;
            let measure: f64 = sides.iter().product();
            let boundary = if d == 2 {
                2.0 * (sides[0] + sides[1])
            } else {
                2.0 * measure * sides.iter().map(|a| 1.0 / a).sum::<f64>()
            };
            let measures = if d == 2 {
                surface(measure, true)
            } else {
                Measures { dimension: 3, volume: Some(measure), has_boundary: Some(true), ..Default::default() }
            };
            let condition = if neumann { "Neumann" } else { "Dirichlet" };
            out.push(Case {
                name: format!("box {sides:?} {condition} exact"),
                class: format!("d{d} {condition} exact"),
                measures,
                boundary: Some(boundary),
                zero_tol: 1e-9,
                unknowns: None,
                eigenvalues: ev,
            });
        }
    }
    let sphere: Vec<f64> =
        (0..40usize).flat_map(|l| std::iter::repeat_n((l * (l + 1)) as f64, 2 * l + 1)).take(count).collect();
    out.push(Case {
        name: "sphere exact".into(),
        class: "d2 closed exact".into(),
        measures: surface(4.0 * PI, false),
        boundary: None,
        zero_tol: 1e-9,
        unknowns: None,
        eigenvalues: sphere,
    });
    out
}

/// Counts per class: covered / reported / omitted, and how many omitted would have covered.
#[derive(Default, Debug, Clone, Copy)]
struct Count {
    covered: usize,
    reported: usize,
    omitted: usize,
    omitted_covering: usize,
}

impl Count {
    fn add(&mut self, o: Count) {
        self.covered += o.covered;
        self.reported += o.reported;
        self.omitted += o.omitted;
        self.omitted_covering += o.omitted_covering;
    }
    fn rate(&self) -> f64 {
        self.covered as f64 / self.reported.max(1) as f64
    }
    fn rate_with_omitted(&self) -> f64 {
        (self.covered + self.omitted_covering) as f64 / (self.reported + self.omitted).max(1) as f64
    }
    fn cell(&self) -> String {
        format!(
            "{}/{} ({} omitted, {} of them covering)",
            self.covered, self.reported, self.omitted, self.omitted_covering
        )
    }
}

#[derive(Default, Debug, Clone, Copy)]
struct Tally {
    measure: Count,
    boundary: Count,
    dimension: Count,
    /// The same, where the analysis raises no warning (neither an omission nor a mesh too coarse for λ_k).
    measure_unwarned: Count,
    boundary_unwarned: Count,
}

/// The analysis' mesh-resolution warning (`analysis::run::weyl_warnings`): λ_k's wavelength 2π/√λ_k spans fewer
/// than 10 mesh spacings h = (|Ω|/n)^{1/d}, n the operator's unknowns.
fn coarse_for(c: &Case, lk: f64) -> bool {
    let (Some(n), Some(measure)) = (c.unknowns, c.measures.measure()) else { return false };
    let h = (measure / n as f64).powf(1.0 / f64::from(c.measures.dimension));
    2.0 * PI / (lk.sqrt() * h) < 10.0
}

/// One estimate against its truth: reported (covered or not) or omitted (its numbers covering or not).
fn judge(reported: Option<(f64, f64)>, omitted: Option<(f64, f64)>, truth: f64) -> Count {
    let covers = |(x, u): (f64, f64)| (x - truth).abs() <= 2.0 * u;
    match (reported, omitted) {
        (Some(e), _) => Count { covered: covers(e) as usize, reported: 1, ..Default::default() },
        (None, Some(e)) => Count { omitted: 1, omitted_covering: covers(e) as usize, ..Default::default() },
        (None, None) => Count::default(),
    }
}

fn unresolved(w: &WeylEstimate, field: &str) -> Option<(f64, f64)> {
    w.unresolved.iter().find(|u| u.field == field).and_then(|u| Some((u.estimate?, u.uncertainty?)))
}

/// The Weyl estimates of each case at each k (the first k non-zero eigenvalues), judged; per class, and the log.
fn calibrate(cases: &[Case], ks: &[usize]) -> BTreeMap<String, Tally> {
    let mut out: BTreeMap<String, Tally> = BTreeMap::new();
    for c in cases {
        let zeros = c.eigenvalues.iter().take_while(|&&l| l <= c.zero_tol).count();
        for &k in ks {
            if zeros + k > c.eigenvalues.len() {
                continue;
            }
            let w = weyl_estimate(&c.eigenvalues[..zeros + k], c.zero_tol, &c.measures).unwrap();
            let truth = c.measures.measure().unwrap();
            let measure =
                judge(w.measure_estimate.zip(w.measure_uncertainty), unresolved(&w, "measure_estimate"), truth);
            let boundary = match c.boundary {
                Some(b) => judge(
                    w.boundary_length_estimate.zip(w.boundary_length_uncertainty),
                    unresolved(&w, "boundary_length_estimate"),
                    b,
                ),
                None => Count::default(),
            };
            let dim = f64::from(c.measures.dimension);
            let dimension = judge(w.dimension_uncertainty.map(|u| (w.dimension_estimate, u)), None, dim);
            println!(
                "{:34} k={k:3}: {} {:?} ± {:?} (truth {truth:.4}); boundary {:?} ± {:?} (truth {:?}); dimension {:.2} ± \
                 {:?}; unresolved {:?}; coarse {}{}",
                c.name,
                w.measure_name,
                w.measure_estimate,
                w.measure_uncertainty,
                w.boundary_length_estimate,
                w.boundary_length_uncertainty,
                c.boundary,
                w.dimension_estimate,
                w.dimension_uncertainty,
                w.unresolved.iter().map(|u| (u.field, u.estimate, u.uncertainty)).collect::<Vec<_>>(),
                coarse_for(c, c.eigenvalues[zeros + k - 1]),
                if measure.reported > measure.covered || boundary.reported > boundary.covered { " MISS" } else { "" }
            );
            let t = out.entry(c.class.clone()).or_default();
            t.measure.add(measure);
            t.boundary.add(boundary);
            t.dimension.add(dimension);
            if w.unresolved.is_empty() && !coarse_for(c, c.eigenvalues[zeros + k - 1]) {
                t.measure_unwarned.add(measure);
                t.boundary_unwarned.add(boundary);
            }
        }
    }
    out
}

/// Prints the figures as the Markdown table of `docs/weyl.md` and returns the totals.
fn report(tallies: &BTreeMap<String, Tally>) -> Tally {
    let mut total = Tally::default();
    println!("| class | measure | boundary | measure, no warning | boundary, no warning | dimension |");
    println!("|---|---|---|---|---|---|");
    let row = |class: &str, t: &Tally| {
        let ratio = |c: Count| format!("{}/{}", c.covered, c.reported);
        println!(
            "| {class} | {} | {} | {} | {} | {} |",
            t.measure.cell(),
            t.boundary.cell(),
            ratio(t.measure_unwarned),
            ratio(t.boundary_unwarned),
            ratio(t.dimension)
        );
    };
    for (class, t) in tallies {
        row(class, t);
        total.measure.add(t.measure);
        total.boundary.add(t.boundary);
        total.dimension.add(t.dimension);
        total.measure_unwarned.add(t.measure_unwarned);
        total.boundary_unwarned.add(t.boundary_unwarned);
    }
    row("all", &total);
    println!(
        "coverage: measure {:.3} ({:.3} with the omitted, {:.3} without a warning), boundary {:.3} ({:.3}, {:.3}), \
         dimension {:.3}",
        total.measure.rate(),
        total.measure.rate_with_omitted(),
        total.measure_unwarned.rate(),
        total.boundary.rate(),
        total.boundary.rate_with_omitted(),
        total.boundary_unwarned.rate(),
        total.dimension.rate()
    );
    total
}

fn assert_calibrated(total: &Tally) {
    for (what, c) in [("measure", total.measure), ("boundary", total.boundary)] {
        assert!(c.rate() >= 0.9, "{what}: the 2σ intervals cover the truth in {}", c.cell());
        assert!(c.rate_with_omitted() >= 0.9, "{what}, the omitted counted too: {}", c.cell());
    }
    for (what, c) in [("measure", total.measure_unwarned), ("boundary", total.boundary_unwarned)] {
        assert!(c.rate() >= 0.95, "{what} without a warning: {}", c.cell());
    }
    assert!(total.dimension.rate() >= 0.9, "dimension: {}", total.dimension.cell());
}

/// The always-run part: exact spectra and a few small meshes of each class, k = 20, 50 and 100.
#[test]
fn weyl_intervals_cover_the_truth_on_a_small_set() {
    let (n, d) = (Boundary::Neumann, Boundary::Dirichlet);
    let mut cases = exact_cases(120);
    for order in [1, 2] {
        cases.push(icosphere(3, order, 100));
        cases.push(square(32, n.clone(), order, 100));
        cases.push(square(32, d.clone(), order, 100));
        cases.push(disk(16, n.clone(), order, 100));
        cases.push(cube(8, n.clone(), order, 100));
        cases.push(cube(8, d.clone(), order, 100));
    }
    let total = report(&calibrate(&cases, &[20, 50, 100]));
    assert_calibrated(&total);
}

/// Issue 48: the Neumann unit cube's volume (tets, n = 16, k = 20) read −2.957 ± 0.507, with no warning. Now it
/// is within 2σ of 1 or omitted as unresolved (the analysis then warns `weyl-underresolved`), in P1 and P2; its
/// boundary term is read with the Neumann sign.
#[test]
fn neumann_cube_volume_is_heard_or_omitted() {
    for order in [1, 2] {
        let c = cube(16, Boundary::Neumann, order, 20);
        let w = weyl_estimate(&c.eigenvalues, c.zero_tol, &c.measures).unwrap();
        assert_eq!(w.zero_modes, 1);
        match (w.measure_estimate, w.measure_uncertainty) {
            (Some(v), Some(dv)) => assert!((v - 1.0).abs() <= 2.0 * dv, "P{order}: volume {v} ± {dv}"),
            _ => assert!(w.unresolved.iter().any(|u| u.field == "measure_estimate"), "P{order}: {w:?}"),
        }
        if let (Some(s), Some(ds)) = (w.boundary_length_estimate, w.boundary_length_uncertainty) {
            assert!((s - 6.0).abs() <= 2.0 * ds, "P{order}: boundary {s} ± {ds}");
        }
        let (dim, du) = (w.dimension_estimate, w.dimension_uncertainty.unwrap());
        assert!((dim - 3.0).abs() <= 2.0 * du, "P{order}: dimension {dim} ± {du}");
    }
    // With 200 P2 eigenvalues the volume is heard, within 10 %.
    let c = cube(16, Boundary::Neumann, 2, 200);
    let w = weyl_estimate(&c.eigenvalues, c.zero_tol, &c.measures).unwrap();
    let (v, dv) = (w.measure_estimate.unwrap(), w.measure_uncertainty.unwrap());
    assert!((v - 1.0).abs() <= 2.0 * dv && dv < 0.1, "volume {v} ± {dv}");
}

/// The issue's under-covered cases: the icosphere (level 4, k = 50; area 12.390 ± 0.025 for 12.551) and the
/// Dirichlet square (64², k = 60; area 0.985 ± 0.0056).
#[test]
fn issue_cases_are_covered() {
    let c = icosphere(4, 1, 50);
    let w = weyl_estimate(&c.eigenvalues, c.zero_tol, &c.measures).unwrap();
    let (a, da) = (w.measure_estimate.unwrap(), w.measure_uncertainty.unwrap());
    assert!((a - c.measures.area.unwrap()).abs() <= 2.0 * da, "icosphere area {a} ± {da}");
    let (dim, du) = (w.dimension_estimate, w.dimension_uncertainty.unwrap());
    assert!((dim - 2.0).abs() <= 2.0 * du, "icosphere dimension {dim} ± {du}");
    let c = square(64, Boundary::Dirichlet, 1, 60);
    let w = weyl_estimate(&c.eigenvalues, c.zero_tol, &c.measures).unwrap();
    let (a, da) = (w.measure_estimate.unwrap(), w.measure_uncertainty.unwrap());
    assert!((a - 1.0).abs() <= 2.0 * da, "square area {a} ± {da}");
    let (p, dp) = (w.boundary_length_estimate.unwrap(), w.boundary_length_uncertainty.unwrap());
    assert!((p - 4.0).abs() <= 2.0 * dp, "square perimeter {p} ± {dp}");
}

/// The full set of `docs/weyl.md` (about a minute in the dev profile): icospheres 2–5, unit squares 16–64 and
/// disks 8–32 with both conditions, cube tets 6–16 with both, P1 and P2, LaPy's `cubeTetra.vtk` (P1), and the
/// exact spectra, at k = 20, 50, 100 and 200.
#[test]
#[ignore = "needs the shared meshes (KAC_TEST_DATA or ../shared/data): scripts/test-all.sh runs it with --ignored where they are"]
fn weyl_calibration_full_set() {
    let mut cases = exact_cases(220);
    for order in [1, 2] {
        for level in 2..=5 {
            cases.push(icosphere(level, order, 200));
        }
        for b in [Boundary::Neumann, Boundary::Dirichlet] {
            for n in [16, 32, 64] {
                cases.push(square(n, b.clone(), order, 200));
            }
            for rings in [8, 16, 32] {
                cases.push(disk(rings, b.clone(), order, 200));
            }
            for n in [6, 8, 12, 16] {
                cases.push(cube(n, b.clone(), order, 200));
            }
        }
    }
    let dir = common::shared_data("weyl_calibration_full_set");
    let path = dir.join("tet/cubeTetra.vtk");
    let opts = kac_core::ValidateOptions::default();
    let v = kac_core::load(&path, None, &kac_core::ReadOptions::default(), &opts).unwrap().0;
    let measures = Measures::of(&v.summary(), None);
    for b in [Boundary::Neumann, Boundary::Dirichlet] {
        cases.push(mesh_case("LaPy cubeTetra", v.shape.clone(), b, 1, 200, (measures, Some(6.0))));
    }
    let total = report(&calibrate(&cases, &[20, 50, 100, 200]));
    assert_calibrated(&total);
}
