//! Metaballs (fitted-bvh-metaballs.txt, bezier-clipping-metaballs.txt): a step is a list of
//! balls, one row each (`x y z [radius [strength [r g b]]]`); what a row leaves out comes from
//! the scene's defaults. The histogram samples the summed field on a grid.

pub mod histogram;
pub mod setup;
pub mod step;
