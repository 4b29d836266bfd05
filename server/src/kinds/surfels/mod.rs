//! The surfel kind on the server (deforming-point-sampled-surfaces.txt): so far its
//! histogram; scene setup and step ingest are still to come (the API refuses the kind).

pub mod histogram;
