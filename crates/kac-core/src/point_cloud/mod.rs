//! Point clouds as geometry (geometry-central gives them a module of their own): the k nearest neighbours of every
//! point, tangent frames and local areas, outliers, and the moving-least-squares projection that removes noise
//! across the surface. The operators built on them (`operators::point_cloud`, `operators::manifold`,
//! `operators::robust`) stand above; nothing here builds an operator. Uses `geometry` and the operators' error
//! type (`operators::error`) only.

pub mod denoise;
mod frames;
mod neighbourhoods;

pub use frames::{local_areas, local_frames, voronoi_cell, Cell};
pub use neighbourhoods::Neighbourhoods;
