//! Small exact MLPs: forward, reverse mode (VJP), forward mode (JVP), Adam
#![warn(missing_docs)]
