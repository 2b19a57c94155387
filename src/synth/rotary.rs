//! Synthetic sphere probing around a rotary axis with planted angular errors, tilt and offset.
