//! IGES output read back by a small independent parser: record layout, section counts,
//! directory/parameter pointers, and the entity 128/126 parameters against the geometry.

use trispline::bspline::fit::{interpolate_curve, Grid, GridMethod};
use trispline::bspline::{basis::ParamMethod, fit::fit_grid, BSplineCurve, BSplineSurface};
use trispline::io::iges::{iges_bytes, IgesOptions};
use trispline::DVec3;

struct Parsed {
    /// (entity type, parameter values as text) per directory entry, in order.
    entities: Vec<(u32, Vec<String>)>,
    global: String,
}

fn parse(bytes: &[u8]) -> Parsed {
    let text = std::str::from_utf8(bytes).expect("ascii");
    let mut sections: std::collections::BTreeMap<char, Vec<&str>> = Default::default();
    let mut order = Vec::new();
    for (k, line) in text.lines().enumerate() {
        assert_eq!(line.len(), 80, "line {k} is {} columns", line.len());
        let letter = line.as_bytes()[72] as char;
        let seq: usize = line[73..].trim().parse().expect("sequence number");
        let lines = sections.entry(letter).or_default();
        assert_eq!(
            seq,
            lines.len() + 1,
            "section {letter} sequence at line {k}"
        );
        lines.push(line);
        if order.last() != Some(&letter) {
            order.push(letter);
        }
    }
    assert_eq!(order, vec!['S', 'G', 'D', 'P', 'T'], "section order");
    let t = sections[&'T'][0];
    let count = |c: char| sections.get(&c).map_or(0, Vec::len);
    assert_eq!(
        &t[..32],
        format!(
            "S{:>7}G{:>7}D{:>7}P{:>7}",
            count('S'),
            count('G'),
            count('D'),
            count('P')
        )
    );
    let d = &sections[&'D'];
    assert_eq!(d.len() % 2, 0);
    let p = &sections[&'P'];
    let field = |l: &str, i: usize| l[i * 8..i * 8 + 8].trim().to_string();
    let mut entities = Vec::new();
    let mut next_p = 1;
    for (k, pair) in d.chunks(2).enumerate() {
        let kind: u32 = field(pair[0], 0).parse().expect("type");
        assert_eq!(field(pair[1], 0), field(pair[0], 0));
        let first: usize = field(pair[0], 1).parse().expect("pointer");
        let n: usize = field(pair[1], 3).parse().expect("line count");
        assert_eq!(first, next_p, "parameter data pointer of entity {k}");
        next_p += n;
        let mut data = String::new();
        for line in &p[first - 1..first - 1 + n] {
            let de: usize = line[65..72].trim().parse().expect("DE pointer");
            assert_eq!(de, 2 * k + 1, "back pointer");
            data.push_str(&line[..64]);
        }
        let data = data.trim_end();
        assert!(data.ends_with(';'), "record terminator");
        let values: Vec<String> = data[..data.len() - 1]
            .split(',')
            .map(|s| s.trim().to_string())
            .collect();
        assert_eq!(values[0], kind.to_string());
        entities.push((kind, values));
    }
    assert_eq!(
        next_p,
        p.len() + 1,
        "every parameter line belongs to an entity"
    );
    let global = sections[&'G'].iter().map(|l| &l[..72]).collect();
    Parsed { entities, global }
}

fn num(s: &str) -> f64 {
    s.replace('D', "E").parse().expect("number")
}

fn check_surface(vals: &[String], s: &BSplineSurface) {
    let (p, q) = s.degrees();
    let (nu, nv) = s.counts();
    let ints: Vec<usize> = vals[1..10]
        .iter()
        .map(|x| x.parse().expect("int"))
        .collect();
    assert_eq!(ints, vec![nu - 1, nv - 1, p, q, 0, 0, 1, 0, 0]);
    let mut k = 10;
    let mut take = |n: usize| {
        let v: Vec<f64> = vals[k..k + n].iter().map(|x| num(x)).collect();
        k += n;
        v
    };
    assert_eq!(take(nu + p + 1), s.knots_u());
    assert_eq!(take(nv + q + 1), s.knots_v());
    assert!(take(nu * nv).iter().all(|&w| w == 1.0));
    let c = take(3 * nu * nv);
    for j in 0..nv {
        for i in 0..nu {
            let b = 3 * (j * nu + i);
            assert_eq!(
                DVec3::new(c[b], c[b + 1], c[b + 2]),
                s.controls()[i * nv + j]
            );
        }
    }
    let ((u0, u1), (v0, v1)) = s.domain();
    assert_eq!(take(4), vec![u0, u1, v0, v1]);
    assert_eq!(k, vals.len(), "no trailing parameters");
}

fn check_curve(vals: &[String], c: &BSplineCurve) {
    let n = c.controls().len();
    let p = c.degree();
    let ints: Vec<usize> = vals[1..7].iter().map(|x| x.parse().expect("int")).collect();
    assert_eq!(ints, vec![n - 1, p, 0, 0, 1, 0]);
    let f: Vec<f64> = vals[7..].iter().map(|x| num(x)).collect();
    assert_eq!(&f[..n + p + 1], c.knots());
    assert!(f[n + p + 1..2 * n + p + 1].iter().all(|&w| w == 1.0));
    for i in 0..n {
        let b = 2 * n + p + 1 + 3 * i;
        assert_eq!(DVec3::new(f[b], f[b + 1], f[b + 2]), c.controls()[i]);
    }
    assert_eq!(f.len(), 2 * n + p + 1 + 3 * n + 2 + 3);
}

#[test]
fn surfaces_and_curves_round_trip() {
    let (rows, cols) = (17, 23);
    let pts: Vec<DVec3> = (0..rows * cols)
        .map(|k| {
            let (x, y) = ((k / cols) as f64 * 1.7, (k % cols) as f64 * 0.9 - 4.0);
            DVec3::new(x, y, (x * 0.3).sin() * 12.5 + y * y * 0.01 - 1234.5)
        })
        .collect();
    let grid = Grid {
        rows,
        cols,
        points: &pts,
    };
    let s1 = fit_grid(
        &grid,
        (9, 11),
        (3, 2),
        ParamMethod::ChordLength,
        GridMethod::Lsq,
    )
    .expect("fit")
    .surface;
    let s2 = fit_grid(
        &grid,
        (5, 4),
        (1, 3),
        ParamMethod::Centripetal,
        GridMethod::TwoPass,
    )
    .expect("fit")
    .surface;
    let helix: Vec<DVec3> = (0..40)
        .map(|k| {
            DVec3::new(
                (k as f64 * 0.3).cos(),
                (k as f64 * 0.3).sin(),
                k as f64 * 1e-3,
            )
        })
        .collect();
    let c1 = interpolate_curve(&helix, 3, ParamMethod::ChordLength)
        .expect("fit")
        .curve;
    let c2 =
        BSplineCurve::new(1, vec![0.0, 0.0, 0.25, 1.0, 1.0], helix[..3].to_vec()).expect("valid");
    let bytes = iges_bytes(&[&s1, &s2], &[&c1, &c2], &IgesOptions::default());
    let parsed = parse(&bytes);
    let kinds: Vec<u32> = parsed.entities.iter().map(|e| e.0).collect();
    assert_eq!(kinds, vec![128, 128, 126, 126]);
    check_surface(&parsed.entities[0].1, &s1);
    check_surface(&parsed.entities[1].1, &s2);
    check_curve(&parsed.entities[2].1, &c1);
    check_curve(&parsed.entities[3].1, &c2);
    assert!(parsed.global.starts_with("1H,,1H;,"));
    assert!(
        parsed.global.contains(",2,2HMM,"),
        "millimetre unit flag and name"
    );
}
