//! Probe files of machined parts: reading and validating measured points, averaging repeats, and rejecting gross errors.
