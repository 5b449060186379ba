//! Operator matrices out: a symmetric sparse matrix as Matrix Market text and as a SciPy `.npz` (the archive
//! `scipy.sparse.save_npz` writes and `scipy.sparse.load_npz` reads: `format`, `shape`, `data`, `indices`,
//! `indptr`, uncompressed). Both are written from the matrix's upper triangle as triplets (row ≤ column,
//! 0-based, explicit zeros left out), the form kac keeps them in.

use crate::pattern::Pattern;
use std::io::Write;

/// The upper triangle (row ≤ column) of the symmetric matrix with `values` on `p`, without explicit zeros, as
/// flat triplets `[row, column, value, …]` ordered by column, then row.
pub fn upper_triplets(p: &Pattern, values: &[f64]) -> Vec<f64> {
    let mut out = Vec::new();
    for j in 0..p.n {
        for pos in p.col_ptr[j]..p.col_ptr[j + 1] {
            let i = p.row_idx[pos];
            if i <= j && values[pos] != 0.0 {
                out.extend_from_slice(&[i as f64, j as f64, values[pos]]);
            }
        }
    }
    out
}

/// Checks flat upper triplets against the size `n` and returns them as (row, column, value).
fn entries(n: usize, triplets: &[f64]) -> Result<Vec<(usize, usize, f64)>, String> {
    if !triplets.len().is_multiple_of(3) {
        return Err(format!("{} values do not make (row, column, value) triplets", triplets.len()));
    }
    triplets
        .chunks_exact(3)
        .map(|t| {
            let (i, j) = (t[0], t[1]);
            let ok = |x: f64| x >= 0.0 && x.fract() == 0.0 && (x as usize) < n;
            if !ok(i) || !ok(j) || i > j {
                return Err(format!("({i}, {j}) is not an upper-triangle entry of an {n} × {n} matrix"));
            }
            Ok((i as usize, j as usize, t[2]))
        })
        .collect()
}

/// Matrix Market `coordinate real symmetric` text of the n × n symmetric matrix with these upper triplets (the
/// file lists the lower triangle, 1-based, as the format asks; values in shortest round-trip form).
pub fn matrix_market(n: usize, triplets: &[f64], comment: &str) -> Result<Vec<u8>, String> {
    let e = entries(n, triplets)?;
    let mut out = Vec::with_capacity(32 * e.len() + 128);
    let _ = writeln!(out, "%%MatrixMarket matrix coordinate real symmetric");
    for line in comment.lines() {
        let _ = writeln!(out, "% {line}");
    }
    let _ = writeln!(out, "{n} {n} {}", e.len());
    for (i, j, v) in e {
        let _ = writeln!(out, "{} {} {v:e}", j + 1, i + 1);
    }
    Ok(out)
}

/// One `.npy` (format 1.0) of a 1-D little-endian array, or of a 0-d string when `descr` is a `<U` type.
fn npy(descr: &str, shape: &str, data: &[u8]) -> Vec<u8> {
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
    let total = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - total % 64) % 64));
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + data.len());
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(data);
    out
}

/// The whole n × n symmetric matrix (both triangles) as SciPy's CSR `.npz`: `indptr` and `indices` as int64
/// (any size), `data` float64, `shape` int64, `format` the string `csr`.
pub fn npz_csr(n: usize, triplets: &[f64]) -> Result<Vec<u8>, String> {
    let e = entries(n, triplets)?;
    let mut count = vec![0usize; n + 1];
    for &(i, j, _) in &e {
        count[i + 1] += 1;
        if i != j {
            count[j + 1] += 1;
        }
    }
    for r in 0..n {
        count[r + 1] += count[r];
    }
    let nnz = count[n];
    let mut next = count.clone();
    let mut indices = vec![0i64; nnz];
    let mut data = vec![0f64; nnz];
    for &(i, j, v) in &e {
        for (r, c) in if i == j { vec![(i, j)] } else { vec![(i, j), (j, i)] } {
            indices[next[r]] = c as i64;
            data[next[r]] = v;
            next[r] += 1;
        }
    }
    // Columns in order within each row (SciPy's canonical form; `has_sorted_indices`).
    for r in 0..n {
        let (a, b) = (count[r], count[r + 1]);
        let mut row: Vec<(i64, f64)> = indices[a..b].iter().copied().zip(data[a..b].iter().copied()).collect();
        row.sort_unstable_by_key(|x| x.0);
        for (k, (c, v)) in row.into_iter().enumerate() {
            indices[a + k] = c;
            data[a + k] = v;
        }
    }
    let le_i64 = |xs: &mut dyn Iterator<Item = i64>| xs.flat_map(i64::to_le_bytes).collect::<Vec<u8>>();
    let members: [(&str, Vec<u8>); 5] = [
        ("indices.npy", npy("<i8", &format!("({nnz},)"), &le_i64(&mut indices.iter().copied()))),
        ("indptr.npy", npy("<i8", &format!("({},)", n + 1), &le_i64(&mut count.iter().map(|&c| c as i64)))),
        ("format.npy", npy("<U3", "()", &"csr".chars().flat_map(|c| (c as u32).to_le_bytes()).collect::<Vec<u8>>())),
        ("shape.npy", npy("<i8", "(2,)", &le_i64(&mut [n as i64, n as i64].into_iter()))),
        ("data.npy", npy("<f8", &format!("({nnz},)"), &data.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>())),
    ];
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Stored)
        .large_file(members.iter().any(|m| m.1.len() >= u32::MAX as usize));
    for (name, bytes) in members {
        zip.start_file(name, options).map_err(|e| e.to_string())?;
        zip.write_all(&bytes).map_err(|e| e.to_string())?;
    }
    Ok(zip.finish().map_err(|e| e.to_string())?.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Read;

    /// [[2, -1, 0], [-1, 2, -1], [0, -1, 1]] as upper triplets.
    fn path3() -> Vec<f64> {
        vec![0., 0., 2., 0., 1., -1., 1., 1., 2., 1., 2., -1., 2., 2., 1.]
    }

    #[test]
    fn matrix_market_lists_the_lower_triangle_one_based() {
        let text = String::from_utf8(matrix_market(3, &path3(), "L").unwrap()).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], "%%MatrixMarket matrix coordinate real symmetric");
        assert_eq!(lines[1], "% L");
        assert_eq!(lines[2], "3 3 5");
        assert_eq!(lines[4], "2 1 -1e0");
        assert!(lines[3..].iter().all(|l| {
            let t: Vec<usize> = l.split(' ').take(2).map(|x| x.parse().unwrap()).collect();
            t[0] >= t[1] && t[1] >= 1
        }));
    }

    #[test]
    fn npz_holds_the_full_csr_matrix_scipy_reads() {
        let bytes = npz_csr(3, &path3()).unwrap();
        let mut z = zip::ZipArchive::new(std::io::Cursor::new(bytes)).unwrap();
        let mut member = |name: &str| {
            let mut f = z.by_name(name).unwrap();
            assert_eq!(f.compression(), zip::CompressionMethod::Stored);
            let mut b = vec![];
            f.read_to_end(&mut b).unwrap();
            let hlen = u16::from_le_bytes([b[8], b[9]]) as usize;
            (String::from_utf8(b[10..10 + hlen].to_vec()).unwrap(), b[10 + hlen..].to_vec())
        };
        let ints = |b: &[u8]| b.chunks(8).map(|c| i64::from_le_bytes(c.try_into().unwrap())).collect::<Vec<_>>();
        let (h, indptr) = member("indptr.npy");
        assert!(h.contains("'<i8'") && h.contains("(4,)"));
        assert_eq!(ints(&indptr), [0, 2, 5, 7]);
        assert_eq!(ints(&member("indices.npy").1), [0, 1, 0, 1, 2, 1, 2]);
        let data: Vec<f64> =
            member("data.npy").1.chunks(8).map(|c| f64::from_le_bytes(c.try_into().unwrap())).collect();
        assert_eq!(data, [2., -1., -1., 2., -1., -1., 1.]);
        assert_eq!(ints(&member("shape.npy").1), [3, 3]);
        let (h, s) = member("format.npy");
        assert!(h.contains("'<U3'") && h.contains("'shape': ()"));
        assert_eq!(s, b"c\0\0\0s\0\0\0r\0\0\0");
    }

    #[test]
    fn lower_triangle_or_out_of_range_triplets_are_refused() {
        assert!(npz_csr(3, &[1., 0., 1.]).is_err());
        assert!(matrix_market(2, &[0., 2., 1.], "").is_err());
        assert!(npz_csr(3, &[0., 1.]).is_err());
    }
}
