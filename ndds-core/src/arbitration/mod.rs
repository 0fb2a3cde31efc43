//! Consumer-side NDDS semantics: arbitration between redundant producers, minimum separation,
//! deadlines and the statuses they produce. (Being written.)
