//! Synthetic thin-walled web-plate family: probe files with a known error field, outliers and a finishing-pass program.
