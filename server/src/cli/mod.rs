//! The `isoray` binary's commands besides serving: `isoray push` (steps from files to a
//! server) and `isoray render` (one image of a scene, offline).

pub mod points_files;
pub mod push;
pub mod push_args;
pub mod push_molecule;
pub mod push_points;
pub mod push_surfels;
pub mod push_vtu;
pub mod render;
pub mod surfel_files;
pub mod vtk_grid;
pub mod vtk_legacy;
pub mod vtk_xml;
