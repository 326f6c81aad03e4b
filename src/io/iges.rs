//! IGES 5.3 writer for B-spline geometry: entity 128 (rational B-spline surface, written
//! with unit weights and the polynomial flag set) and entity 126 (rational B-spline curve).
//!
//! Fixed 80-column records: columns 1-72 data, column 73 the section letter (S, G, D, P,
//! T), columns 74-80 the sequence number within the section. Each entity has a two-line
//! directory entry pointing at its first parameter line; each parameter line carries the
//! entity's directory sequence number in columns 66-72. Strings are Hollerith (`5Hhello`).

use crate::bspline::{BSplineCurve, BSplineSurface};
use glam::DVec3;
use std::time::SystemTime;

/// The length unit an IGES file declares (coordinates are written unscaled).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum IgesUnits {
    /// Millimetres.
    Mm,
    /// Metres.
    M,
    /// Inches.
    In,
}

impl IgesUnits {
    /// Every unit, in the order a user interface lists them.
    pub const ALL: [IgesUnits; 3] = [IgesUnits::Mm, IgesUnits::M, IgesUnits::In];

    /// The unit's short name ("mm", "m", "in").
    pub fn name(self) -> &'static str {
        match self {
            IgesUnits::Mm => "mm",
            IgesUnits::M => "m",
            IgesUnits::In => "in",
        }
    }

    /// The global section's unit flag and unit name.
    fn flag_and_name(self) -> (u32, &'static str) {
        match self {
            IgesUnits::In => (1, "INCH"),
            IgesUnits::Mm => (2, "MM"),
            IgesUnits::M => (6, "M"),
        }
    }
}

impl IgesUnits {
    /// Metres per unit.
    pub fn metres(self) -> f64 {
        match self {
            IgesUnits::Mm => 1e-3,
            IgesUnits::M => 1.0,
            IgesUnits::In => 0.0254,
        }
    }

    /// A warning when data whose largest bounding-box side is `extent` (in this unit) would
    /// be an implausible size for a scanned object: under 1 cm or over 100 m. A unit
    /// mismatch is a factor of 1000 (or 25.4), so it lands far outside that range for
    /// anything from a coin to a house, while a correct unit rarely does.
    pub fn size_warning(self, extent: f64) -> Option<String> {
        let metres = extent * self.metres();
        if !metres.is_finite() || metres <= 0.0 || (1e-2..=100.0).contains(&metres) {
            return None;
        }
        let likely = IgesUnits::ALL
            .into_iter()
            .filter(|u| *u != self)
            .min_by(|a, b| {
                let off = |u: &IgesUnits| (extent * u.metres()).log10().abs();
                off(a).total_cmp(&off(b))
            })
            .unwrap_or(IgesUnits::M);
        Some(format!(
            "the data are {extent:.4} {self} across ({metres:.3e} m) if --units {self} is right; \
             if the input is in {likely}, pass --units {likely} so CAD tools read true size"
        ))
    }
}

impl std::fmt::Display for IgesUnits {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for IgesUnits {
    type Err = crate::names::UnknownName;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        IgesUnits::ALL
            .into_iter()
            .find(|u| u.name() == s)
            .ok_or_else(|| crate::names::UnknownName::new(s, IgesUnits::ALL.map(IgesUnits::name)))
    }
}

#[derive(Clone, Debug)]
/// What goes into an IGES file's global section.
pub struct IgesOptions {
    /// Declared length unit.
    pub units: IgesUnits,
    /// Written into the global section (truncated to 60 characters).
    pub file_name: String,
    /// Written into the global section's author field.
    pub author: String,
    /// Generation time; `None` writes the Unix epoch (reproducible output for tests).
    pub time: Option<SystemTime>,
}

impl Default for IgesOptions {
    fn default() -> Self {
        Self {
            units: IgesUnits::Mm,
            file_name: "surface.igs".into(),
            author: "trispline".into(),
            time: None,
        }
    }
}

fn hollerith(s: &str) -> String {
    let s: String = s
        .chars()
        .filter(|c| c.is_ascii() && !c.is_ascii_control())
        .take(60)
        .collect();
    format!("{}H{}", s.len(), s)
}

/// A real with a decimal point and exponent, in the shortest form that reads back to the
/// same f64 (valid in IGES and in STEP, which both require the point).
pub(super) fn real(x: f64) -> String {
    let s = format!("{x:E}");
    match s.find('E') {
        Some(e) if !s[..e].contains('.') => format!("{}.0{}", &s[..e], &s[e..]),
        _ => s,
    }
}

/// `YYYYMMDD.HHNNSS` in UTC.
fn timestamp(t: Option<SystemTime>) -> String {
    let [y, m, d, hh, mm, ss] = civil_utc(t);
    format!("{y:04}{m:02}{d:02}.{hh:02}{mm:02}{ss:02}")
}

/// [year, month, day, hour, minute, second] in UTC, from days since the epoch by the
/// civil-calendar algorithm; `None` (and times before 1970) give the epoch.
pub(super) fn civil_utc(t: Option<SystemTime>) -> [i64; 6] {
    let secs = t
        .and_then(|t| t.duration_since(SystemTime::UNIX_EPOCH).ok())
        .map(|d| d.as_secs() as i64)
        .unwrap_or(0);
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    [y, m, d, rem / 3600, rem / 60 % 60, rem % 60]
}

/// Packs delimited tokens into lines of at most `width` columns without splitting tokens.
fn pack(tokens: &[String], width: usize, record_end: char) -> Vec<String> {
    let mut lines = Vec::new();
    let mut cur = String::new();
    for (k, t) in tokens.iter().enumerate() {
        let delim = if k + 1 == tokens.len() {
            record_end
        } else {
            ','
        };
        let piece = format!("{t}{delim}");
        if !cur.is_empty() && cur.len() + piece.len() > width {
            lines.push(std::mem::take(&mut cur));
        }
        cur.push_str(&piece);
    }
    if !cur.is_empty() {
        lines.push(cur);
    }
    lines
}

struct Entity {
    kind: u32,
    label: &'static str,
    params: Vec<String>,
}

fn surface_entity(s: &BSplineSurface) -> Entity {
    let (p, q) = s.degrees();
    let (nu, nv) = s.counts();
    let mut t: Vec<String> = vec![
        "128".into(),
        (nu - 1).to_string(),
        (nv - 1).to_string(),
        p.to_string(),
        q.to_string(),
        "0".into(), // not closed in u
        "0".into(), // not closed in v
        "1".into(), // polynomial: all weights equal
        "0".into(), // not periodic in u
        "0".into(), // not periodic in v
    ];
    t.extend(s.knots_u().iter().map(|&k| real(k)));
    t.extend(s.knots_v().iter().map(|&k| real(k)));
    t.extend(std::iter::repeat_n("1.0".to_string(), nu * nv));
    // IGES runs the first (u) index fastest; ours is row-major with u slowest.
    for j in 0..nv {
        for i in 0..nu {
            let c = s.controls()[i * nv + j];
            t.extend([real(c.x), real(c.y), real(c.z)]);
        }
    }
    let ((u0, u1), (v0, v1)) = s.domain();
    t.extend([real(u0), real(u1), real(v0), real(v1)]);
    Entity {
        kind: 128,
        label: "BSURF",
        params: t,
    }
}

fn curve_entity(c: &BSplineCurve) -> Entity {
    let n = c.controls().len();
    let p = c.degree();
    let mut t: Vec<String> = vec![
        "126".into(),
        (n - 1).to_string(),
        p.to_string(),
        "0".into(), // not known to be planar
        "0".into(), // open
        "1".into(), // polynomial
        "0".into(), // not periodic
    ];
    t.extend(c.knots().iter().map(|&k| real(k)));
    t.extend(std::iter::repeat_n("1.0".to_string(), n));
    for x in c.controls() {
        t.extend([real(x.x), real(x.y), real(x.z)]);
    }
    let (a, b) = c.domain();
    t.extend([real(a), real(b)]);
    // Unit normal of the plane: meaningful only for planar curves; zeros otherwise.
    t.extend(["0.0".into(), "0.0".into(), "0.0".into()]);
    Entity {
        kind: 126,
        label: "BCURVE",
        params: t,
    }
}

/// The complete IGES file holding the given surfaces and curves, in that order.
pub fn iges_bytes(
    surfaces: &[&BSplineSurface],
    curves: &[&BSplineCurve],
    o: &IgesOptions,
) -> Vec<u8> {
    let entities: Vec<Entity> = surfaces
        .iter()
        .map(|s| surface_entity(s))
        .chain(curves.iter().map(|c| curve_entity(c)))
        .collect();
    let max_coord = surfaces
        .iter()
        .flat_map(|s| s.controls().iter())
        .chain(curves.iter().flat_map(|c| c.controls().iter()))
        .map(|p: &DVec3| p.abs().max_element())
        .fold(0.0, f64::max);
    let stamp = timestamp(o.time);
    let (unit_flag, unit_name) = o.units.flag_and_name();
    let global: Vec<String> = vec![
        "1H,".into(),
        "1H;".into(),
        hollerith("trispline surface"),
        hollerith(&o.file_name),
        hollerith("trispline"),
        hollerith(env!("CARGO_PKG_VERSION")),
        "32".into(),
        "38".into(),
        "6".into(),
        "308".into(),
        "15".into(),
        hollerith("trispline surface"),
        "1.0".into(),
        unit_flag.to_string(),
        hollerith(unit_name),
        "1".into(),
        "1.0".into(),
        hollerith(&stamp),
        real((max_coord * 1e-9).max(1e-12)),
        real(max_coord.max(1.0)),
        hollerith(&o.author),
        hollerith("trispline"),
        "11".into(), // IGES 5.3
        "0".into(),
        hollerith(&stamp),
    ];

    let mut out = String::new();
    let start = ["B-spline geometry written by trispline (least-squares fit)."];
    for (k, l) in start.iter().enumerate() {
        out.push_str(&format!("{l:<72}S{:>7}\n", k + 1));
    }
    let glines = pack(&global, 72, ';');
    for (k, l) in glines.iter().enumerate() {
        out.push_str(&format!("{l:<72}G{:>7}\n", k + 1));
    }
    // Parameter lines first (their counts feed the directory), then emit D before P.
    let mut dir = String::new();
    let mut par = String::new();
    let mut p_seq = 1;
    for (k, e) in entities.iter().enumerate() {
        let de_seq = 2 * k + 1;
        let lines = pack(&e.params, 64, ';');
        let first = p_seq;
        for l in &lines {
            par.push_str(&format!("{l:<64} {de_seq:>7}P{p_seq:>7}\n"));
            p_seq += 1;
        }
        dir.push_str(&format!(
            "{:>8}{:>8}{:>8}{:>8}{:>8}{:>8}{:>8}{:>8}{:>8}D{:>7}\n",
            e.kind, first, 0, 0, 0, 0, 0, 0, "00000000", de_seq
        ));
        dir.push_str(&format!(
            "{:>8}{:>8}{:>8}{:>8}{:>8}{:>8}{:>8}{:>8}{:>8}D{:>7}\n",
            e.kind,
            0,
            0,
            lines.len(),
            0,
            "",
            "",
            e.label,
            k + 1,
            de_seq + 1
        ));
    }
    out.push_str(&dir);
    out.push_str(&par);
    let t = format!(
        "S{:>7}G{:>7}D{:>7}P{:>7}",
        start.len(),
        glines.len(),
        2 * entities.len(),
        p_seq - 1
    );
    out.push_str(&format!("{t:<72}T{:>7}\n", 1));
    out.into_bytes()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_names_parse_back_and_an_unknown_one_lists_them() {
        for u in IgesUnits::ALL {
            assert_eq!(u.to_string().parse::<IgesUnits>(), Ok(u));
        }
        let e = "cm".parse::<IgesUnits>().expect_err("not a unit");
        assert_eq!(
            e.to_string(),
            "unknown name \"cm\"; expected one of: mm, m, in"
        );
    }

    #[test]
    fn reals_always_carry_a_decimal_point_and_round_trip() {
        for x in [0.0, 1.0, -2.5, 1e-300, 123456.789, 0.1 + 0.2, -7e22] {
            let s = real(x);
            assert!(s.contains('.') && s.contains('E'), "{s}");
            assert_eq!(s.parse::<f64>().ok(), Some(x), "{s}");
        }
    }

    #[test]
    fn timestamps_follow_the_civil_calendar() {
        let t = SystemTime::UNIX_EPOCH + std::time::Duration::from_secs(1_709_210_096);
        assert_eq!(timestamp(Some(t)), "20240229.123456");
        assert_eq!(timestamp(None), "19700101.000000");
    }

    #[test]
    fn hollerith_counts_characters() {
        assert_eq!(hollerith("MM"), "2HMM");
        assert_eq!(hollerith(""), "0H");
    }
}
