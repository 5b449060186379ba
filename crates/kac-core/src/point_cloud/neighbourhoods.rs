//! The k nearest neighbours of every point of a cloud, from a k-d tree (kiddo).

use crate::geometry::Point;
use crate::operators::error::OperatorError;
use kiddo::{KdTree, SquaredEuclidean};
use rayon::prelude::*;

/// The k nearest neighbours of every point (itself excluded), nearest first.
pub struct Neighbourhoods {
    pub k: usize,
    pub index: Vec<u32>,
    pub tree: KdTree<f64, 3>,
}

impl Neighbourhoods {
    pub fn knn(points: &[Point], k: usize) -> Result<Self, OperatorError> {
        if points.len() < 4 {
            return Err(OperatorError::InvalidParameter {
                name: "points",
                message: format!("{} points; a point-cloud Laplacian needs at least 4", points.len()),
            });
        }
        let k = k.clamp(3, points.len() - 1);
        let mut tree: KdTree<f64, 3> = KdTree::with_capacity(points.len());
        for (i, p) in points.iter().enumerate() {
            tree.add(p, i as u64);
        }
        let index: Vec<u32> = points
            .par_iter()
            .enumerate()
            .flat_map_iter(|(i, p)| {
                let found = tree.nearest_n::<SquaredEuclidean>(p, k + 1);
                let mut out: Vec<u32> = found.iter().map(|n| n.item as u32).filter(|&j| j as usize != i).collect();
                out.truncate(k);
                while out.len() < k {
                    out.push(out.last().copied().unwrap_or(0));
                }
                out
            })
            .collect();
        Ok(Neighbourhoods { k, index, tree })
    }
    pub fn of(&self, i: usize) -> &[u32] {
        &self.index[i * self.k..(i + 1) * self.k]
    }
}
