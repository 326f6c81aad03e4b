//! Binary glTF writer: positions, optional normals and colours (normalised bytes), u32
//! indices, one non-metallic material; the error colour ramp, its scale and an SVG legend
//! for it.

use super::{IoError, IoErrorKind};
use crate::mesh::TriMesh;
use glam::DVec3;
use serde_json::json;
use std::path::Path;

/// Optional per-vertex attributes for [`glb_bytes`].
#[derive(Default)]
pub struct GlbAttributes<'a> {
    /// Unit normals, one per vertex.
    pub normals: Option<&'a [DVec3]>,
    /// Linear RGBA in 0..1.
    pub colors: Option<&'a [[f32; 4]]>,
    /// Line strips written as extra LINE_STRIP primitives (region boundaries, trims).
    pub polylines: &'a [Vec<DVec3>],
}

/// One buffer view's contents, written straight into the file's binary chunk.
enum ViewData<'a> {
    /// f32 x, y, z per point.
    Vec3(&'a [DVec3]),
    /// r, g, b, a per vertex as normalised unsigned bytes: a display's precision, a
    /// quarter of the f32 bytes (12 of every vertex's 40 bytes saved).
    Rgba(&'a [[f32; 4]]),
    /// u32 per corner.
    Indices(&'a [[u32; 3]]),
}

impl ViewData<'_> {
    /// Bytes of the view; every kind is a whole number of 4-byte words, so views laid end
    /// to end stay 4-byte aligned as glTF requires.
    fn byte_len(&self) -> usize {
        match self {
            ViewData::Vec3(p) => 12 * p.len(),
            ViewData::Rgba(c) => 4 * c.len(),
            ViewData::Indices(t) => 12 * t.len(),
        }
    }

    fn write(&self, out: &mut Vec<u8>) {
        match self {
            ViewData::Vec3(pts) => {
                for p in *pts {
                    for c in [p.x as f32, p.y as f32, p.z as f32] {
                        out.extend_from_slice(&c.to_le_bytes());
                    }
                }
            }
            ViewData::Rgba(colors) => {
                out.extend(colors.iter().flatten().map(|&c| unit_byte(c)));
            }
            ViewData::Indices(tris) => {
                for i in tris.iter().flatten() {
                    out.extend_from_slice(&i.to_le_bytes());
                }
            }
        }
    }
}

/// `x` in 0..1 as the nearest of 256 levels (glTF's normalised unsigned byte).
fn unit_byte(x: f32) -> u8 {
    // NaN saturates to 0 in the cast.
    (x.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// The material every primitive uses. glTF's default material is fully metallic, which
/// renders vertex colours almost black under standard image-based lighting; a white,
/// non-metallic, fairly rough base lets `COLOR_0` (which multiplies the base colour) show
/// as written. Double-sided: fitted patches are open surfaces seen from both sides.
fn material() -> serde_json::Value {
    json!({
        "name": "trispline-vertex-colours",
        "pbrMetallicRoughness": {
            "baseColorFactor": [1.0, 1.0, 1.0, 1.0],
            "metallicFactor": 0.0,
            "roughnessFactor": 0.8,
        },
        "doubleSided": true,
    })
}

/// Encodes a triangle mesh as GLB. glTF stores f32: coordinates are written as given,
/// with no axis swap or scaling.
pub fn glb_bytes<'a>(mesh: &'a TriMesh, attrs: &GlbAttributes<'a>) -> Vec<u8> {
    glb_bytes_with_extras(mesh, attrs, None)
}

/// [`glb_bytes`] with application data in the mesh's `extras` (e.g.
/// [`ErrorRamp::extras`], so that a viewer or script can read what the colours mean).
pub fn glb_bytes_with_extras<'a>(
    mesh: &'a TriMesh,
    attrs: &GlbAttributes<'a>,
    extras: Option<serde_json::Value>,
) -> Vec<u8> {
    // The views' sizes are known up front: the JSON chunk (which lists their offsets) is
    // made first and each view is then encoded once, in place in the output, instead of
    // into a buffer of its own that is copied into the binary chunk and that into the file.
    let mut data: Vec<ViewData<'a>> = Vec::new();
    let mut views = Vec::new();
    let mut bin_len = 0;
    let mut push_view = |d: ViewData<'a>, target: u32| -> usize {
        let len = d.byte_len();
        views
            .push(json!({"buffer": 0, "byteOffset": bin_len, "byteLength": len, "target": target}));
        bin_len += len;
        data.push(d);
        views.len() - 1
    };
    let mut accessors = Vec::new();
    let vec3_accessor = |view: usize, pts: &[DVec3], with_bounds: bool| {
        let mut acc =
            json!({"bufferView": view, "componentType": 5126, "count": pts.len(), "type": "VEC3"});
        if with_bounds && !pts.is_empty() {
            let (lo, hi) =
                pts.iter()
                    .fold(([f32::MAX; 3], [f32::MIN; 3]), |(mut lo, mut hi), p| {
                        for (k, c) in [p.x as f32, p.y as f32, p.z as f32].into_iter().enumerate() {
                            lo[k] = lo[k].min(c);
                            hi[k] = hi[k].max(c);
                        }
                        (lo, hi)
                    });
            acc["min"] = json!(lo);
            acc["max"] = json!(hi);
        }
        acc
    };

    let pos_view = push_view(ViewData::Vec3(&mesh.positions), 34962);
    accessors.push(vec3_accessor(pos_view, &mesh.positions, true));
    let mut attributes = json!({"POSITION": 0});
    if let Some(n) = attrs.normals.filter(|n| n.len() == mesh.positions.len()) {
        let v = push_view(ViewData::Vec3(n), 34962);
        accessors.push(vec3_accessor(v, n, false));
        attributes["NORMAL"] = json!(accessors.len() - 1);
    }
    if let Some(c) = attrs.colors.filter(|c| c.len() == mesh.positions.len()) {
        let v = push_view(ViewData::Rgba(c), 34962);
        accessors.push(
            json!({"bufferView": v, "componentType": 5121, "normalized": true, "count": c.len(), "type": "VEC4"}),
        );
        attributes["COLOR_0"] = json!(accessors.len() - 1);
    }
    let iv = push_view(ViewData::Indices(&mesh.triangles), 34963);
    accessors.push(json!({"bufferView": iv, "componentType": 5125, "count": mesh.triangles.len() * 3, "type": "SCALAR"}));
    let mut primitives = vec![
        json!({"attributes": attributes, "indices": accessors.len() - 1, "mode": 4, "material": 0}),
    ];
    for line in attrs.polylines.iter().filter(|l| l.len() >= 2) {
        let v = push_view(ViewData::Vec3(line), 34962);
        accessors.push(vec3_accessor(v, line, true));
        primitives.push(
            json!({"attributes": {"POSITION": accessors.len() - 1}, "mode": 3, "material": 0}),
        );
    }
    let mut gltf_mesh = json!({"primitives": primitives});
    if let Some(e) = extras {
        gltf_mesh["extras"] = e;
    }
    let doc = json!({
        "asset": {"version": "2.0", "generator": "trispline"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [gltf_mesh],
        "materials": [material()],
        "buffers": [{"byteLength": bin_len}],
        "bufferViews": views,
        "accessors": accessors,
    });
    let mut json_bytes = serde_json::to_vec(&doc).unwrap_or_default();
    while !json_bytes.len().is_multiple_of(4) {
        json_bytes.push(b' ');
    }
    let total = 12 + 8 + json_bytes.len() + 8 + bin_len;
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json_bytes.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json_bytes);
    out.extend_from_slice(&(bin_len as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    for d in &data {
        d.write(&mut out);
    }
    debug_assert_eq!(out.len(), total);
    out
}

/// The error heatmap's colour ramp: linear RGB stops evenly spaced over
/// `error / tolerance` in [0, `max_ratio`], larger errors clamped to the last stop. Blue is
/// exact, green half the tolerance, yellow the tolerance, red twice it or more.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ErrorRamp {
    /// Linear RGB colours, evenly spaced from ratio 0 to `max_ratio`.
    pub stops: [[f32; 3]; 5],
    /// The ratio error / tolerance at the last stop.
    pub max_ratio: f64,
}

/// The ramp the fitted surfaces' GLB heatmaps use.
pub const ERROR_RAMP: ErrorRamp = ErrorRamp {
    stops: [
        [0.10, 0.25, 0.90],
        [0.10, 0.75, 0.30],
        [0.95, 0.90, 0.10],
        [0.95, 0.50, 0.10],
        [0.85, 0.10, 0.10],
    ],
    max_ratio: 2.0,
};

impl ErrorRamp {
    /// The error at stop `k` for this tolerance.
    pub fn stop_error(&self, k: usize, tolerance: f64) -> f64 {
        tolerance * self.max_ratio * k as f64 / (self.stops.len() - 1) as f64
    }

    /// The linear RGBA colour of an error.
    pub fn colour(&self, error: f64, tolerance: f64) -> [f32; 4] {
        let t = if tolerance > 0.0 {
            (error / tolerance).clamp(0.0, self.max_ratio) / self.max_ratio
        } else {
            0.0
        } as f32;
        let spans = self.stops.len() - 1;
        let x = t * spans as f32;
        let i = (x.floor() as usize).min(spans - 1);
        let f = x - i as f32;
        let (a, b) = (self.stops[i], self.stops[i + 1]);
        [
            a[0] + (b[0] - a[0]) * f,
            a[1] + (b[1] - a[1]) * f,
            a[2] + (b[2] - a[2]) * f,
            1.0,
        ]
    }

    /// The ramp and its scale as JSON for a GLB's `extras` or a report: every stop's
    /// error in `unit` and its colour.
    pub fn extras(&self, tolerance: f64, unit: &str, quantity: &str) -> serde_json::Value {
        let stops: Vec<_> = self
            .stops
            .iter()
            .enumerate()
            .map(|(k, rgb)| {
                json!({
                    "error": self.stop_error(k, tolerance),
                    "ratio_to_tolerance": self.max_ratio * k as f64 / (self.stops.len() - 1) as f64,
                    "linear_rgb": rgb,
                })
            })
            .collect();
        json!({"error_ramp": {
            "quantity": quantity,
            "unit": unit,
            "tolerance": tolerance,
            "interpolation": "linear between stops in linear RGB; errors above the last stop take its colour",
            "attribute": "COLOR_0",
            "stops": stops,
        }})
    }

    /// An SVG legend: the ramp as a horizontal bar with each stop's error in `unit`.
    /// Colours are converted to sRGB, as a viewer displays the linear vertex colours.
    pub fn legend_svg(&self, tolerance: f64, unit: &str, title: &str) -> String {
        let (w, bar_x, bar_w) = (480.0, 40.0, 380.0);
        let n = self.stops.len() - 1;
        let mut gradient = String::new();
        for (k, rgb) in self.stops.iter().enumerate() {
            let [r, g, b] = rgb.map(|c| (linear_to_srgb(c) * 255.0).round() as u8);
            gradient.push_str(&format!(
                "<stop offset=\"{:.3}\" stop-color=\"#{r:02x}{g:02x}{b:02x}\"/>",
                k as f64 / n as f64
            ));
        }
        // Three significant digits on the largest label, the same decimals on all.
        let largest = self.stop_error(n, tolerance);
        let decimals = if largest > 0.0 && largest.is_finite() {
            (2.0 - largest.log10().floor()).clamp(0.0, 12.0) as usize
        } else {
            3
        };
        let mut ticks = String::new();
        for k in 0..=n {
            let x = bar_x + bar_w * k as f64 / n as f64;
            let label = format!("{:.decimals$}", self.stop_error(k, tolerance));
            let label = if k == n {
                format!("\u{2265} {label}")
            } else {
                label
            };
            ticks.push_str(&format!(
                "<line x1=\"{x}\" y1=\"62\" x2=\"{x}\" y2=\"68\" stroke=\"#222\"/><text x=\"{x}\" y=\"82\" text-anchor=\"middle\">{label}</text>"
            ));
        }
        format!(
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"110\" viewBox=\"0 0 {w} 110\" font-family=\"sans-serif\" font-size=\"12\"><rect width=\"{w}\" height=\"110\" fill=\"white\"/><defs><linearGradient id=\"ramp\">{gradient}</linearGradient></defs><text x=\"{bar_x}\" y=\"22\" font-size=\"13\">{}</text><rect x=\"{bar_x}\" y=\"32\" width=\"{bar_w}\" height=\"30\" fill=\"url(#ramp)\" stroke=\"#222\"/>{ticks}<text x=\"{bar_x}\" y=\"102\">{} (tolerance {:.decimals$} {})</text></svg>\n",
            xml_escape(title),
            xml_escape(unit),
            tolerance,
            xml_escape(unit),
        )
    }
}

fn linear_to_srgb(c: f32) -> f64 {
    let c = f64::from(c.clamp(0.0, 1.0));
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

pub(crate) fn write_glb(path: &Path, mesh: &TriMesh, attrs: &GlbAttributes) -> Result<(), IoError> {
    std::fs::write(path, glb_bytes(mesh, attrs))
        .map_err(|e| IoError::new(path.display().to_string(), None, IoErrorKind::Write(e)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn glb_round_trips_through_the_gltf_crate() {
        let mesh = TriMesh::new(
            vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::new(1.0, 1.0, 0.5)],
            vec![[0, 1, 2], [1, 3, 2]],
        );
        let colors = vec![
            [1.0, 0.0, 0.0, 1.0],
            [0.3, 0.61, 0.9, 1.0],
            [0.0, 1.0, 0.0, 1.0],
            [0.0, 0.0, 1.0, 1.0],
        ];
        let bytes = glb_bytes(
            &mesh,
            &GlbAttributes {
                colors: Some(&colors),
                ..Default::default()
            },
        );
        let (doc, buffers, _) = gltf::import_slice(&bytes).expect("valid glb");
        let prim = doc
            .meshes()
            .next()
            .and_then(|m| m.primitives().next())
            .expect("one primitive");
        let reader = prim.reader(|b| Some(&buffers[b.index()]));
        let pos: Vec<[f32; 3]> = reader.read_positions().expect("positions").collect();
        assert_eq!(pos[3], [1.0, 1.0, 0.5]);
        let idx: Vec<u32> = reader.read_indices().expect("indices").into_u32().collect();
        assert_eq!(idx, vec![0, 1, 2, 1, 3, 2]);
        let read: Vec<[f32; 4]> = reader
            .read_colors(0)
            .expect("colours")
            .into_rgba_f32()
            .collect();
        // Each channel within half a level of what was written.
        for (r, c) in read.iter().flatten().zip(colors.iter().flatten()) {
            assert!((r - c).abs() <= 0.5 / 255.0 + 1e-6, "{r} for {c}");
        }
        let material = prim.material();
        let pbr = material.pbr_metallic_roughness();
        assert_eq!(pbr.metallic_factor(), 0.0);
        assert_eq!(pbr.base_color_factor(), [1.0; 4]);
        assert!(material.double_sided());
    }

    #[test]
    fn the_ramp_goes_into_the_mesh_extras_with_its_scale() {
        let mesh = TriMesh::new(vec![DVec3::ZERO, DVec3::X, DVec3::Y], vec![[0, 1, 2]]);
        let extras = ERROR_RAMP.extras(0.5e-3, "m", "geometric error");
        let bytes = glb_bytes_with_extras(&mesh, &GlbAttributes::default(), Some(extras));
        assert!(gltf::import_slice(&bytes).is_ok(), "valid glb");
        // The gltf crate reads extras only with a feature this crate does not enable:
        // read the JSON chunk directly.
        let json_len = u32::from_le_bytes([bytes[12], bytes[13], bytes[14], bytes[15]]) as usize;
        let doc: serde_json::Value =
            serde_json::from_slice(&bytes[20..20 + json_len]).expect("json");
        let v = &doc["meshes"][0]["extras"];
        assert_eq!(
            doc["materials"][0]["pbrMetallicRoughness"]["metallicFactor"],
            json!(0.0)
        );
        let stops = v["error_ramp"]["stops"].as_array().expect("stops");
        assert_eq!(stops.len(), 5);
        assert_eq!(stops[2]["error"], json!(0.5e-3));
        assert_eq!(stops[4]["error"], json!(1e-3));
        assert_eq!(v["error_ramp"]["unit"], "m");
    }

    #[test]
    fn ramp_colours_hit_the_stops_and_clamp() {
        let t = 2.0;
        let near = |e: f64, k: usize| {
            let c = ERROR_RAMP.colour(e, t);
            (0..3).all(|i| (c[i] - ERROR_RAMP.stops[k][i]).abs() < 1e-6)
        };
        assert!(near(0.0, 0) && near(t, 2) && near(2.0 * t, 4) && near(100.0, 4));
        assert!(!near(0.5 * t, 2));
        let svg = ERROR_RAMP.legend_svg(t, "mm", "error <b>");
        assert!(
            svg.contains("error &lt;b&gt;") && svg.contains(">\u{2265} 4.00<"),
            "{svg}"
        );
    }
}
