// A build script makes cargo take this crate's build-dependencies into account (the features
// of the proc-macro crates, which are built for the host).
fn main() {}
