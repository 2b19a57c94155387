//! Heatmap pictures of error maps: diverging colour map centred on 0 µm, colour bar, axes in mm, probe points.
