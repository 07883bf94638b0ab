//! No code: the dependencies in this crate's manifest, with their features unified across the
//! workspace, are the point (see the manifest's comment).
