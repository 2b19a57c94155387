//! Synthetic laser-interferometer runs of a linear axis with known pitch error, reversal and noise.
