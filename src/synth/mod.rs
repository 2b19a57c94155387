//! Generators of sample data with known ground truth, for every kind of measurement errmap reads.

pub mod circular;
pub mod linear;
pub mod rotary;
pub mod thermal;
pub mod training;
pub mod web_plate;
pub mod web_plate_args;
