//! Synthetic thermal campaigns: warm-up with known temperature lags and a fanning error line.
