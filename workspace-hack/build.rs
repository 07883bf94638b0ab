// Makes the `[build-dependencies]` in the manifest count: they unify the features of the
// crates that build scripts and procedural macros use.
fn main() {}
