//! # kac-core
//!
//! *Can you hear the shape of a drum?* The numerical core of kac: shapes and their readers
//! ([`io`], [`geometry`]), validation with repairs and a report, content-hash ids, discrete Laplace operators,
//! generalized eigensolvers and the descriptors read from a spectrum.
//!
//! This crate has no HTTP and no async runtime; the service and CLI are thin layers over it. Its global state is
//! two items, each kept because what it counts or limits spans more than one call:
//!
//! - a thread-local limit on the values of a factor (the private `FACTOR_LIMIT` in [`cholesky::factor`], set only
//!   inside [`cholesky::factor::with_factor_limit`], which restores the previous value, and read by
//!   [`cholesky::factor::factor_limit`]): a host bounds every factor the PDE tools and descriptors make during one
//!   analysis without a limit parameter on each of their signatures; unset, there is no limit;
//! - a process-wide count of the threads running work a caller may abandon (a private `static` in
//!   [`spectrum::Control::abandonable`]): abandoned work keeps its thread until it ends, so the cap of one such
//!   thread per core must count across callers and outlive each call.
//!
//! Not global, though kept between calls: a [`cholesky::factor::Cholesky`] caches its parallel solve plan
//! (`OnceLock`) and its parallel solve's scratch block (`Mutex`), per factor. Statics in `#[cfg(test)]` code only
//! serve the tests.
//!
//! Conventions (stated once, echoed in every result): the Laplacian `L` is positive semidefinite (the stiffness
//! matrix; libigl's `cotmatrix` is `−L`), the eigenproblem is `L φ = λ M φ` with `M` the mass matrix,
//! eigenvalues ascend, eigenvectors are `M`-orthonormal.
//!
//! Sign, one convention everywhere (the textbook chapter's, eq. 9.7): Δ = −∇·∇ is positive semidefinite and `L`
//! is its weak form, `L ⪰ 0`. So "Δf = g" means `L f = M g` ([`pde::poisson`]); the heat equation is
//! ∂u/∂t = −Δu, `M u̇ = −L u` (eq. 9.23; [`descriptors::heat`], [`pde::heat_implicit`]); the wave equation is
//! ∂²u/∂t² = −Δu (example 9.7; [`pde::wave`]); smoothing is u + αΔu = ū, `(M + αL) u = M ū` (exercise 9.4;
//! [`pde::smooth`]); harmonic functions satisfy Δu = 0 ([`pde::harmonic`]). On the unit sphere a degree-l
//! spherical harmonic has Δ Y_l = l(l+1) Y_l.

// Unsafe code (the style guide, "Unsafe code"): every unsafe operation inside an `unsafe fn` sits in an explicit `unsafe`
// block, and every `unsafe` block carries a `SAFETY:` comment naming the check that makes it sound.
#![deny(unsafe_op_in_unsafe_fn)]
#![deny(clippy::undocumented_unsafe_blocks)]
// Compressed-column loops index parallel arrays (row indices and values) by position.
#![allow(clippy::needless_range_loop)]
// `!(x > 0.0)` is deliberate throughout: it is also true for NaN, which must fail every positivity check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod cholesky;
pub mod correspondence;
pub mod descriptors;
pub mod error;
pub mod geometry;
pub mod io;
pub mod operators;
pub mod pattern;
pub mod pde;
pub mod point_cloud;
pub mod simd;
pub mod spectrum;

pub use error::{Element, Location, ShapeError};
pub use geometry::validate::{validate, ValidateOptions, Validated, Weld};
pub use geometry::{Shape, ShapeKind};
pub use io::{Format, ReadOptions};

/// Serialize/Deserialize for a request type whose derives carry `#[serde(remote = "Self")]`: the same fields, but
/// only a JSON object is accepted (serde's derive would also take an array of field values, which the published
/// JSON Schema does not allow).
#[macro_export]
macro_rules! object_only_serde {
    ($t:ty) => {
        impl serde::Serialize for $t {
            fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                <$t>::serialize(self, s)
            }
        }
        impl<'de> serde::Deserialize<'de> for $t {
            fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                let m = <serde_json::Map<String, serde_json::Value> as serde::Deserialize>::deserialize(d)?;
                <$t>::deserialize(serde_json::Value::Object(m)).map_err(serde::de::Error::custom)
            }
        }
    };
}

/// Reads and validates a file in one step (format from `format`, the extension, or the content).
pub fn load(
    path: &std::path::Path,
    format: Option<Format>,
    read: &ReadOptions,
    validate_opts: &ValidateOptions,
) -> Result<(Validated, Format), ShapeError> {
    let (raw, fmt) = io::read_path(path, format, read)?;
    Ok((validate(raw, validate_opts)?, fmt))
}

/// Reads and validates bytes in one step.
pub fn load_bytes(
    bytes: &[u8],
    format: Format,
    read: &ReadOptions,
    validate_opts: &ValidateOptions,
) -> Result<Validated, ShapeError> {
    validate(io::read_bytes(bytes, format, read)?, validate_opts)
}
