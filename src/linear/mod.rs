//! Linear axes measured by laser interferometer: run files, positioning evaluation by standard, air and material correction, error budget, pitch-error fit, compensation tables.
