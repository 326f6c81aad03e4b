//! The collocation operator: how the surface's control points reach the data parameters.
//! Shared by the exact-connectivity path and the scan path.

use crate::fit::{Collocation, Csr};
use crate::surface::{SurfaceParam, TriSurface};
use rayon::prelude::*;

/// The collocation operator of `params` on `surface`: matrix-free for a Bezier patch
/// sampled on lattice rows, otherwise the sparse matrix (rows built in parallel).
pub fn collocation(surface: &dyn TriSurface, params: &[SurfaceParam]) -> Collocation {
    let matrix = || collocation_rows(surface, params);
    match surface.as_bezier() {
        Some(b) => Collocation::bezier(b.degree, params, matrix),
        None => Collocation::new(matrix()),
    }
}

/// The collocation rows at `params` as a stored matrix (no transpose), built in parallel
/// chunks with one row buffer per chunk.
pub(crate) fn collocation_rows(surface: &dyn TriSurface, params: &[SurfaceParam]) -> Csr {
    const CHUNK: usize = 4096;
    let parts: Vec<(Vec<usize>, Vec<u32>, Vec<f64>)> = params
        .par_chunks(CHUNK)
        .map(|chunk| {
            let mut row = Vec::new();
            let (mut lens, mut cols, mut vals) =
                (Vec::with_capacity(chunk.len()), Vec::new(), Vec::new());
            for p in chunk {
                surface.basis_row(*p, &mut row);
                let before = cols.len();
                for &(c, w) in &row {
                    if w != 0.0 {
                        cols.push(c);
                        vals.push(w);
                    }
                }
                lens.push(cols.len() - before);
            }
            (lens, cols, vals)
        })
        .collect();
    let nnz = parts.iter().map(|p| p.1.len()).sum();
    let mut m = Csr {
        nrows: params.len(),
        ncols: surface.control_count(),
        row_ptr: Vec::with_capacity(params.len() + 1),
        col_idx: Vec::with_capacity(nnz),
        values: Vec::with_capacity(nnz),
    };
    m.row_ptr.push(0);
    for (lens, cols, vals) in parts {
        for len in lens {
            let last = *m.row_ptr.last().unwrap_or(&0);
            m.row_ptr.push(last + len);
        }
        m.col_idx.extend(cols);
        m.values.extend(vals);
    }
    m
}
