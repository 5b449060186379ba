//! Nearest rows in a spectral embedding: tiles of single-precision products scanned by a kernel compiled per
//! instruction set.

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatMut, MatRef, Par};
use rayon::prelude::*;

/// For each row of `query` (q × d), the row of `data` (n × d) nearest to it, and the distance, by tiles of matrix
/// products (|a − b|² = |a|² + |b|² − 2 a·b), the query's blocks in parallel.
///
/// The search runs in single precision (twice the products per instruction of double, half the memory), so a row
/// within single-precision rounding of the nearest (about 10⁻⁶ of the rows' squared norms) may be chosen in its
/// place; the distance returned is the chosen row's, in double precision. A tile of products (64 query rows × 1,024
/// data rows, 256 KiB) stays in cache while it is scanned: a product block as wide as the data (tens of MB at 30,000
/// vertices) went to memory and back, which cost more than the products. (Trees do not prune in the 30 to 200
/// dimensions of a spectral embedding, and a clustered search with triangle-inequality bounds costs more than it
/// prunes.)
pub fn nearest_rows(data: MatRef<'_, f64>, query: MatRef<'_, f64>) -> (Vec<u32>, Vec<f64>) {
    const QUERY_ROWS: usize = 64;
    const DATA_ROWS: usize = 1024;
    let (n, q, d) = (data.nrows(), query.nrows(), data.ncols());
    if n == 0 {
        return (vec![0; q], vec![f64::INFINITY; q]);
    }
    let single = |m: MatRef<'_, f64>| Mat::<f32>::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)] as f32);
    let (data32, query32) = (single(data), single(query));
    let dn: Vec<f32> = (0..n).map(|i| (0..d).map(|j| data32[(i, j)].powi(2)).sum()).collect();
    let blocks: Vec<usize> = (0..q).step_by(QUERY_ROWS).collect();
    let isa = crate::simd::Isa::detect();
    let best: Vec<Vec<u32>> = blocks
        .par_iter()
        .map_init(
            // One tile per thread, reused (a fresh one per block spent as much time in page faults as in products).
            || vec![0.0f32; QUERY_ROWS * DATA_ROWS],
            |tile, &r0| {
                let rows = QUERY_ROWS.min(q - r0);
                let qb = query32.as_ref().subrows(r0, rows);
                // Per query row: the least |b|² − 2 a·b so far and its data row; within a tile, the row's place in
                // the tile as f32 (−1: none closer there), so that the scan is of one width and vectorizes.
                let mut bd = vec![f32::INFINITY; rows];
                let mut bi = vec![0u32; rows];
                let mut local = vec![-1.0f32; rows];
                for d0 in (0..n).step_by(DATA_ROWS) {
                    let cols = DATA_ROWS.min(n - d0);
                    // G = Q_b D_tileᵀ, column-major (rows × cols): column i holds every query row's product with
                    // data row d0 + i.
                    let g = &mut tile[..rows * cols];
                    let dt = data32.as_ref().subrows(d0, cols).transpose();
                    let gm = MatMut::from_column_major_slice_mut(g, rows, cols);
                    matmul(gm, Accum::Replace, qb, dt, 1.0f32, Par::Seq);
                    local.fill(-1.0);
                    scan_tile(isa, g, &dn[d0..d0 + cols], &mut bd, &mut local);
                    for (x, &l) in bi.iter_mut().zip(&local) {
                        if l >= 0.0 {
                            *x = (d0 + l as usize) as u32;
                        }
                    }
                }
                bi
            },
        )
        .collect();
    let idx: Vec<u32> = best.into_iter().flatten().collect();
    let dist = idx
        .iter()
        .enumerate()
        .map(|(r, &i)| (0..d).map(|j| (query[(r, j)] - data[(i as usize, j)]).powi(2)).sum::<f64>().sqrt())
        .collect();
    (idx, dist)
}

/// The scan of one tile of products (column-major, `bd.len()` rows): for each row r, over the columns i, the least
/// dn[i] − 2 g[r, i] below bd[r], and i where it is (as f32) in `local`. Compiled for AVX-512 and AVX2, `isa`
/// chosen at run time (the portable build leaves it scalar, with a branch per row).
pub(super) fn scan_tile(isa: crate::simd::Isa, g: &[f32], dn: &[f32], bd: &mut [f32], local: &mut [f32]) {
    #[inline(always)]
    fn body(g: &[f32], dn: &[f32], bd: &mut [f32], local: &mut [f32]) {
        let rows = bd.len();
        let local = &mut local[..rows];
        for (i, col) in g.chunks_exact(rows).enumerate() {
            let (di, place) = (dn[i], i as f32);
            for r in 0..rows {
                let d2 = di - 2.0 * col[r];
                let closer = d2 < bd[r];
                local[r] = if closer { place } else { local[r] };
                bd[r] = if closer { d2 } else { bd[r] };
            }
        }
    }
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx512f")]
        fn wide(g: &[f32], dn: &[f32], bd: &mut [f32], local: &mut [f32]) {
            body(g, dn, bd, local)
        }
        #[target_feature(enable = "avx2,fma")]
        fn narrow(g: &[f32], dn: &[f32], bd: &mut [f32], local: &mut [f32]) {
            body(g, dn, bd, local)
        }
        match isa {
            // SAFETY: the CPU has AVX-512F (`isa` is one it supports).
            crate::simd::Isa::Avx512 => return unsafe { wide(g, dn, bd, local) },
            // SAFETY: the CPU has AVX2 and FMA (`isa` is one it supports).
            crate::simd::Isa::Avx2 => return unsafe { narrow(g, dn, bd, local) },
            crate::simd::Isa::Scalar => {}
        }
    }
    body(g, dn, bd, local)
}
