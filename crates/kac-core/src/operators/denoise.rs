//! Denoising and outlier removal of scanned point clouds ([`crate::point_cloud::denoise`]), re-exported beside the
//! operators whose build calls them.

pub use crate::point_cloud::denoise::*;
