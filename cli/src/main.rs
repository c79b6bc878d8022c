//! The dynlab offline command line: collect, train, compare, diagnose, eval, bag info
fn main() {}
