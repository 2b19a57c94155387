//! Error maps: one fitted part (grid + model), family aggregation, and the map file formats.
