//! One sign convention, checked against closed forms. Δ = −∇·∇ is positive semidefinite (the chapter's eq. 9.7)
//! and L, its weak form, is the stiffness matrix (L ⪰ 0): "Δf = g" is L f = M g, heat is ∂u/∂t = −Δu, waves are
//! ∂²u/∂t² = −Δu, smoothing is u + αΔu = ū. On the unit sphere a degree-l spherical harmonic satisfies
//! Δ Y_l = l(l+1) Y_l, so every PDE tool has a closed-form answer for u₀ = Y_l, and the opposite sign gives a
//! different one (−f for Poisson, growth instead of decay for heat, cosh instead of cos for waves).
#![allow(clippy::needless_range_loop)]

use kac_core::descriptors::heat::diffuse_spectral;
use kac_core::descriptors::Basis;
use kac_core::geometry::{generate, Point, Shape};
use kac_core::operators::sparse::{matvec, SparsePair};
use kac_core::operators::{self, Boundary, Mass, Operator, OperatorOptions};
use kac_core::pde;
use kac_core::spectrum::{eigs, Control, EigenOptions, Method};

/// A spherical harmonic: its name, its degree l, and its values on the unit sphere (unnormalized).
type Harmonic = (&'static str, u32, fn(Point) -> f64);

/// Δ Y_l = l(l+1) Y_l on the unit sphere for each of these.
const HARMONICS: [Harmonic; 4] = [
    ("z", 1, |p| p[2]),
    ("xy", 2, |p| p[0] * p[1]),
    ("3z²−1", 2, |p| 3.0 * p[2] * p[2] - 1.0),
    ("z(5z²−3)", 3, |p| p[2] * (5.0 * p[2] * p[2] - 3.0)),
];

/// The icosphere of the given level (unit radius) and its cotan operator with the consistent mass.
fn sphere(level: u32) -> (Vec<Point>, Operator) {
    let m = generate::icosphere(level);
    let vertices = m.vertices.clone();
    let shape = Shape::TriangleMesh(m);
    let options = OperatorOptions { mass: Some(Mass::Consistent), boundary: Boundary::Neumann, ..Default::default() };
    (vertices, operators::build(&shape, &options).unwrap())
}

fn sample(vertices: &[Point], y: fn(Point) -> f64) -> Vec<f64> {
    vertices.iter().map(|&p| y(p)).collect()
}

/// ⟨a, b⟩_M = aᵀ M b.
fn m_inner(pair: &SparsePair, a: &[f64], b: &[f64]) -> f64 {
    let mut mb = vec![0.0; b.len()];
    matvec(&pair.pattern, &pair.mass, b, &mut mb);
    a.iter().zip(&mb).map(|(x, y)| x * y).sum()
}

/// ‖got − want‖_M / ‖want‖_M: the relative L² error on the mesh.
fn rel_err(pair: &SparsePair, got: &[f64], want: &[f64]) -> f64 {
    let d: Vec<f64> = got.iter().zip(want).map(|(a, b)| a - b).collect();
    (m_inner(pair, &d, &d) / m_inner(pair, want, want)).sqrt()
}

fn scaled(u: &[f64], s: f64) -> Vec<f64> {
    u.iter().map(|v| v * s).collect()
}

fn column(m: &faer::Mat<f64>, j: usize) -> Vec<f64> {
    m.col(j).iter().copied().collect()
}

fn lambda(l: u32) -> f64 {
    (l * (l + 1)) as f64
}

#[test]
fn poisson_of_a_spherical_harmonic_is_the_harmonic_over_l_l_plus_1() {
    // Δf = Y_l on the unit sphere (Neumann; ∫ Y_l = 0, so g is compatible) has the mean-zero solution
    // f = Y_l / (l(l+1)), since Δ Y_l = l(l+1) Y_l with Δ = −∇·∇ ⪰ 0: L f = M g. The old sign (L f = −M g) gave
    // −f, whose relative error is 2. P1 elements converge at second order in h, and h halves per level, so the
    // error falls by 4 per level. Measured relative M-norm errors: level 4 1.4e-3 (l = 1), 2.9e-3 (l = 2),
    // 5.1e-3 (l = 3); level 5 3.6e-4 … 1.3e-3; ratios level 3→4 and 4→5 between 3.96 and 3.99.
    let mut errors = vec![];
    for level in [3, 4, 5] {
        let (v, op) = sphere(level);
        let mut row = vec![];
        for (name, l, y) in HARMONICS {
            let g = sample(&v, y);
            let p = pde::poisson(&op.pair, &g, None).unwrap();
            assert!(
                p.removed_mean[0].abs() < 1e-2,
                "{name}: ∫ Y_l = 0, yet the mean {} was removed",
                p.removed_mean[0]
            );
            let f = p.values;
            let want = scaled(&g, 1.0 / lambda(l));
            let err = rel_err(&op.pair, &f, &want);
            assert!(m_inner(&op.pair, &f, &g) > 0.0, "level {level}, {name}: f points against g (the old sign)");
            assert!(rel_err(&op.pair, &f, &scaled(&want, -1.0)) > 1.9, "level {level}, {name}: f ≈ −Y_l/(l(l+1))");
            if level >= 4 {
                assert!(err < 1e-2, "level {level}, {name}: relative error {err:.3e}");
            }
            row.push(err);
        }
        errors.push(row);
    }
    for w in errors.windows(2) {
        for (j, (a, b)) in w[0].iter().zip(&w[1]).enumerate() {
            assert!((3.5..4.5).contains(&(a / b)), "{}: errors {a:.3e} → {b:.3e} do not fall like h²", HARMONICS[j].0);
        }
    }
}

#[test]
fn implicit_heat_of_a_spherical_harmonic_decays_as_exp_minus_l_l_plus_1_t() {
    // ∂u/∂t = −Δu (M u̇ = −L u) from u₀ = Y_l: u(t) = e^{−l(l+1)t} Y_l, a decay; the opposite sign would grow as
    // e^{+l(l+1)t}. Backward Euler multiplies the mode by (1 + τλ)^{−N}, τ = t/N, which decays more slowly than
    // e^{−λt} by a relative λ²t²/(2N) (7.2e-3 for l = 3, t = 0.2, N = 400); the mesh's eigenvalue λ_h exceeds
    // l(l+1) by 0.14 % … 0.5 % (level 4), which speeds the decay by about (λ_h − λ)t (at most 1.2e-2 here). The
    // two partly cancel: measured relative M-norm errors 1.4e-4 … 5.0e-3 (largest for l = 3 at t = 0.2). The
    // tolerance 1.5e-2 covers either source alone.
    let (v, op) = sphere(4);
    let times = [0.05, 0.1, 0.2];
    for (name, l, y) in HARMONICS {
        let u0 = sample(&v, y);
        let u = pde::heat_implicit(&op.pair, &u0, &times, 400).unwrap();
        let mut previous = m_inner(&op.pair, &u0, &u0).sqrt();
        for (j, &t) in times.iter().enumerate() {
            let got = column(&u, j);
            let err = rel_err(&op.pair, &got, &scaled(&u0, (-lambda(l) * t).exp()));
            assert!(err < 1.5e-2, "{name} at t = {t}: relative error {err:.3e}");
            let norm = m_inner(&op.pair, &got, &got).sqrt();
            assert!(norm < previous, "{name}: ‖u‖_M grew from {previous} to {norm} at t = {t}");
            previous = norm;
        }
    }
    // Any u₀ (here a hat function) loses M-norm and keeps its integral: 1ᵀL = 0, so 1ᵀM u is conserved.
    let mut hat = vec![0.0; v.len()];
    hat[0] = 1.0;
    let u = pde::heat_implicit(&op.pair, &hat, &times, 10).unwrap();
    let ones = vec![1.0; v.len()];
    let mut previous = m_inner(&op.pair, &hat, &hat);
    for j in 0..times.len() {
        let got = column(&u, j);
        assert!(m_inner(&op.pair, &got, &got) < previous);
        previous = m_inner(&op.pair, &got, &got);
        assert!((m_inner(&op.pair, &got, &ones) - m_inner(&op.pair, &hat, &ones)).abs() < 1e-12);
    }
}

#[test]
fn waves_and_spectral_heat_of_a_spherical_harmonic_follow_cos_and_exp() {
    // With the 16 lowest eigenpairs of the level-4 sphere (l = 0 … 3, whole clusters: the icosahedral group keeps
    // the l ≤ 2 clusters degenerate and splits l = 3 into 3 + 4 nearby values), for u₀ = Y_l:
    // - waves ∂²u/∂t² = −Δu, v₀ = 0: u(t) = cos(√(l(l+1)) t) Y_l (the opposite sign would give cosh, a growth);
    // - heat ∂u/∂t = −Δu (descriptors::heat::diffuse_spectral): u(t) = e^{−l(l+1)t} Y_l, a decay.
    // Both errors come from the mesh's eigenvalue λ_h ≠ l(l+1) (λ_h − l(l+1) = 0.0029, 0.017, 0.061 for
    // l = 1, 2, 3) and from the part of the sampled Y_l outside the discrete eigenspace (relative M-norm
    // 6e-5 … 3.4e-4). Waves: the phase error is at most |√λ_h − √(l(l+1))| t (7.1e-3 for l = 2, 1.8e-2 for
    // l = 3 at t = 2); measured ‖error‖_M/‖Y_l‖_M up to 7.0e-3 and 1.1e-2. Heat: the relative error is
    // 1 − e^{−(λ_h − l(l+1)) t} (3.4e-2 for l = 2, 0.115 for l = 3 at t = 2), as measured. Tolerances: 1.5 × the
    // predicted error + 1e-3, with λ_h from the computed eigenvalues; and the decay rate −ln(⟨u(t), Y_l⟩_M /
    // ‖Y_l‖²_M)/t, and λ_h itself, within 1 % of l(l+1).
    let (v, op) = sphere(4);
    let options = EigenOptions { k: 16, method: Method::Sparse, ..Default::default() };
    let s = eigs(&op.pair, &options, None, Control::default()).unwrap();
    let basis = Basis::of(&s, &op.pair);
    let times = [0.1, 0.5, 1.0, 2.0];
    for (name, l, y) in HARMONICS {
        let cluster = &s.values[(l * l) as usize..((l + 1) * (l + 1)) as usize];
        let lambda_h = cluster.iter().sum::<f64>() / cluster.len() as f64;
        assert!((lambda_h / lambda(l) - 1.0).abs() < 1e-2, "l = {l}: eigenvalues {cluster:?}");
        let u0 = sample(&v, y);
        let norm2 = m_inner(&op.pair, &u0, &u0);
        let (w, dropped) = pde::wave(&basis, &op.pair, &u0, None, &times).unwrap();
        assert!(dropped < 1e-3 * norm2.sqrt(), "{name}: {dropped} of Y_l lies outside the basis");
        let d = diffuse_spectral(&basis, &op.pair, &u0, &times).unwrap();
        for (j, &t) in times.iter().enumerate() {
            let got = column(&w, j);
            let cos = (lambda(l).sqrt() * t).cos();
            let err = rel_err(&op.pair, &got, &scaled(&u0, cos)) * cos.abs();
            let tol = 1.5 * (lambda_h.sqrt() - lambda(l).sqrt()).abs() * t + 1e-3;
            assert!(err < tol, "wave, {name} at t = {t}: error {err:.3e} of ‖Y_l‖_M (tolerance {tol:.1e})");
            assert!(m_inner(&op.pair, &got, &got) <= norm2 * (1.0 + 1e-6), "wave, {name} at t = {t}: u grew");
            let got = column(&d.values, j);
            let err = rel_err(&op.pair, &got, &scaled(&u0, (-lambda(l) * t).exp()));
            let tol = 1.5 * (1.0 - (-(lambda_h - lambda(l)).abs() * t).exp()) + 1e-3;
            assert!(err < tol, "heat, {name} at t = {t}: relative error {err:.3e} (tolerance {tol:.1e})");
            let rate = -(m_inner(&op.pair, &got, &u0) / norm2).ln() / t;
            assert!((rate / lambda(l) - 1.0).abs() < 1e-2, "heat, {name}: decay rate {rate}, l(l+1) = {}", lambda(l));
        }
    }
}

#[test]
fn smoothing_a_spherical_harmonic_divides_it_by_one_plus_alpha_l_l_plus_1() {
    // u + αΔu = ū (exercise 9.4), (M + αL) u = M ū, with ū = Y_l: u = Y_l / (1 + α l(l+1)), a damping; the
    // opposite sign (u − αΔu = ū) would give Y_l / (1 − α l(l+1)), an amplification or a flip. Measured relative
    // M-norm errors at level 4: 3.9e-5 (l = 1, α = 0.01) … 4.7e-3 (l = 3, α = 1); level 5 four times smaller
    // (second order). Tolerance 1e-2 at level 4 and a ratio above 3.5 to level 5.
    let (four, five) = (sphere(4), sphere(5));
    for alpha in [0.01, 0.1, 1.0] {
        for (name, l, y) in HARMONICS {
            let mut errors = vec![];
            for (v, op) in [&four, &five] {
                let ubar = sample(v, y);
                let um = faer::Mat::from_fn(ubar.len(), 1, |i, _| ubar[i]);
                let u = column(&pde::smooth(&op.pair, um.as_ref(), alpha, None).unwrap(), 0);
                errors.push(rel_err(&op.pair, &u, &scaled(&ubar, 1.0 / (1.0 + alpha * lambda(l)))));
                let flipped = rel_err(&op.pair, &u, &scaled(&ubar, 1.0 / (1.0 - alpha * lambda(l))));
                assert!(flipped > 0.03, "α = {alpha}, {name}: u matches the opposite sign");
            }
            assert!(errors[0] < 1e-2, "α = {alpha}, {name}: relative error {:.3e}", errors[0]);
            assert!(errors[0] / errors[1] > 3.5, "α = {alpha}, {name}: errors {errors:?} do not fall like h²");
        }
    }
}
