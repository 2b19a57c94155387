//! Scattered-point interpolation on the map plane: Delaunay surface (spade), natural-neighbour, Sibson C1 and linear resampling onto grids.
