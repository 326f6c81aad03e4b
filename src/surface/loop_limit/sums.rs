//! Exact column sums of basis rows formed through deep subdivision.

/// Rounding leaves the column sums a few ulps of the largest intermediate term off their
/// exact values (1 for the value, 0 for derivatives, which are 2^depth times larger near an
/// irregular vertex). The residual is spread over the entries in proportion to their
/// size, which keeps the rows exactly affine invariant without moving any weight by more
/// than its rounding.
pub(super) fn restore_sums(acc: &mut [[f64; 6]]) {
    for d in 0..6 {
        let target = if d == 0 { 1.0 } else { 0.0 };
        let (sum, size) = acc
            .iter()
            .fold((0.0, 0.0), |(s, a), w| (s + w[d], a + w[d].abs()));
        if size > 0.0 {
            let r = (sum - target) / size;
            for w in acc.iter_mut() {
                w[d] -= r * w[d].abs();
            }
        }
    }
}

/// `restore_sums` for one column with target `target`.
pub(super) fn restore_sum(col: &mut [f64], target: f64) {
    let (sum, size) = col
        .iter()
        .fold((0.0, 0.0), |(s, a), w| (s + w, a + w.abs()));
    if size > 0.0 {
        let r = (sum - target) / size;
        for w in col.iter_mut() {
            *w -= r * w.abs();
        }
    }
}
