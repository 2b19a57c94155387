//! Rotary axes: sphere fits, double-vector angular error (seed 003), axis location and compensation tables.
