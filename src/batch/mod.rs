//! Batch jobs over a part family: the job manifest, scheduling over parts, sharding and the summary.
