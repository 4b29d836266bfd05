//! The server binary's file readers, by path: the very source `isoray push` runs (VTK for
//! tet meshes; particle files for metaball scenes; point clouds and meshes for surfel
//! scenes).

#[path = "../../../server/src/cli/points_files.rs"]
pub mod points_files;
#[path = "../../../server/src/cli/surfel_files.rs"]
pub mod surfel_files;
#[path = "../../../server/src/cli/vtk_grid.rs"]
pub mod vtk_grid;
#[path = "../../../server/src/cli/vtk_legacy.rs"]
pub mod vtk_legacy;
#[path = "../../../server/src/cli/vtk_xml.rs"]
pub mod vtk_xml;
