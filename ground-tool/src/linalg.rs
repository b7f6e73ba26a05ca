//! Small dense linear-algebra helpers shared by the estimators.
//!
//! Why a module: every estimator needs the same three things (a checked SPD inverse, a
//! pseudo-inverse for rank-deficient within-epoch covariances, and sorted symmetric
//! eigen-decompositions for observability reports); doing them once keeps the tolerances in
//! one place.

use nalgebra::{DMatrix, DVector};

/// Inverse of a symmetric positive-definite matrix by Cholesky; `None` if it is not SPD.
#[must_use]
pub fn spd_inverse(m: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    if m.iter().any(|x| !x.is_finite()) {
        return None;
    }
    let sym = (m + m.transpose()) * 0.5;
    sym.cholesky().map(|c| c.inverse())
}

/// Symmetric eigen-decomposition with eigenvalues in ascending order (columns of the returned
/// matrix are the matching unit eigenvectors).
#[must_use]
pub fn sym_eigen_ascending(m: &DMatrix<f64>) -> (DVector<f64>, DMatrix<f64>) {
    let sym = (m + m.transpose()) * 0.5;
    let n = sym.nrows();
    let eig = sym.symmetric_eigen();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    let values = DVector::from_iterator(n, order.iter().map(|&k| eig.eigenvalues[k]));
    let mut vectors = DMatrix::zeros(n, n);
    for (col, &k) in order.iter().enumerate() {
        vectors.set_column(col, &eig.eigenvectors.column(k));
    }
    (values, vectors)
}

/// Pseudo-inverse of a symmetric positive semi-definite matrix: eigenvalues below
/// `rel_tol * λ_max` are treated as zero. Returns the inverse and the rank kept.
#[must_use]
pub fn sym_pinv(m: &DMatrix<f64>, rel_tol: f64) -> (DMatrix<f64>, usize) {
    // (nalgebra's eigen-decomposition panics on an empty matrix.)
    if m.nrows() == 0 || !m.is_square() {
        return (DMatrix::zeros(m.ncols(), m.nrows()), 0);
    }
    let (values, vectors) = sym_eigen_ascending(m);
    let n = m.nrows();
    let max = values.iter().fold(0.0_f64, |a, &v| a.max(v));
    let mut out = DMatrix::zeros(n, n);
    let mut rank = 0;
    if max <= 0.0 || !max.is_finite() {
        return (out, 0);
    }
    for k in 0..n {
        let lambda = values[k];
        if lambda > rel_tol * max {
            rank += 1;
            let v = vectors.column(k);
            out += v * v.transpose() / lambda;
        }
    }
    (out, rank)
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;

    #[test]
    fn eigen_sorted_and_pinv() {
        let m = DMatrix::from_row_slice(3, 3, &[2.0, 1.0, 0.0, 1.0, 2.0, 0.0, 0.0, 0.0, 0.0]);
        let (values, _) = sym_eigen_ascending(&m);
        assert!(values[0].abs() < 1e-12 && (values[1] - 1.0).abs() < 1e-12);
        assert!((values[2] - 3.0).abs() < 1e-12);
        let (p, rank) = sym_pinv(&m, 1e-12);
        assert_eq!(rank, 2);
        let back = &m * &p * &m;
        assert!((back - &m).norm() < 1e-12);
        assert!(spd_inverse(&m).is_none());
    }

    /// An empty comparison (no star both halves determine) has rank 0, not a panic.
    #[test]
    fn pinv_of_an_empty_matrix_is_empty() {
        let (p, rank) = sym_pinv(&DMatrix::zeros(0, 0), 1e-9);
        assert_eq!((p.nrows(), p.ncols(), rank), (0, 0, 0));
    }
}
