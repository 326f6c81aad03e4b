//! Small f64 kernels the matrix-free operators share, written so that the compiler can
//! keep them in vector registers. `F` selects fused multiply-add: callers monomorphise
//! once for a CPU with FMA (behind `wide()`) and once without, since `mul_add` without
//! the instruction is a slow library call.

/// a * b + c, fused only when the caller was compiled for FMA (without the instruction
/// `mul_add` is a slow library call).
#[inline(always)]
pub(crate) fn madd<const F: bool>(a: f64, b: f64, c: f64) -> f64 {
    if F {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// y += a x.
#[inline(always)]
pub(crate) fn axpy<const F: bool>(a: f64, x: &[f64], y: &mut [f64]) {
    y.iter_mut()
        .zip(x)
        .for_each(|(y, x)| *y = madd::<F>(a, *x, *y));
}

/// Eight-accumulator dot product: lets the compiler use vector registers for a reduction
/// it may not reorder on its own.
#[inline(always)]
pub(crate) fn dot<const F: bool>(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for k in 0..8 {
            acc[k] = madd::<F>(x[k], y[k], acc[k]);
        }
    }
    let tail: f64 = ra.iter().zip(rb).map(|(x, y)| x * y).sum();
    let half = [
        acc[0] + acc[4],
        acc[1] + acc[5],
        acc[2] + acc[6],
        acc[3] + acc[7],
    ];
    (half[0] + half[1]) + (half[2] + half[3]) + tail
}

/// ys[l] += a[l] x for three lanes in one pass over x (x is the large operand).
#[inline(always)]
pub(crate) fn axpy3<const F: bool>(a: [f64; 3], x: &[f64], ys: &mut [f64]) {
    let len = x.len();
    let (y0, rest) = ys.split_at_mut(len);
    let (y1, y2) = rest.split_at_mut(len);
    for (((x, y0), y1), y2) in x.iter().zip(y0).zip(y1).zip(y2) {
        *y0 = madd::<F>(a[0], *x, *y0);
        *y1 = madd::<F>(a[1], *x, *y1);
        *y2 = madd::<F>(a[2], *x, *y2);
    }
}

/// Three dot products against one shared operand `a`, in one pass over it.
#[inline(always)]
pub(crate) fn dot3<const F: bool>(a: &[f64], ys: &[f64]) -> [f64; 3] {
    let len = a.len();
    let (y0, rest) = ys.split_at(len);
    let (y1, y2) = rest.split_at(len);
    let mut acc = [[0.0; 4]; 3];
    let chunks = len / 4;
    let quads = a
        .chunks_exact(4)
        .zip(y0.chunks_exact(4))
        .zip(y1.chunks_exact(4).zip(y2.chunks_exact(4)));
    for ((a, y0), (y1, y2)) in quads {
        for (k, &ak) in a.iter().enumerate() {
            acc[0][k] = madd::<F>(ak, y0[k], acc[0][k]);
            acc[1][k] = madd::<F>(ak, y1[k], acc[1][k]);
            acc[2][k] = madd::<F>(ak, y2[k], acc[2][k]);
        }
    }
    let mut out = [0.0; 3];
    for (l, y) in [y0, y1, y2].into_iter().enumerate() {
        let tail: f64 = (4 * chunks..len).map(|p| a[p] * y[p]).sum();
        out[l] = (acc[l][0] + acc[l][1]) + (acc[l][2] + acc[l][3]) + tail;
    }
    out
}

/// Whether this CPU has AVX2 and FMA (checked once; the answer cannot change).
pub(crate) fn wide() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        static WIDE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
        *WIDE.get_or_init(|| is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma"))
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}
