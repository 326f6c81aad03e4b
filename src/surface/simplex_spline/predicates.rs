//! Exact orientation signs and the symbolic perturbation of points on knot lines.

use glam::DVec2;

/// (a, b) -> (s, e) with s + e == a + b exactly (Knuth's two-sum).
#[inline]
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bb = s - a;
    (s, (a - (s - bb)) + (b - bb))
}

/// Exact sign of `sum a_i b_i` for finite inputs without overflow: every product becomes
/// two floats (the fused multiply-add gives the rounding error exactly) and the sum is
/// accumulated as a non-overlapping expansion, whose sign is that of its largest part.
fn exact_sign_of_products(terms: &[(f64, f64)]) -> i8 {
    let mut expansion = [0.0f64; 32];
    let mut len = 0usize;
    let mut grow = |b: f64| {
        let mut q = b;
        let mut out = 0usize;
        for i in 0..len {
            let (s, e) = two_sum(q, expansion[i]);
            if e != 0.0 {
                expansion[out] = e;
                out += 1;
            }
            q = s;
        }
        if q != 0.0 {
            expansion[out] = q;
            out += 1;
        }
        len = out;
    };
    for &(a, b) in terms {
        let hi = a * b;
        grow(hi);
        grow(a.mul_add(b, -hi));
    }
    match len {
        0 => 0,
        _ if expansion[len - 1] > 0.0 => 1,
        _ => -1,
    }
}

/// Sign of the orientation of (p, q, r): +1 counter-clockwise, -1 clockwise, 0 collinear,
/// exact (a float filter first, the exact expansion only near zero).
pub fn orient_sign(p: DVec2, q: DVec2, r: DVec2) -> i8 {
    let left = (q.x - p.x) * (r.y - p.y);
    let right = (q.y - p.y) * (r.x - p.x);
    if let Some(sign) = float_filtered_sign(left, right) {
        return sign;
    }
    exact_sign_of_products(&[
        (q.x, r.y),
        (-q.x, p.y),
        (-p.x, r.y),
        (-q.y, r.x),
        (q.y, p.x),
        (p.y, r.x),
    ])
}

/// The sign of `left - right` when floating point decides it (the difference clears the
/// rounding bound of the two products); `None` near zero, where only exact arithmetic can.
fn float_filtered_sign(left: f64, right: f64) -> Option<i8> {
    let det = left - right;
    let bound = 1e-15 * (left.abs() + right.abs());
    if det > bound {
        Some(1)
    } else if -det > bound {
        Some(-1)
    } else {
        None
    }
}

/// Exact sign of `(q - p) x d`.
fn cross_sign(p: DVec2, q: DVec2, d: DVec2) -> i8 {
    let left = (q.x - p.x) * d.y;
    let right = (q.y - p.y) * d.x;
    if let Some(sign) = float_filtered_sign(left, right) {
        return sign;
    }
    exact_sign_of_products(&[(q.x, d.y), (-p.x, d.y), (-q.y, d.x), (p.y, d.x)])
}

/// The side of line p -> q that the symbolic point `x + eps d + eps^2 (1,0) + eps^3 (0,1)`
/// lies on: +1 left, -1 right; never 0 for p != q.
pub fn perturbed_side(p: DVec2, q: DVec2, x: DVec2, d: DVec2) -> i8 {
    let s = orient_sign(p, q, x);
    if s != 0 {
        return s;
    }
    let s = cross_sign(p, q, d);
    if s != 0 {
        return s;
    }
    // (q - p) x (1, 0) = -(q.y - p.y); (q - p) x (0, 1) = q.x - p.x: signs of exact
    // differences are comparisons.
    match q.y.partial_cmp(&p.y) {
        Some(std::cmp::Ordering::Greater) => -1,
        Some(std::cmp::Ordering::Less) => 1,
        _ => {
            if q.x > p.x {
                1
            } else {
                -1
            }
        }
    }
}

/// Twice the signed area of (p, q, r) in floats.
#[inline]
pub fn det2(p: DVec2, q: DVec2, r: DVec2) -> f64 {
    (q - p).perp_dot(r - p)
}

/// Affine barycentric coordinates of a triangle: `lambda_j(x) = c[j][0] + c[j][1] x + c[j][2] y`.
pub fn barycentric_affine(w: [DVec2; 3]) -> [[f64; 3]; 3] {
    let d = det2(w[0], w[1], w[2]);
    let mut c = [[0.0; 3]; 3];
    for (j, cj) in c.iter_mut().enumerate() {
        let (p, q) = (w[(j + 1) % 3], w[(j + 2) % 3]);
        // orient(x, p, q) = p x q + x x (p - q), linear in x.
        *cj = [p.perp_dot(q) / d, (p.y - q.y) / d, -(p.x - q.x) / d];
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_orientation_is_consistent_where_floats_are_not() {
        let p = DVec2::new(0.1, 0.1);
        let q = DVec2::new(0.3, 0.3);
        let r = DVec2::new(0.7, 0.7);
        assert_eq!(orient_sign(p, q, r), 0);
        let above = DVec2::new(0.7, f64::from_bits(0.7f64.to_bits() + 1));
        assert_eq!(orient_sign(p, q, above), 1);
        assert_eq!(orient_sign(q, p, above), -1);
        // Points rounded onto a line: an exact sign is the same for every order of the
        // three points (up to the permutation's parity); float determinants disagree.
        let (a, b) = (DVec2::new(0.13, 0.71), DVec2::new(12.3, -4.1));
        for k in 1..200 {
            let c = a + (b - a) * (k as f64 * 0.0173);
            let s = orient_sign(a, b, c);
            assert_eq!(orient_sign(b, c, a), s);
            assert_eq!(orient_sign(c, a, b), s);
            assert_eq!(orient_sign(b, a, c), -s);
            assert_eq!(orient_sign(a, c, b), -s);
        }
        // A point on the line is put on the side the perturbation points to, antisymmetrically.
        let d = DVec2::new(-1.0, 1.0);
        assert_eq!(perturbed_side(p, q, r, d), 1);
        assert_eq!(perturbed_side(q, p, r, d), -1);
    }
}
