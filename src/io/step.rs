//! STEP AP214 (ISO 10303-21 clear text) writer for B-spline surfaces.
//!
//! The surfaces go into a `GEOMETRIC_SET` of a
//! `GEOMETRICALLY_BOUNDED_SURFACE_SHAPE_REPRESENTATION`, attached to a minimal product
//! structure (application context, product, definition, shape) so that CAD readers find a
//! part to import. A geometric set needs no topology: a reader makes each surface one face
//! bounded by its parameter domain, which is exactly what a fitted patch is. Boundary
//! representations (edges, loops, shells) would add nothing but entities to get wrong.
//!
//! The length unit is declared in the representation context (`SI_UNIT` metre or
//! millimetre, or the inch as a `CONVERSION_BASED_UNIT`); coordinates are written as given.

use super::iges::{civil_utc, real, IgesUnits};
use crate::bspline::BSplineSurface;
use glam::DVec3;
use std::collections::HashMap;
use std::fmt::Write as _;
use std::time::SystemTime;

#[derive(Clone, Debug)]
/// What goes into a STEP file's header and context.
pub struct StepOptions {
    /// The length unit the coordinates are in (written unscaled).
    pub units: IgesUnits,
    /// The header's file name and the product's name.
    pub file_name: String,
    /// Generation time; `None` writes the Unix epoch (reproducible output for tests).
    pub time: Option<SystemTime>,
}

impl Default for StepOptions {
    fn default() -> Self {
        Self {
            units: IgesUnits::M,
            file_name: "surface.stp".into(),
            time: None,
        }
    }
}

/// Numbered entity instances, written `#n=TEXT;` in order.
struct Data {
    lines: Vec<String>,
    /// Control points written so far, by their coordinates' bits: surfaces that share a
    /// point (a patchwork's edges, a degenerate side's repeated corner) share its instance,
    /// which keeps a patchwork's file about 40 % smaller.
    points: HashMap<[u64; 3], String>,
}

impl Data {
    /// Adds an instance and returns its reference (`#n`).
    fn add(&mut self, text: String) -> String {
        self.lines.push(text);
        format!("#{}", self.lines.len())
    }

    /// The `CARTESIAN_POINT` instance of `c`, added the first time it is asked for.
    fn point(&mut self, c: DVec3) -> String {
        let key = [c.x.to_bits(), c.y.to_bits(), c.z.to_bits()];
        if let Some(reference) = self.points.get(&key) {
            return reference.clone();
        }
        let reference = self.add(format!(
            "CARTESIAN_POINT('',({},{},{}))",
            real(c.x),
            real(c.y),
            real(c.z)
        ));
        self.points.insert(key, reference.clone());
        reference
    }
}

/// A STEP string: apostrophes doubled, only printable ASCII kept.
fn string(s: &str) -> String {
    let kept: String = s
        .chars()
        .filter(|c| c.is_ascii() && !c.is_ascii_control() && *c != '\\')
        .take(200)
        .collect();
    format!("'{}'", kept.replace('\'', "''"))
}

fn list(items: impl IntoIterator<Item = String>) -> String {
    format!("({})", items.into_iter().collect::<Vec<_>>().join(","))
}

/// Distinct knots and their multiplicities, as STEP stores a knot vector.
pub(crate) fn knots_with_multiplicities(knots: &[f64]) -> (Vec<f64>, Vec<usize>) {
    let mut values: Vec<f64> = Vec::new();
    let mut mults: Vec<usize> = Vec::new();
    for &k in knots {
        match (values.last(), mults.last_mut()) {
            (Some(&last), Some(m)) if last == k => *m += 1,
            _ => {
                values.push(k);
                mults.push(1);
            }
        }
    }
    (values, mults)
}

/// The length unit instance, and the context's other units (angles).
fn unit_entities(d: &mut Data, units: IgesUnits) -> [String; 3] {
    let length = match units {
        IgesUnits::M => d.add("(LENGTH_UNIT()NAMED_UNIT(*)SI_UNIT($,.METRE.))".into()),
        IgesUnits::Mm => d.add("(LENGTH_UNIT()NAMED_UNIT(*)SI_UNIT(.MILLI.,.METRE.))".into()),
        IgesUnits::In => {
            let metre = d.add("(LENGTH_UNIT()NAMED_UNIT(*)SI_UNIT($,.METRE.))".into());
            let measure = d.add(format!(
                "LENGTH_MEASURE_WITH_UNIT(LENGTH_MEASURE({}),{metre})",
                real(0.0254)
            ));
            let dims = d.add("DIMENSIONAL_EXPONENTS(1.,0.,0.,0.,0.,0.,0.)".into());
            d.add(format!(
                "(CONVERSION_BASED_UNIT('INCH',{measure})LENGTH_UNIT()NAMED_UNIT({dims}))"
            ))
        }
    };
    let angle = d.add("(NAMED_UNIT(*)PLANE_ANGLE_UNIT()SI_UNIT($,.RADIAN.))".into());
    let solid = d.add("(NAMED_UNIT(*)SI_UNIT($,.STERADIAN.)SOLID_ANGLE_UNIT())".into());
    [length, angle, solid]
}

fn surface_entity(d: &mut Data, s: &BSplineSurface) -> String {
    let (p, q) = s.degrees();
    let (nu, nv) = s.counts();
    // STEP's control_points_list is a list of rows along u, each row running along v:
    // the same order as our row-major storage.
    let rows: Vec<String> = (0..nu)
        .map(|i| list((0..nv).map(|j| d.point(s.controls()[i * nv + j]))))
        .collect();
    let (ku, mu) = knots_with_multiplicities(s.knots_u());
    let (kv, mv) = knots_with_multiplicities(s.knots_v());
    d.add(format!(
        "B_SPLINE_SURFACE_WITH_KNOTS('',{p},{q},{},.UNSPECIFIED.,.F.,.F.,.F.,{},{},{},{},.UNSPECIFIED.)",
        list(rows),
        list(mu.iter().map(usize::to_string)),
        list(mv.iter().map(usize::to_string)),
        list(ku.into_iter().map(real)),
        list(kv.into_iter().map(real)),
    ))
}

/// The complete STEP AP214 file holding the given surfaces as one part.
pub fn step_bytes(surfaces: &[&BSplineSurface], o: &StepOptions) -> Vec<u8> {
    let mut d = Data {
        lines: Vec::new(),
        points: HashMap::new(),
    };
    let app =
        d.add("APPLICATION_CONTEXT('core data for automotive mechanical design processes')".into());
    d.add(format!(
        "APPLICATION_PROTOCOL_DEFINITION('international standard','automotive_design',2000,{app})"
    ));
    let product_context = d.add(format!("PRODUCT_CONTEXT('',{app},'mechanical')"));
    let name = string(o.file_name.trim_end_matches(".stp"));
    let product = d.add(format!(
        "PRODUCT({name},{name},'fitted surface',({product_context}))"
    ));
    d.add(format!(
        "PRODUCT_RELATED_PRODUCT_CATEGORY('part',$,({product}))"
    ));
    let formation = d.add(format!("PRODUCT_DEFINITION_FORMATION('','',{product})"));
    let def_context = d.add(format!(
        "PRODUCT_DEFINITION_CONTEXT('part definition',{app},'design')"
    ));
    let definition = d.add(format!(
        "PRODUCT_DEFINITION('design','',{formation},{def_context})"
    ));
    let shape = d.add(format!("PRODUCT_DEFINITION_SHAPE('','',{definition})"));
    let [length, angle, solid] = unit_entities(&mut d, o.units);
    // Model resolution: a billionth of the part's extent, as the IGES writer declares.
    let extent = surfaces
        .iter()
        .flat_map(|s| s.controls().iter())
        .map(|p| p.abs().max_element())
        .fold(0.0, f64::max);
    let uncertainty = d.add(format!(
        "UNCERTAINTY_MEASURE_WITH_UNIT(LENGTH_MEASURE({}),{length},'distance_accuracy_value','confusion accuracy')",
        real((extent * 1e-9).max(1e-12))
    ));
    let context = d.add(format!(
        "(GEOMETRIC_REPRESENTATION_CONTEXT(3)GLOBAL_UNCERTAINTY_ASSIGNED_CONTEXT(({uncertainty}))GLOBAL_UNIT_ASSIGNED_CONTEXT(({length},{angle},{solid}))REPRESENTATION_CONTEXT('',''))"
    ));
    let origin = d.add("CARTESIAN_POINT('',(0.,0.,0.))".into());
    let z = d.add("DIRECTION('',(0.,0.,1.))".into());
    let x = d.add("DIRECTION('',(1.,0.,0.))".into());
    let placement = d.add(format!("AXIS2_PLACEMENT_3D('',{origin},{z},{x})"));
    let surfaces: Vec<String> = surfaces.iter().map(|s| surface_entity(&mut d, s)).collect();
    let set = d.add(format!("GEOMETRIC_SET('',{})", list(surfaces)));
    let representation = d.add(format!(
        "GEOMETRICALLY_BOUNDED_SURFACE_SHAPE_REPRESENTATION({name},({placement},{set}),{context})"
    ));
    d.add(format!(
        "SHAPE_DEFINITION_REPRESENTATION({shape},{representation})"
    ));

    let [y, mo, da, hh, mi, ss] = civil_utc(o.time);
    let mut out = String::new();
    out.push_str("ISO-10303-21;\nHEADER;\n");
    out.push_str("FILE_DESCRIPTION(('trispline B-spline surface'),'2;1');\n");
    let _ = writeln!(
        out,
        "FILE_NAME({},'{y:04}-{mo:02}-{da:02}T{hh:02}:{mi:02}:{ss:02}',('trispline'),(''),{},'trispline','');",
        string(&o.file_name),
        string(concat!("trispline ", env!("CARGO_PKG_VERSION")))
    );
    out.push_str("FILE_SCHEMA(('AUTOMOTIVE_DESIGN { 1 0 10303 214 1 1 1 1 }'));\nENDSEC;\nDATA;\n");
    for (k, line) in d.lines.iter().enumerate() {
        let _ = writeln!(out, "#{}={line};", k + 1);
    }
    out.push_str("ENDSEC;\nEND-ISO-10303-21;\n");
    out.into_bytes()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn knot_vectors_split_into_distinct_values_and_multiplicities() {
        let (k, m) = knots_with_multiplicities(&[0.0, 0.0, 0.0, 0.5, 0.5, 1.0, 1.0, 1.0]);
        assert_eq!(k, vec![0.0, 0.5, 1.0]);
        assert_eq!(m, vec![3, 2, 3]);
    }

    #[test]
    fn strings_double_apostrophes_and_drop_control_characters() {
        assert_eq!(string("bun's\nscan"), "'bun''sscan'");
    }
}
