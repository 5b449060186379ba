//! Between the input file's vertex numbering and the validated shape's: requests name input vertices and
//! per-vertex outputs are given in input rows (welded input vertices share their value; vertices validation
//! dropped get NaN), while operators work on the validated vertices.

use super::validate::Validated;
use faer::MatRef;

impl Validated {
    /// The columns of `m` (one value per validated vertex, or per unknown: `expand` maps a column to one value per
    /// validated vertex, e.g. `Operator::expand` after Dirichlet elimination) as a row-major array of input rows ×
    /// columns, NaN where validation dropped the vertex.
    pub fn to_input_rows(&self, m: MatRef<'_, f64>, expand: impl Fn(&[f64]) -> Vec<f64>) -> Vec<f64> {
        let cols = m.ncols();
        let mut data = vec![f64::NAN; self.vertex_map.len() * cols];
        for j in 0..cols {
            let col: Vec<f64> = m.col(j).iter().copied().collect();
            let full = expand(&col);
            for (input, &mapped) in self.vertex_map.iter().enumerate() {
                if mapped != u32::MAX {
                    data[input * cols + j] = full[mapped as usize];
                }
            }
        }
        data
    }

    /// Column `col` of a row-major array of input rows × `cols` as one value per validated vertex (the first input
    /// vertex of each validated one gives its value; NaN where none does).
    pub fn from_input_rows(&self, data: &[f64], cols: usize, col: usize) -> Vec<f64> {
        let mut out = vec![f64::NAN; self.shape.vertex_count()];
        for (input, &m) in self.vertex_map.iter().enumerate() {
            if m != u32::MAX && out[m as usize].is_nan() {
                out[m as usize] = data[input * cols + col];
            }
        }
        out
    }
}
