//! In-process tests of the library: formats, mesh, surfaces, fitting, pipeline.
//! One binary (a module per area) links faster than one binary per file.

mod bpatch_dms;
mod bspline;
mod curvature;
mod dayone;
mod dms_pieces;
mod fit_engine;
mod fit_operator;
mod iges;
mod io_formats;
mod io_limits;
mod io_malformed;
mod io_shared_data;
mod loop_crease;
mod loop_fit;
mod loop_limit;
mod loop_limit_irregular;
mod loop_patchwork;
mod mesh_clean;
mod mesh_elephant;
mod mesh_roundtrip;
mod object_crease;
mod object_faceted;
mod object_fit;
mod object_growth;
mod object_pipeline;
mod object_session;
mod object_session_local;
mod planar_product;
mod planar_subdivided;
mod point_clouds;
mod scan_dispatch;
mod scan_pipeline;
mod shown_surface;
mod step_export;

/// A mesh of the shared data (`None` where `../shared/data` is absent outside CI: the test
/// then skips), read with the default options; a file that does not read fails the test.
pub(crate) fn shared_mesh(relative: &str) -> Option<trispline::TriMesh> {
    let path = trispline::testdata::shared_data(relative)?;
    Some(
        trispline::io::read_mesh_file(&path, &trispline::io::LoadOptions::default())
            .unwrap_or_else(|e| panic!("{relative}: {e}"))
            .mesh,
    )
}
