//! The assembled normal matrices against dense normal equations built from the same rows.

use super::*;
use nalgebra::{DMatrix, DVector};

fn dense(n: &Csr) -> DMatrix<f64> {
    let mut a = DMatrix::zeros(n.nrows, n.ncols);
    for r in 0..n.nrows {
        for k in n.row_ptr[r]..n.row_ptr[r + 1] {
            a[(r, n.col_idx[k] as usize)] += n.values[k];
        }
    }
    a
}

fn to_dense(m: &ScalarMatrix) -> DMatrix<f64> {
    let size = m.rhs.len();
    let mut d = DMatrix::zeros(size, size);
    for c in 0..size {
        for k in m.ptr[c]..m.ptr[c + 1] {
            d[(c, m.idx[k] as usize)] = m.entries[k][0];
        }
    }
    d
}

/// Rows repeating a few column patterns (one given in a different order, one with a
/// repeated column), weights varying per row, a fairness term: M, b and both solvers
/// against dense normal equations.
#[test]
fn scalar_assembly_and_solves_match_dense_normal_equations() {
    let m = 10;
    let patterns: [&[u32]; 4] = [&[0, 1, 2, 5], &[5, 2, 1, 0], &[3, 4, 4, 9], &[6, 7, 8]];
    let rows: Vec<Vec<(u32, f64)>> = (0..300)
        .map(|j| {
            let pat = patterns[j % 4];
            pat.iter()
                .enumerate()
                .map(|(k, &c)| (c, 0.1 + ((j * 7 + k * 3) % 11) as f64 * 0.05))
                .collect()
        })
        .collect();
    let n = Csr::from_rows(m, rows.iter().map(|r| r.as_slice()));
    let l = crate::fit::csr::ring_laplacian(m, 9);
    let lt = l.transpose();
    let s = 0.3;
    let fair = Some(Fairness {
        l: &l,
        lt: &lt,
        smoothing: s,
    });
    let data: Vec<DVec3> = (0..300)
        .map(|j| DVec3::new((j as f64 * 0.37).sin(), j as f64 * 0.01, (j % 13) as f64))
        .collect();
    let full = ScalarMatrix::assemble(&n, &data, fair, false);
    let (a, ld) = (dense(&n), dense(&l));
    let want = a.transpose() * &a + (ld.transpose() * &ld) * s;
    let got = to_dense(&full);
    assert!(
        (&got - &want).amax() < 1e-12 * want.amax(),
        "{got} vs {want}"
    );
    for axis in 0..3 {
        let p = DVector::from_iterator(300, data.iter().map(|d| d[axis]));
        let b = a.transpose() * &p;
        let x = want.clone().cholesky().expect("definite").solve(&b);
        let (pcg, steps) = full.solve_pcg(vec![DVec3::ZERO; m], 200, 1e-14);
        let direct = ScalarMatrix::assemble(&n, &data, fair, true)
            .solve_direct()
            .expect("definite");
        assert!(steps < 200);
        for c in 0..m {
            assert!((full.rhs[c][axis] - b[c]).abs() < 1e-12 * b.amax().max(1.0));
            assert!(
                (pcg[c][axis] - x[c]).abs() < 1e-9,
                "{} vs {}",
                pcg[c][axis],
                x[c]
            );
            assert!((direct[c][axis] - x[c]).abs() < 1e-10);
        }
    }
}

/// One pattern shared by enough rows to be summed in parallel chunks (a single Bezier
/// patch), with normals, tangential shares and curvature terms: the blocks against the
/// dense 3m x 3m matrix.
#[test]
fn one_large_pattern_summed_in_parallel_matches_dense_blocks() {
    let m = 40;
    let rows_count = 3000;
    let rows: Vec<Vec<(u32, f64)>> = (0..rows_count)
        .map(|j| {
            (0..m as u32)
                .map(|c| (c, 1.0 + ((j * 31 + c as usize * 17) % 23) as f64 / 23.0))
                .collect()
        })
        .collect();
    assert!(rows_count * packed_len(m) >= PARALLEL_PATTERN_WORK);
    let n = Csr::from_rows(m, rows.iter().map(|r| r.as_slice()));
    let data: Vec<DVec3> = (0..rows_count)
        .map(|j| DVec3::new(j as f64, (j as f64).cos(), 1.0))
        .collect();
    let normals: Vec<DVec3> = (0..rows_count)
        .map(|j| DVec3::new((j as f64).sin(), 0.5, 1.0).normalize())
        .collect();
    // Each row its own tangential share, as near and far from the data's edges.
    let t: Vec<f64> = (0..rows_count).map(|j| [0.005, 0.05][j % 2]).collect();
    // A curvature term along one tangent, of a weight varying with the row (none on every
    // third), and none past the first 2000 rows (the rows of surface samples).
    let tangent = |j: usize| normals[j].cross(DVec3::X).normalize();
    let curvature: Vec<[f64; 6]> = (0..2000)
        .map(|j| crate::numeric::packed_outer(tangent(j), 0.01 * (j % 3) as f64))
        .collect();
    let blocks = BlockMatrix::assemble(&n, &data, &normals, (&t, Some(&curvature)), None, false);
    let mut want = DMatrix::<f64>::zeros(3 * m, 3 * m);
    let mut rhs = DVector::<f64>::zeros(3 * m);
    for (j, row) in rows.iter().enumerate() {
        let q = normals[j];
        let mut w = DMat3::from_cols(q * q.x, q * q.y, q * q.z) + DMat3::IDENTITY * t[j];
        if j < curvature.len() {
            let (e, k) = (tangent(j), 0.01 * (j % 3) as f64);
            w += DMat3::from_cols(e * e.x, e * e.y, e * e.z) * k;
        }
        let wp = w * data[j];
        for &(a, wa) in row {
            for r in 0..3 {
                rhs[3 * a as usize + r] += wa * wp[r];
            }
            for &(b, wb) in row {
                for r in 0..3 {
                    for c in 0..3 {
                        want[(3 * a as usize + r, 3 * b as usize + c)] += wa * wb * w.col(c)[r];
                    }
                }
            }
        }
    }
    let scale = want.amax();
    for c in 0..m {
        assert_eq!(blocks.ptr[c + 1] - blocks.ptr[c], m, "every pair present");
        for k in blocks.ptr[c]..blocks.ptr[c + 1] {
            let j = blocks.idx[k] as usize;
            let b = BlockMatrix::block(&blocks.entries[k]);
            for r in 0..3 {
                for q in 0..3 {
                    let d = (b[3 * r + q] - want[(3 * c + r, 3 * j + q)]).abs();
                    assert!(d < 1e-11 * scale, "block ({c},{j}) [{r},{q}] off by {d}");
                }
            }
        }
        for r in 0..3 {
            assert!((blocks.rhs[c][r] - rhs[3 * c + r]).abs() < 1e-11 * rhs.amax());
        }
    }
}
