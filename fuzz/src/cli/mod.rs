//! The server binary's VTK readers, by path: the very source `isoray push` runs.

#[path = "../../../server/src/cli/vtk_grid.rs"]
pub mod vtk_grid;
#[path = "../../../server/src/cli/vtk_legacy.rs"]
pub mod vtk_legacy;
#[path = "../../../server/src/cli/vtk_xml.rs"]
pub mod vtk_xml;
