//! STEP AP214 export: the text read back by a minimal ISO 10303-21 parser of the test's
//! own (entity count, knot vectors, control points, units).

use glam::DVec3;
use std::collections::BTreeMap;
use trispline::bspline::BSplineSurface;
use trispline::io::iges::IgesUnits;
use trispline::io::step::{step_bytes, StepOptions};

/// `#n=TEXT;` instances of the DATA section, by number.
fn instances(text: &str) -> BTreeMap<usize, String> {
    let data = text
        .split_once("DATA;\n")
        .and_then(|(_, rest)| rest.split_once("ENDSEC;"))
        .map(|(d, _)| d)
        .expect("a DATA section");
    data.split(";\n")
        .filter(|s| !s.trim().is_empty())
        .map(|s| {
            let (id, body) = s.trim().split_once('=').expect("#n=...");
            (
                id.trim_start_matches('#').parse().expect("number"),
                body.to_string(),
            )
        })
        .collect()
}

/// The top-level comma-separated parameters inside the outermost parentheses of `body`.
fn params(body: &str) -> Vec<String> {
    let start = body.find('(').expect("(");
    let inner = &body[start + 1..body.rfind(')').expect(")")];
    let (mut out, mut depth, mut cur) = (Vec::new(), 0, String::new());
    for c in inner.chars() {
        match c {
            '(' => depth += 1,
            ')' => depth -= 1,
            ',' if depth == 0 => {
                out.push(std::mem::take(&mut cur));
                continue;
            }
            _ => {}
        }
        cur.push(c);
    }
    out.push(cur);
    out
}

fn list(p: &str) -> Vec<String> {
    params(p).into_iter().filter(|s| !s.is_empty()).collect()
}

fn point(body: &str) -> DVec3 {
    let c: Vec<f64> = list(&params(body)[1])
        .iter()
        .map(|x| x.parse().expect("real"))
        .collect();
    DVec3::new(c[0], c[1], c[2])
}

fn test_surface(shift: f64) -> BSplineSurface {
    let (nu, nv) = (5, 4);
    let controls: Vec<DVec3> = (0..nu)
        .flat_map(|i| {
            (0..nv).map(move |j| {
                DVec3::new(
                    i as f64 * 0.1 + shift,
                    j as f64 * 0.013,
                    (i * j) as f64 * 1e-3 / 3.0,
                )
            })
        })
        .collect();
    BSplineSurface::new(
        (3, 2),
        vec![0.0, 0.0, 0.0, 0.0, 0.37, 1.0, 1.0, 1.0, 1.0],
        vec![0.0, 0.0, 0.0, 0.5, 1.0, 1.0, 1.0],
        (nu, nv),
        controls,
    )
    .expect("valid surface")
}

#[test]
fn step_text_round_trips_entities_knots_and_control_points() {
    let surfaces = [test_surface(0.0), test_surface(2.0)];
    let bytes = step_bytes(&[&surfaces[0], &surfaces[1]], &StepOptions::default());
    let text = String::from_utf8(bytes).expect("ASCII");
    assert!(text.starts_with("ISO-10303-21;\nHEADER;"));
    assert!(text.contains("FILE_SCHEMA(('AUTOMOTIVE_DESIGN"));
    assert!(text.ends_with("END-ISO-10303-21;\n"));
    let inst = instances(&text);
    // Numbered 1..=n without gaps, every reference resolving.
    assert_eq!(
        inst.keys().copied().collect::<Vec<_>>(),
        (1..=inst.len()).collect::<Vec<_>>()
    );
    for body in inst.values() {
        for r in body.split('#').skip(1) {
            let n: usize = r
                .chars()
                .take_while(char::is_ascii_digit)
                .collect::<String>()
                .parse()
                .expect("reference");
            assert!(inst.contains_key(&n), "dangling #{n} in {body}");
        }
    }
    let kinds = |name: &str| inst.values().filter(|b| b.starts_with(name)).count();
    // 18 context/product/unit/placement instances, 20 control points per surface.
    assert_eq!(kinds("B_SPLINE_SURFACE_WITH_KNOTS("), 2);
    assert_eq!(kinds("CARTESIAN_POINT("), 1 + 2 * 20);
    assert_eq!(kinds("GEOMETRIC_SET("), 1);
    assert_eq!(kinds("SHAPE_DEFINITION_REPRESENTATION("), 1);
    assert_eq!(inst.len(), 18 + 2 * 21 + 3);
    assert!(text.contains("SI_UNIT($,.METRE.)"));

    let written: Vec<&String> = inst
        .values()
        .filter(|b| b.starts_with("B_SPLINE_SURFACE_WITH_KNOTS("))
        .collect();
    for (body, s) in written.iter().zip(&surfaces) {
        let p = params(body);
        assert_eq!(
            (p[1].parse::<usize>().ok(), p[2].parse::<usize>().ok()),
            (Some(3), Some(2))
        );
        let rows = list(&p[3]);
        assert_eq!(rows.len(), 5);
        for (i, row) in rows.iter().enumerate() {
            let refs = list(row);
            assert_eq!(refs.len(), 4);
            for (j, r) in refs.iter().enumerate() {
                let id: usize = r.trim_start_matches('#').parse().expect("ref");
                assert_eq!(
                    point(&inst[&id]),
                    s.controls()[i * 4 + j],
                    "control ({i}, {j})"
                );
            }
        }
        let expand = |mults: &str, knots: &str| -> Vec<f64> {
            list(mults)
                .iter()
                .zip(list(knots))
                .flat_map(|(m, k)| {
                    std::iter::repeat_n(k.parse::<f64>().expect("knot"), m.parse().expect("mult"))
                })
                .collect()
        };
        assert_eq!(expand(&p[8], &p[10]), s.knots_u());
        assert_eq!(expand(&p[9], &p[11]), s.knots_v());
    }
}

#[test]
fn step_declares_the_chosen_length_unit() {
    let s = test_surface(0.0);
    let text = |units| {
        String::from_utf8(step_bytes(
            &[&s],
            &StepOptions {
                units,
                ..Default::default()
            },
        ))
        .expect("ASCII")
    };
    assert!(text(IgesUnits::Mm).contains("SI_UNIT(.MILLI.,.METRE.)"));
    let inch = text(IgesUnits::In);
    assert!(
        inch.contains("CONVERSION_BASED_UNIT('INCH',") && inch.contains("LENGTH_MEASURE(2.54E-2)")
    );
}

#[test]
fn unit_size_warnings_flag_factor_thousand_mismatches_only() {
    // A 20 cm scan in metres is plausible; the same numbers declared mm are 0.2 mm.
    assert_eq!(IgesUnits::M.size_warning(0.2), None);
    let w = IgesUnits::Mm.size_warning(0.2).expect("0.2 mm object");
    assert!(w.contains("--units m"), "{w}");
    assert_eq!(IgesUnits::Mm.size_warning(200.0), None);
    let w = IgesUnits::M.size_warning(200.0).expect("200 m object");
    assert!(w.contains("--units mm"), "{w}");
}
