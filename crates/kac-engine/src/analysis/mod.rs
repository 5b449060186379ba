//! Analyses: what a client can ask of a stored shape, as one serde type shared by the CLI subcommands and the
//! service's job API. Each analysis names its operator, solver and descriptor parameters; [`run`] computes it
//! from a validated shape (reusing cached eigenpairs through [`SpectrumCache`]) and returns a JSON summary that
//! echoes every parameter plus the per-vertex arrays, kept apart so that they can be written as `.npy` or shown
//! as colours.
//!
//! Vertex indices in requests and rows of per-vertex arrays follow the numbering of the uploaded file (welded
//! input vertices share their value; vertices validation dropped get NaN).

use kac_core::descriptors::curvature;
use kac_core::descriptors::graph::{components, eigenmap, fiedler, spanning_trees};
use kac_core::descriptors::heat::{diffuse_spectral, heat_kernel_row, heat_trace, heat_trace_tail_bound};
use kac_core::descriptors::shape_dna::{self, Measures, ShapeDnaOptions};
use kac_core::descriptors::signatures::{self, HksOptions, SiHksOptions, WksOptions};
use kac_core::descriptors::weyl::weyl_estimate;
use kac_core::descriptors::{Basis, DescriptorError};
use kac_core::operators::{self, Boundary, CloudParams, Mass, Neighbourhood, Operator, OperatorKind, OperatorOptions};
use kac_core::pde::{self, geodesic};
use kac_core::spectrum::{self, Control, EigenOptions, Spectrum};
use kac_core::{Shape, Validated};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};
use std::sync::Arc;

pub mod compare;
pub mod correspond;
mod dispatch;
mod eigen;
mod entries;
mod error;
mod extrapolate;
mod finite;
mod inputs;
mod operator;
mod options;
mod output;
pub mod registry;
mod request;
mod results;
mod rows;
mod run;
mod tools;

pub use eigen::*;
pub use error::*;
pub use finite::{finite_json, first_non_finite};
pub use inputs::*;
pub use operator::{is_per_vertex, unknown_vertices, MATRIX_ARRAYS};
pub use options::*;
pub use output::*;
pub use request::*;
pub use results::*;
pub use rows::*;
pub use run::*;
